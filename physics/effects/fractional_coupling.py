"""``fractional_coupling``: rough, high-surface electrodes give a fractional-order load constant.

Thesis eq. 14:  kf(f) = kf0 / ((j2πf)^a (j2πf + p)^b), identified as 0.095/(j2πf)^0.60
for the IPMC (eq. 15) and 27.08/((j2πf)^0.62 (j2πf + 53)^0.15) for the IP2C (eq. 16):
a constant-phase (−90°·(a+b) at low frequency) and constant log-log slope response,
the signature of the dendritic electrode/polymer interface (Caponetto et al. 2013).
The thesis law has an unbounded gain at DC, which no real device shows; here the first
factor is (j2πf + 2π f_lo)^a with a corner f_lo (default 1e-4 Hz, 0.03° from the thesis
law at 0.1 Hz; p is raised to at least 2π f_lo likewise), so that both solvers share one bounded, causal response.  The time
solver realises it with real poles (error < 0.1 % over the band).  Where a device's law flattens is
its own (a corner of a few mHz is common, a 25 s step shows it), so the diagnosis fits f_lo with the
effect as a shape parameter (10⁻⁴–0.05 Hz: a corner below the device default is beyond what
minutes of record resolve).
Off: constant kf.  A humidity map on ``kf`` scales kf0 alike.
"""
from __future__ import annotations

import numpy as np

from ..parameters import ParamSpec
from .base import Effect


class ConstantCoupling(Effect):
    stage = "coupling"
    summary = "constant load constant kf (eq. 9)"
    requires = ("kf",)

    def kf(self, s, p) -> np.ndarray:
        """Load constant kf(s) [N m/mol] (humidity already applied to ``p``)."""
        return np.full(np.shape(s), p["kf"], dtype=complex)

    def gain_equivalent(self, p, w: float) -> float:
        """Role hook (the diagnosis translates starts between models): the constant coupling
        gain [N m/mol] equivalent to this stage's at ω = ``w`` [rad/s]."""
        return float(p["kf"])

    def gain_start(self, value: float, p, w: float) -> dict:
        """Role hook: this stage's parameters giving the coupling gain ``value`` at ω = ``w``."""
        return {"kf": float(value)}


class FractionalCoupling(ConstantCoupling):
    id = "fractional_coupling"
    summary = "rough electrodes: kf(f) = kf0/((j2πf)^a (j2πf+p)^b), constant-phase fractional load"
    explanation = __doc__
    requires = ()
    params = (
        ParamSpec("kf0", "N m/mol", 0.0, 1e6, "fractional load gain kf0 of eq. 14 (s in rad/s)"),
        ParamSpec("frac_a", "1", 0.0, 1.0, "fractional order a of eq. 14"),
        ParamSpec("frac_b", "1", 0.0, 1.0, "fractional order b of eq. 14"),
        ParamSpec("frac_p", "1/s", 0.0, 1e6, "pole p of the second factor of eq. 14 [rad/s]"),
        ParamSpec("frac_f_lo", "Hz", 1e-5, 1.0, "low-frequency corner below which the law flattens", optional=True,
                  default=1e-4),
    )
    diagnosis = {
        "free": ("frac_a",), "shape": ("frac_f_lo",),       # where a real device's law flattens (steps, holds)
        "bounds": {"frac_a": (0.0, 0.95), "frac_f_lo": (1e-4, 0.05)},
        "starts": [{"frac_a": 0.1}, {"frac_a": 0.5}, {"frac_a": 0.8}],
        "nested": True, "off": {"frac_a": 0.0, "frac_b": 0.0, "kf0": (1.0, "kf")},   # kf(s) = kf0 = kf
        "roles": {"gain": ("kf0", 1)},                       # kf0 takes over the base's kf
        "excitation": "a broadband record spanning at least one decade (constant log-log slope and phase), "
                      "ideally down to 0.1 Hz",
        "reveal": {"decades_min": 1.0},
        "signature": [("constant_slope_phase", 1.0), ("lf_excess_lag", 0.5), ("step_creep", 0.5)],
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: frac_a U(0.25, 0.6), kf0 so that |kf(1 Hz)| is the
        device's kf × U(0.7, 1.4)."""
        p = device.params
        a = float(rng.uniform(0.25, 0.6))
        w_lo = 2 * np.pi * p.get("frac_f_lo", 1e-4)
        kf0 = float(p["kf"] * rng.uniform(0.7, 1.4) * abs((2j * np.pi + w_lo) ** a))
        vals = {"frac_a": a, "frac_b": 0.0, "kf0": kf0}
        return device.with_params(**vals), vals

    #: Identification hints: why a parameter may have no effect ({name: sentence}).
    hints = {"frac_p": "frac_p has no effect when frac_b = 0",
             "kf": "the load is then kf0/((j2πf)^a (j2πf+p)^b) and a humidity map on kf acts as a ratio on kf0"}
    #: Fractional order a start translated from a constant gain begins with.
    START_ORDER = 0.3

    def gain_equivalent(self, p, w: float) -> float:
        return float(abs(self.kf(np.array([1j * w]), p)[0]))

    def gain_start(self, value: float, p, w: float) -> dict:
        q = {**p, "frac_a": self.START_ORDER, "kf0": 1.0, "frac_b": p.get("frac_b", 0.0), "frac_p": p.get("frac_p", 0.0)}
        return {"frac_a": self.START_ORDER, "kf0": float(value) / float(abs(self.kf(np.array([1j * w]), q)[0]))}

    def kf(self, s, p) -> np.ndarray:
        s = np.asarray(s, dtype=complex)
        w_lo = 2.0 * np.pi * p.get("frac_f_lo", 1e-4)
        return p["kf0"] / ((s + w_lo) ** p["frac_a"] * (s + max(p["frac_p"], w_lo)) ** p["frac_b"])
