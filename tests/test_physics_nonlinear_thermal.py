"""Large-signal double layer and Joule heating."""
import numpy as np
import pytest
from scipy.optimize import brentq

import physics
from physics import signals
from physics.device import load_device
from physics.effects.double_layer import DoubleLayer
from physics.effects.nonlinear_charge import NonlinearCharge


def _tone_fit(t, y, f):
    """Complex amplitude of the component at f (least squares over whole periods)."""
    X = np.column_stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)])
    c = np.linalg.lstsq(X, y, rcond=None)[0]
    return c[0] - 1j * c[1]


def test_equilibrium_law_matches_an_independent_poisson_boltzmann_root_solve():
    """ν = 0 (plain PNP): both diffuse layers satisfy q² = 2 κe R T C⁻ (x + e^{−x} − 1)."""
    dev = load_device("ipmc_pt_eg").with_params(C_max=np.inf)
    p = dict(dev.params)
    d = DoubleLayer.props(p)
    law = NonlinearCharge(dev)
    Q = np.array([1e-4, 1e-2, 0.1, 0.3])
    U, dU, c_up, c_low = law.equilibrium(Q, d, p)
    scale = np.sqrt(2 * d.kappa * 8.314462618 * p["T_ext"] * p["C_anion"])
    G = lambda x: x + np.expm1(-x)  # noqa: E731
    for q, u, cu, cl in zip(Q, U, c_up, c_low):
        qh2 = (q / scale) ** 2
        x_dep = brentq(lambda x: G(x) - qh2, 0, 500)
        x_acc = brentq(lambda x: G(x) - qh2, -60, 0)
        assert u == pytest.approx(d.V_T * (x_dep - x_acc), rel=1e-4)
        assert cu == pytest.approx(p["C_anion"] * np.expm1(-x_acc), rel=1e-3)   # cathode accumulates
        assert cl == pytest.approx(p["C_anion"] * np.expm1(-x_dep), rel=1e-3)   # anode depletes ≥ −C⁻
    assert np.all(c_low >= -p["C_anion"])
    # depletion dominates at large charge: Q ≈ sqrt(2 κe F C⁻ ψ_anode)
    assert Q[-1] ** 2 / (2 * d.kappa * 96485.33212 * p["C_anion"] * U[-1]) == pytest.approx(1.0, abs=0.15)


def test_small_signal_limit_matches_its_frequency_response():
    sig = signals.tone(1e-3, 2.0, 6.0, 500.0)
    r = physics.simulate("ipmc_pt_eg", "nonlinear_charge", sig.t, sig.v)
    fr = physics.frequency_response("ipmc_pt_eg", "nonlinear_charge", [2.0])
    last = sig.t > 2.0
    H = _tone_fit(sig.t[last], r.deflection[last], 2.0) / _tone_fit(sig.t[last], sig.v[last], 2.0)
    assert abs(H / fr.deflection[0] - 1) < 0.01


def test_large_signal_saturates_and_is_odd_symmetric():
    gains = []
    for amp in (0.01, 0.5, 2.0):
        sig = signals.tone(amp, 1.0, 3.0, 400.0)
        r = physics.simulate("ipmc_pt_eg", "nonlinear_charge", sig.t, sig.v)
        gains.append(np.ptp(r.deflection[sig.t > 1.0]) / (2 * amp))
        if amp == 2.0:
            rn = physics.simulate("ipmc_pt_eg", "nonlinear_charge", sig.t, -sig.v)
            np.testing.assert_allclose(rn.deflection, -r.deflection, atol=1e-12 * np.ptp(r.deflection))
            late = sig.t > 1.0
            tt, cur = sig.t[late], r.current[late]
            h1, h2, h3 = (abs(_tone_fit(tt, cur, k * 1.0)) for k in (1, 2, 3))
            assert h3 > 1e-2 * h1 and h2 < 0.1 * h3       # odd harmonics only (symmetric cell)
    assert gains[0] > gains[1] > gains[2]


def test_thermal_steady_state_energy_balance():
    """At a constant voltage all electrical power leaves by convection: V·I = Σ h A (T − T_ext)."""
    from physics import stepper
    from physics.model import ActuatorModel
    from physics.strip import segment_edges
    m = ActuatorModel("ipmc_pt_eg", "thermal,electrode_resistance")
    p = dict(m.device.params)
    edges = segment_edges(m.free_length, 16, 1.5)
    t = np.arange(0, 400.0, 0.5)
    v0 = 1.5
    out = stepper.run(m, m.params_at, t, np.full(t.size, v0), np.full(t.size, 100.0), edges, {"T"})
    net = m.components["temperature"].network(p, edges)
    T = out["T"][:, -1]
    assert np.max(np.abs(out["T"][:, -1] - out["T"][:, -11])) < 1e-4     # steady state reached
    loss = np.sum(net.convection * (T - p["T_ext"]))
    assert loss == pytest.approx(v0 * out["current"][-1], rel=2e-3)
    assert T.max() - p["T_ext"] > 0.05


def test_heating_is_strongest_near_the_clamp_and_steeper_for_pedot():
    """Thesis Fig. 31: temperature highest near the clamp, steeper profile for PEDOT:PSS."""
    sig = signals.tone(2.0, 1.0, 40.0, 100.0)
    drops = {}
    for dev in ("ipmc_pt_eg", "ip2c_pedot_water"):
        r = physics.simulate(dev, "thermal,electrode_resistance", sig.t, sig.v, fields=("temperature",))
        T = r.fields["temperature"][:, -1] - 298.15
        assert np.argmax(T) < T.size // 3
        assert T.min() > 0
        drops[dev] = (T.max() - T[-1]) / T.max()
    assert drops["ip2c_pedot_water"] > drops["ipmc_pt_eg"]


def test_isothermal_temperature_field_is_ambient():
    t = np.arange(0, 1, 1e-2)
    r = physics.simulate("ipmc_pt_eg", "none", t, np.sin(t), fields=("temperature",))
    np.testing.assert_allclose(r.fields["temperature"], 298.15)
