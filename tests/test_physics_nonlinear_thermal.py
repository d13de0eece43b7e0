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


def test_a_lattice_too_small_for_the_fixed_anions_is_refused_by_name():
    """C_max ≤ C⁻ (ν ≥ 1) has no Bikerman law: the error names both concentrations and the
    search-bound flag instead of a NaN deep inside a fit."""
    dev = load_device("ipmc_pt_eg").with_params(C_max=50.0)
    t = np.arange(0, 0.5, 1e-3)
    with pytest.raises(physics.InputError, match=r"C_max = 50 mol/m\^3 of nonlinear_charge is not above .*C_anion = 1100") as exc:
        physics.simulate(dev, "none,+nonlinear_charge", t=t, voltage=np.sin(2 * np.pi * t), rh=60.0)
    assert exc.value.params == ("bounds",)


@pytest.mark.parametrize("c_max,share", [(np.inf, 1.0), (5000.0, 1.0), (5000.0, 0.2)])
def test_stepper_law_matches_a_root_solve_on_every_branch(c_max, share):
    """The time stepper's compiled law (one interpolation in a ±q̂ table) against an
    independent Poisson–Boltzmann root solve, each branch at its own temperature.  Behind
    compact layers taking 1 − d of the small-signal voltage, the diffuse layers are those of
    charge d·Q and the compact layers add (1 − d)·Q/C0, C0 the pair's small-signal capacitance
    (here from the root solve itself)."""
    dev = load_device("ipmc_pt_eg").with_params(C_max=c_max, diffuse_share=share)
    p = dict(dev.params)
    T = p["T_ext"] + np.array([0.0, 5.0, 20.0, 40.0])
    d = DoubleLayer.props(p, T)
    law = NonlinearCharge(dev).compiled(d, p)
    Q = np.array([-0.3, 1e-3, 0.05, 0.3])                  # C/m²
    U, dU = law.evaluate(Q)
    c_up, c_low = law.excess(np.vstack([Q, Q]))            # (samples, branches)
    C, nu = p["C_anion"], p["C_anion"] / c_max
    G = (lambda x: x + np.log1p(-nu + nu * np.exp(-x)) / nu) if nu > 0 else (lambda x: x + np.expm1(-x))
    excess = lambda x: C * (np.exp(-x) / (1 - nu + nu * np.exp(-x)) - 1)  # noqa: E731

    def solve(q, k):
        qh2 = q * q / (2 * d.kappa * 8.314462618 * T[k] * C)
        x_pos, x_neg = brentq(lambda x: G(x) - qh2, 0, 500), brentq(lambda x: G(x) - qh2, -60, 0)
        return (x_neg, x_pos) if q > 0 else (x_pos, x_neg)   # (upper, lower): Q > 0 depletes the lower face

    for k, q in enumerate(Q):
        V_T = 8.314462618 * T[k] / 96485.33212
        inv_c0 = V_T * -np.subtract(*solve(1e-7, k)) / 1e-7           # small-signal 1/C0 of the bare pair
        x_up, x_low = solve(share * q, k)
        assert U[k] == pytest.approx(V_T * (x_low - x_up) + (1 - share) * q * inv_c0, rel=1e-4)
        dq = 1e-6 * abs(q)
        slope = share * V_T * (np.subtract(*solve(share * (q - dq), k)) - np.subtract(*solve(share * (q + dq), k))) \
            / (2 * share * dq) + (1 - share) * inv_c0
        assert dU[k] == pytest.approx(slope, rel=1e-3)
        assert c_up[1, k] == pytest.approx(excess(x_up), rel=1e-4)
        assert c_low[1, k] == pytest.approx(excess(x_low), rel=1e-4)


@pytest.mark.parametrize("share", [1.0, 0.2])
def test_small_signal_limit_matches_its_frequency_response(share):
    dev = load_device("ipmc_pt_eg").with_params(diffuse_share=share)
    sig = signals.tone(1e-3, 2.0, 6.0, 500.0)
    r = physics.simulate(dev, "nonlinear_charge", sig.t, sig.v)
    fr = physics.frequency_response(dev, "nonlinear_charge", [2.0])
    last = sig.t > 2.0
    H = _tone_fit(sig.t[last], r.deflection[last], 2.0) / _tone_fit(sig.t[last], sig.v[last], 2.0)
    assert abs(H / fr.deflection[0] - 1) < 0.01
    plain = physics.frequency_response("ipmc_pt_eg", "nonlinear_charge", [2.0])
    assert fr.deflection[0] == pytest.approx(plain.deflection[0], rel=1e-12)    # the same small-signal law


def test_compact_layers_move_the_saturation_to_volts():
    """Bare diffuse layers leave their small-signal line at a few tenths of a volt.  Behind
    compact layers taking 1 − d of the small-signal voltage (the same small-signal capacitance)
    the onset moves as d^(−3/2): the pair's law is odd in the charge, its first departure from
    the line cubic, U_PB(q) ≈ q/C0 + a q³, and U = Q/C0 + a d³ Q³ departs by a given share at
    Q ∝ d^(−3/2).  With d = 0.2 the strip stays on its line to about a volt."""
    from scipy.optimize import brentq
    dev = load_device("ipmc_pt_eg")
    p = dict(dev.params)
    d = DoubleLayer.props(p)
    law = NonlinearCharge(dev)
    c_small = d.C0 * np.sqrt(1 - law.nu(p))

    def onset(ds):                         # the voltage at which the charge is 5 % below its line
        q_ = {**p, "diffuse_share": ds}

        def share(u):
            Q = brentq(lambda q: float(law.potential(np.array([q]), d, q_)[0][0]) - u, 0.0, 1.01 * c_small * u)
            return Q / (c_small * u)
        return brentq(lambda u: share(u) - 0.95, 1e-3, 5.0)

    bare = onset(1.0)
    assert bare < 0.3
    for ds in (0.5, 0.3, 0.2):
        assert onset(ds) / bare == pytest.approx(ds ** -1.5, rel=0.05)
    assert onset(0.2) > 0.5


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
    from physics.solvers import stepper
    from physics.model import ActuatorModel
    from physics.solvers.discretisation import segment_edges
    m = ActuatorModel("ipmc_pt_eg", "thermal,electrode_resistance")
    p = dict(m.device.params)
    edges = segment_edges(m.free_length, 16, 1.5)
    t = np.arange(0, 400.0, 0.5)
    v0 = 1.5
    out = stepper.run(m, m.params_at, t, np.full(t.size, v0), np.full(t.size, 100.0), edges, {"T"})
    net = m.stages["temperature"].network(p, edges)
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


def test_newton_stopping_rule_matches_newton_iterated_to_convergence(monkeypatch):
    """The stage solver may stop after one Newton update (when quadratic convergence predicts
    the tolerance) and takes the current from the stage equation; the record must agree with
    stages solved by plain Newton iterated to round-off."""
    from scipy.linalg import solve

    from physics.solvers import stepper
    sig = signals.sweep(2.0, 0.5, 50.0, 4.0, 1000.0)
    effects = "nonlinear_charge,thermal,electrode_resistance"
    r = physics.simulate("ipmc_pt_eg", effects, sig.t, sig.v)

    def converged(self, net, base, hg, vin, Z, tol, state=True):
        for _ in range(50):
            f, U, _, dU = net.evaluate(Z, vin)
            dZ = solve(net.newton_matrix(dU, hg), base + hg * f - Z)
            Z = Z + dZ
            if np.abs(dZ).max() <= 1e-13 * (np.abs(Z).max() + net.q_scale):
                f, U = net.evaluate(Z, vin)[:2]
                return Z, (f, U)
        raise AssertionError("reference Newton did not converge")

    monkeypatch.setattr(stepper._Newton, "solve", converged)
    ref = physics.simulate("ipmc_pt_eg", effects, sig.t, sig.v)
    assert np.abs(r.deflection - ref.deflection).max() < 1e-6 * np.ptp(ref.deflection)
    assert np.abs(r.current - ref.current).max() < 1e-4 * np.ptp(ref.current)


def test_constant_input_at_rest_is_held_without_stepping(monkeypatch):
    """Between the edges of a pulse the stepper holds the state once it is at rest; the record
    must equal the one stepped through every sample, and far fewer evaluations are made."""
    from physics.solvers import stepper
    sig = signals.square(2.0, 2.0, 6.0, 1, 1000.0)
    effects = "nonlinear_charge,electrode_resistance"
    calls = {"n": 0}
    evaluate = stepper.BranchNetwork.evaluate

    def counted(self, Q, vin):
        calls["n"] += 1
        return evaluate(self, Q, vin)

    monkeypatch.setattr(stepper.BranchNetwork, "evaluate", counted)
    held = physics.simulate("ipmc_pt_eg", effects, sig.t, sig.v, fields=("voltage", "cation"))
    n_held, calls["n"] = calls["n"], 0
    monkeypatch.setattr(stepper, "_constant_input_runs", lambda v, vs, rk: np.arange(v.size))
    stepped = physics.simulate("ipmc_pt_eg", effects, sig.t, sig.v, fields=("voltage", "cation"))
    assert n_held < 0.5 * calls["n"]
    for a, b in ((held.deflection, stepped.deflection), (held.current, stepped.current),
                 (held.fields["voltage"], stepped.fields["voltage"]),
                 (held.fields["cation_upper"], stepped.fields["cation_upper"])):
        assert np.abs(a - b).max() < 1e-6 * np.ptp(b)


def test_the_stepper_takes_the_parameters_at_the_records_own_rh():
    """The large-signal stepper rebuilds its network when the RH moves by a quarter percent; it
    took the parameters at the rounded RH, so a record at 40.3 % under a map fitted per RH level
    (levels at 40.3 and 79.7 %, as ``eap diagnose`` fits them) was evaluated at 40.25 %, outside
    the map, and every diagnosis of such records warned "RH 40.2–40.2 % is outside the 40.3–79.7 %
    range".  At the level's own RH there is no warning, and the result is the map's value there:
    the same as a device whose map is constant at that value."""
    import dataclasses
    import warnings
    dev = load_device("ipmc_pt_eg")
    def maps(ends):         # absolute maps, as a per-RH fit writes them
        return {n: dataclasses.replace(m, rh=np.array([40.3, 79.7]), values=dev.params[n] * np.array(ends),
                                       mode="absolute") for n, m in dev.humidity_maps.items()}
    fitted = dataclasses.replace(dev, humidity_maps=maps([1.3, 0.7]))
    flat = dataclasses.replace(dev, humidity_maps=maps([1.3, 1.3]))
    sig = signals.tone(1.0, 1.0, 1.5, 200.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = physics.simulate(fitted, "nonlinear_charge,humidity", sig.t, sig.v, rh=40.3)
    ref = physics.simulate(flat, "nonlinear_charge,humidity", sig.t, sig.v, rh=40.3)
    np.testing.assert_allclose(r.deflection, ref.deflection, rtol=1e-9, atol=1e-15)


def test_large_signal_charge_along_the_resistive_electrodes_matches_an_independent_ladder():
    """The stepper's network (clamp branch at Vin, free segments on the electrode ladder, implicit
    SDIRK with Newton stages) against a line discretised here by another route: 80 equal
    finite-volume cells of the free length, link conductance w/(2 R_s Δz), node voltages from the
    banded Kirchhoff system at each instant, and scipy's Radau integrator.  Only the equilibrium law
    (checked above against a root solve) and the branch constants R_b, σ/(2h) are the model's.  At
    2 V the compact-layer law changes the charge by ~44 % of its range against a nearly linear
    law, so agreement within 2e-3 of the charge's range (1e-2 of the current's, rich in harmonics)
    tests the large-signal line itself (measured: 7e-4 and 4e-3)."""
    from scipy.integrate import solve_ivp
    from scipy.linalg import solve_banded

    from physics.model import ActuatorModel
    dev = load_device("ipmc_pt_eg").with_params(Rs=40.0, diffuse_share=0.5)
    effects = "nonlinear_charge,electrode_resistance"
    sig = signals.tone(2.0, 5.0, 0.3, 2000.0)
    r = physics.simulate(dev, effects, sig.t, sig.v, fields=("charge",))
    model = ActuatorModel(dev, effects)
    p = dict(dev.params)
    d = model.double_layer_props(p)
    law = model.stages["charge_law"].compiled(d, p)
    Rb, G, w = float(d.R_bulk), float(d.G_leak), p["width"]
    n = 80
    dz = (p["L_total"] - p["L_clamp"]) / n
    zc, area, a0 = (np.arange(n) + 0.5) * dz, w * dz, w * p["L_clamp"]
    g = np.full(n, w / (2 * p["Rs"] * dz))
    g[0] *= 2.0                                       # the clamp's edge to the first cell's centre
    band = np.zeros((3, n))
    band[1] = g + np.append(g[1:], 0.0) + area * (1 / Rb + G)
    band[0, 1:] = band[2, :-1] = -g[1:]

    def nodes(u_eq, v):
        rhs = area * u_eq / Rb
        rhs[0] += g[0] * v
        return solve_banded((1, 1), band, rhs)

    def rate(t, y):
        v = np.interp(t, sig.t, sig.v)
        u_eq = law.evaluate(y)[0]
        return np.concatenate([[v - u_eq[0]], nodes(u_eq[1:], v) - u_eq[1:]]) / Rb

    sol = solve_ivp(rate, (sig.t[0], sig.t[-1]), np.zeros(n + 1), method="Radau", t_eval=sig.t,
                    rtol=1e-6, atol=1e-8, max_step=5e-4)
    assert sol.status == 0
    current = np.empty(sig.t.size)
    for k, v in enumerate(sig.v):
        u_eq = law.evaluate(sol.y[:, k])[0]
        current[k] = a0 * ((v - u_eq[0]) / Rb + G * v) + g[0] * (v - nodes(u_eq[1:], v)[0])
    charge = np.array([np.interp(r.z, zc, q) for q in sol.y[1:].T]).T
    late = sig.t > 0.1
    span = np.ptp(r.fields["charge"])
    assert np.abs(charge - r.fields["charge"])[:, late].max() < 2e-3 * span
    assert np.abs(current - r.current)[late].max() < 1e-2 * np.ptp(r.current)
    near_linear = physics.simulate(dev.with_params(diffuse_share=1e-3), effects, sig.t, sig.v, fields=("charge",))
    assert np.abs(near_linear.fields["charge"] - r.fields["charge"])[:, late].max() > 0.3 * span
