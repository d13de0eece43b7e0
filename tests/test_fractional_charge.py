"""The constant-phase double layer (``fractional_charge``) against the closed-form laws of a
constant-phase element: admittance phase (1 − a)·90° and charge ∝ f^(−a) in the frequency
domain, charge ∝ t^a/Γ(1 + a) after a voltage step in the time domain."""
import math

import numpy as np
import pytest

import physics
from physics.errors import ModelError
from physics.model import ActuatorModel
from physics.solvers.frequency import frequency_response
from physics.solvers.timedomain import simulate

A = 0.45


def _model(effects, **params):
    return ActuatorModel(physics.load_device("ipmc_pt_eg").with_params(**params), effects)


def _charging_current(m, f):
    """Input current per volt less the electronic leakage's [A/V]."""
    p = m.params_at(None)
    leak = m.double_layer_props(p).G_leak * p["width"] * p["L_total"]
    return frequency_response(m, None, f).current - leak


def test_the_input_admittance_has_the_constant_phase_of_its_order():
    m = _model("fractional_charge", cpe_a=A, cpe_f_lo=1e-5)
    f = np.geomspace(0.05, 20.0, 12)               # far above the corner, far below the bulk RC corner
    cur = _charging_current(m, f)
    phase = np.degrees(np.angle(cur))
    slope = np.polyfit(np.log(f), np.log(np.abs(cur)), 1)[0]
    assert np.allclose(phase, 90.0 * (1.0 - A), atol=0.5)
    assert slope == pytest.approx(1.0 - A, abs=0.01)
    # the ideal double layer is a capacitor there: 90°, slope 1
    ideal = _charging_current(_model("none"), f)
    assert np.allclose(np.degrees(np.angle(ideal)), 90.0, atol=0.5)


def test_after_a_voltage_step_the_charge_grows_as_t_to_the_order():
    """Q(t) = C0 (ω_r)^a t^a / Γ(1 + a) for τ_bulk ≪ t ≪ 1/ω_lo (the inverse Laplace transform of
    C0 (ω_r/s)^a / s), checked on the time solver's realisation through the input current."""
    m = _model("fractional_charge", cpe_a=A, cpe_f_lo=1e-5)
    fs, T = 2000.0, 20.0
    t = np.arange(int(T * fs)) / fs
    v = np.where(t >= 0.05, 0.1, 0.0)
    p = m.params_at(None)
    d = m.double_layer_props(p)
    area = p["width"] * p["L_total"]
    r = simulate(m, None, t, v)
    charge = np.cumsum(r.current - d.G_leak * area * v) / fs      # [C], the leakage's current left out
    ts = np.array([0.5, 1.0, 2.0, 5.0, 10.0])
    q = np.interp(ts + 0.05, t, charge) / area
    w_r = 2.0 * np.pi * 1.0
    expected = d.C0 * 0.1 * w_r ** A * ts ** A / math.gamma(1.0 + A)
    assert np.allclose(q, expected, rtol=0.02)
    assert np.polyfit(np.log(ts), np.log(q), 1)[0] == pytest.approx(A, abs=0.01)


def test_its_order_zero_is_the_ideal_double_layer_and_the_stepper_refuses_a_rough_one():
    f = np.geomspace(0.1, 10.0, 5)
    a = frequency_response(_model("electrode_resistance,fractional_charge", cpe_a=0.0), None, f).deflection
    b = frequency_response(_model("electrode_resistance"), None, f).deflection
    assert np.array_equal(a, b)
    t = np.arange(200) / 100.0
    with pytest.raises(ModelError, match="fractional_charge"):
        simulate(_model("thermal,fractional_charge", cpe_a=A), None, t, np.sin(t))


def test_the_electrode_line_sees_the_constant_phase_charge():
    """Equipotential electrodes: the deflection equals the fractional load constant's with the same
    law (the load follows the charge).  Behind resistive electrodes the two part: the line's
    attenuation follows the CPE's admittance, not the ideal capacitor's."""
    f = np.geomspace(0.1, 20.0, 9)
    kw = dict(cpe_a=A, cpe_f_lo=1e-3, frac_a=A, frac_f_lo=1e-3, frac_b=0.0, frac_p=0.0)
    dev = physics.load_device("ipmc_pt_eg")
    kf0 = dev["kf"] * math.hypot(2 * math.pi, 2 * math.pi * 1e-3) ** A
    ratios = []
    for line in ("", "electrode_resistance,"):
        charge = frequency_response(_model(line + "fractional_charge", **kw), None, f).deflection
        load = frequency_response(_model(line + "fractional_coupling", **kw, kf0=kf0), None, f).deflection
        ratios.append(np.abs(charge / load))
    assert np.allclose(ratios[0], 1.0, rtol=2e-3)
    assert np.max(np.abs(ratios[1] - 1.0)) > 0.05


def test_a_candidate_whose_default_is_off_starts_where_its_corner_acts():
    """Switched on at its declared default (cpe_a = 0, the "off" value) the corner ``cpe_f_lo``
    would have no effect at the start and be held, not fitted; the candidate starts at its spec's
    first start instead, where the corner changes the response."""
    from physics.diagnose.candidates import candidate_spec
    dev = physics.load_device("ipmc_pt_eg")
    spec = candidate_spec("fractional_charge", ["double_layer"], ["kf", "Y", "beta_f"], [], dev, (0.1, 20.0), 1)
    assert spec.start["cpe_a"] == pytest.approx(0.1) and "cpe_f_lo" in spec.free
    f = np.array([0.02, 0.05])
    lo, hi = (frequency_response(_model("fractional_charge", cpe_a=spec.start["cpe_a"], cpe_f_lo=c), None,
                                 f).deflection for c in (1e-4, 1e-2))
    assert np.min(np.abs(lo / hi - 1.0)) > 0.01
    # an effect whose device value is not its off value keeps the device's start
    rs = candidate_spec("electrode_resistance", ["double_layer"], ["kf", "Y", "beta_f"], [], dev, (0.1, 20.0), 1)
    assert rs.start["Rs"] == pytest.approx(dev["Rs"])
