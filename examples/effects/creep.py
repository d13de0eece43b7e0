"""Creep of the polymer: the tip keeps moving after the drive settles.

The whole recipe for adding an effect to eap-model is this one file.  Use it with any
command that takes ``--effects``::

    eap frf --effects default,+creep --effects-path examples/effects/creep.py
    eap diagnose rec*.csv --effects none --effects-path examples/effects/creep.py

Model: the tip load is multiplied by ``1 + r / (1 + s τ)``: a fraction ``r`` of the
deflection builds up (or, for r < 0, relaxes back) with time constant ``τ``; r = 0 is
the model without creep (nested).  A standard linear solid in series with the beam gives
this form (Findley, Lai & Onaran, *Creep and relaxation of nonlinear viscoelastic
materials*, 1976, ch. 5).  Values come from the device file's section ``creep``
(``creep_r``, ``creep_tau``) or the defaults below.
"""
from physics.effects import OutputEffect
from physics.parameters import ParamSpec


class Creep(OutputEffect):
    id = "creep"
    summary = "polymer creep: tip load × (1 + r/(1 + sτ)), a slow extra deflection"
    explanation = __doc__
    params = (
        ParamSpec("creep_r", "1", -0.9, 10.0, "creep fraction r: extra static deflection / elastic deflection",
                  optional=True, default=0.3),
        ParamSpec("creep_tau", "s", 1e-3, 1e5, "creep time constant τ", optional=True, default=20.0),
    )
    diagnosis = {
        "free": ("creep_r", "creep_tau"),
        "bounds": {"creep_r": (-0.9, 5.0), "creep_tau": (0.05, 1e4)},
        "starts": [{"creep_tau": 1.0}, {"creep_tau": 10.0}, {"creep_tau": 100.0}],
        "nested": True, "off": {"creep_r": 0.0},
        "excitation": "a step or pulse held longer than the creep time (≥ 10 s), or a sweep down to 1/(2πτ)",
        "reveal": {"f_lo_max": 0.05, "hold_s": 10.0},
        "signature": [("step_creep", 1.0), ("lf_excess_lag", 0.5)],
    }

    def output_tf(self, p):
        r, tau = self.value(p, "creep_r"), self.value(p, "creep_tau")
        return [tau, 1.0 + r], [tau, 1.0]     # (τ s + 1 + r) / (τ s + 1)
