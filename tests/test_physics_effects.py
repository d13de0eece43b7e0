"""Each effect against an independent limit or closed form."""
import numpy as np
import pytest
from scipy.integrate import solve_bvp

import physics
from physics import signals
from physics.device import load_device
from physics.effects.double_layer import DoubleLayer
from physics.solvers.frequency import frequency_response
from physics.model import ActuatorModel

F = np.logspace(-1, np.log10(50), 40)


# --- electrode_resistance ---------------------------------------------------------------
def test_no_resistance_limit():
    d = load_device("ipmc_pt_eg").with_params(Rs=1e-7)
    a = frequency_response(d, "electrode_resistance", F)
    b = frequency_response(d, "none", F)
    np.testing.assert_allclose(a.deflection, b.deflection, rtol=1e-6)
    np.testing.assert_allclose(a.current, b.current, rtol=1e-6)


def test_transmission_line_matches_a_boundary_value_solve():
    """U'' = 2 Rs Y_p U, U(0) = 1, U'(L) = 0 solved numerically (scipy solve_bvp) at 20 Hz."""
    m = ActuatorModel("ipmc_pt_eg", "electrode_resistance")
    p = dict(m.device.params)
    s = 2j * np.pi * 20.0
    d = DoubleLayer.props(p)
    Yp = s * DoubleLayer.charge_per_volt(np.array([s]), d)[0][0] + d.G_leak
    k2 = 2 * p["Rs"] * Yp
    L = m.free_length

    def rhs(z, y):  # y = [Re U, Im U, Re U', Im U']
        U = y[0] + 1j * y[1]
        dd = k2 * U
        return np.vstack([y[2], y[3], dd.real, dd.imag])

    def bc(ya, yb):
        return np.array([ya[0] - 1.0, ya[1], yb[2], yb[3]])

    z = np.linspace(0, L, 200)
    sol = solve_bvp(rhs, bc, z, np.zeros((4, z.size)), tol=1e-8, max_nodes=100000)
    assert sol.success
    U = m.stages["line"].distribution(np.array([s]), np.array([Yp]), p, z)[0]
    ref = sol.sol(z)
    np.testing.assert_allclose(U, ref[0] + 1j * ref[1], atol=1e-5)
    assert np.all(np.diff(np.abs(U)) < 0)     # the voltage falls along the strip


@pytest.mark.parametrize("mL", [0.3, 5.0, 200.0, 600.0, 5000.0])
def test_line_voltage_is_the_closed_form_on_short_and_very_long_lines(mL):
    """cosh(m(L−z))/cosh(mL) (Re m > 0, arg m = 30°) on short lines, and on lines so long that
    cosh overflows and e^{−2mL} underflows: there the same ratio written with the two decaying
    waves, (e^{−mz} + e^{−m(2L−z)})/(1 + e^{−2mL}), each exponential taken whole."""
    m = ActuatorModel("ipmc_pt_eg", "electrode_resistance")
    p = dict(m.device.params)
    L = m.free_length
    mc = mL / L * np.exp(1j * np.pi / 6)
    Yp = mc ** 2 / (2.0 * p["Rs"])
    z = np.linspace(0.0, L, 101)
    U = m.stages["line"].distribution(np.array([1j]), np.array([Yp]), p, z)[0]
    assert np.all(np.isfinite(U))
    if mL < 300:            # cosh itself overflows beyond ≈ 710
        np.testing.assert_allclose(U, np.cosh(mc * (L - z)) / np.cosh(mc * L), rtol=1e-12)
    waves = (np.exp(-mc * z) + np.exp(-mc * (2.0 * L - z))) / (1.0 + np.exp(-2.0 * mc * L))
    np.testing.assert_allclose(U, waves, rtol=1e-12, atol=1e-320)


def test_voltage_falls_along_the_strip_in_time():
    sig = signals.tone(1.0, 20.0, 1.0, 2000.0)
    r = physics.simulate("ipmc_pt_eg", "electrode_resistance", sig.t, sig.v, fields=("voltage",), periodic=True)
    amp = np.ptp(r.fields["voltage"], axis=1)
    assert np.all(np.diff(amp) < 0)
    assert amp[-1] < 0.9 * amp[0] < 0.9 * np.ptp(sig.v)


# --- solvent_diffusion ------------------------------------------------------------------
def test_solvent_back_diffusion_removes_the_dc_gain():
    f = np.logspace(-7, -5, 5)
    fr = frequency_response("ip2c_pedot_water", "solvent_diffusion", f)
    slope = np.diff(np.log(np.abs(fr.deflection))) / np.diff(np.log(f))
    np.testing.assert_allclose(slope, 1.0, atol=1e-3)      # B(s) ≈ s h²/(3 Ds): gain ∝ f → 0 at DC
    nodiff = frequency_response("ip2c_pedot_water", "none", f).magnitude
    h, Ds = 90e-6, 2.4e-10
    np.testing.assert_allclose(fr.magnitude / nodiff, 2 * np.pi * f * h ** 2 / (3 * Ds), rtol=1e-3)


def test_solvent_released_in_a_layer_matches_a_finite_volume_solve_and_its_thin_layer_limit():
    """B(s) with the solvent released in a face layer δ against the truth families' finite-volume
    line (600 cells, written separately) for δ/h from 1 % to 50 % over 10 µHz–1 kHz; δ → 0 is
    Crank's 1 − tanh(g)/g; the layer keeps more of the moment at high frequency; the reference
    solver, which releases the solvent in the double layer, refuses δ > 0."""
    from bench.truths.lines import solvent_moment
    from physics.errors import InputError
    from physics.reference.strip import ReferenceStrip
    m = ActuatorModel("ip2c_pedot_water", "solvent_diffusion")
    p = dict(m.device.params)
    h, f = 0.5 * p["t_polymer"], np.logspace(-5, 3, 60)
    s = 2j * np.pi * f
    B = m.stages["solvent"].solvent_factor
    for share in (0.01, 0.07, 0.5):
        got = B(s, {**p, "solvent_layer": share * h})
        want = solvent_moment(f, h, p["D_solvent"], share * h, n_cells=600)
        np.testing.assert_allclose(got, want, atol=2e-3)
    g = h * np.sqrt(s / p["D_solvent"])
    np.testing.assert_allclose(B(s, {**p, "solvent_layer": 1e-6 * h}), 1 - np.tanh(g) / g, atol=2e-6)
    hi = f > 10 * p["D_solvent"] / h ** 2
    assert np.all(np.abs(B(s, {**p, "solvent_layer": 0.1 * h}))[hi] > np.abs(B(s, p))[hi])
    with pytest.raises(InputError, match="solvent_layer"):
        ReferenceStrip(m.device.with_params(solvent_layer=5e-6), ["solvent_diffusion"])


def test_step_relaxation_rate_is_the_first_diffusion_mode():
    """After a voltage step the deflection relaxes back with rate Ds (π/2h)² (slowest mode of
    diffusion on [0, h] with a Dirichlet midplane and a no-flux face)."""
    d = load_device("ip2c_pedot_water")
    for Ds in (2.4e-10, 9.6e-10):
        dev = d.with_params(D_solvent=Ds)
        sig = signals.steps([1.0], [0.05], duration=120.0, fs=20.0)
        r = physics.simulate(dev, "solvent_diffusion", sig.t, sig.v, hold="linear")
        rate = Ds * (np.pi / d["t_polymer"]) ** 2
        sel = (sig.t > 4.0 / rate) & (sig.t < 8.0 / rate)
        fit = np.polyfit(sig.t[sel], np.log(r.deflection[sel]), 1)[0]
        assert -fit == pytest.approx(rate, rel=0.02)


# --- fractional_coupling ----------------------------------------------------------------
def test_fractional_coupling_has_the_thesis_constant_phase():
    """Thesis §4.1 case II: the phase of kf(f) = 0.095/(j2πf)^0.6 is constant at −54°."""
    m = ActuatorModel("ipmc_pt_eg", "fractional_coupling")
    p = dict(m.device.params)
    f = np.logspace(-1, np.log10(50), 20)
    kf = m.stages["coupling"].kf(2j * np.pi * f, p)
    np.testing.assert_allclose(np.degrees(np.angle(kf)), -54.0, atol=0.05)
    slope = np.diff(np.log(np.abs(kf))) / np.diff(np.log(f))
    np.testing.assert_allclose(slope, -0.6, atol=1e-3)


# --- viscoelastic -----------------------------------------------------------------------
@pytest.mark.parametrize("device,table", [("ipmc_pt_eg", "dma"), ("ipmc_pt_eg", "dma_membrane"),
                                          ("ip2c_pedot_water", "dma")])
def test_prony_fit_reproduces_the_dma_table_and_is_passive(device, table):
    from physics.effects.viscoelastic import fit_prony
    t = load_device(device).tables[table]
    pr = fit_prony(tuple(t["freq"]), tuple(t["storage"]), tuple(t["loss"]))
    E = pr(2j * np.pi * t["freq"])
    np.testing.assert_allclose(E.real, t["storage"], rtol=0.04)
    np.testing.assert_allclose(E.imag, t["loss"], rtol=0.01)
    Ew = pr(2j * np.pi * np.logspace(-6, 6, 400))
    assert np.all(Ew.imag >= 0) and np.all(Ew.real > 0)


def test_the_free_shape_holds_a_power_law_from_ve_f_lo_and_a_plateau_below():
    """A power-law modulus E* ∝ (jω)^α is causal with tan δ = tan(απ/2) and a storage rise of
    10^α − 1 per decade (Kramers–Kronig): the free shape given those reproduces it from ve_f_lo
    to the table's top, and below ve_f_lo the relaxation has ended (a plateau)."""
    from physics.effects.viscoelastic import Viscoelastic
    dev = load_device("ipmc_pt_eg")
    alpha, f_lo = 0.05, 0.01
    shape = {"ve_slope": 10 ** alpha - 1, "ve_tan_delta": np.tan(alpha * np.pi / 2)}
    ve = Viscoelastic(dev)
    pr = ve.polymer_modulus({**dev.params, **shape, "ve_f_lo": f_lo}, False)
    f = np.geomspace(3 * f_lo, 20.0, 30)
    E = pr(2j * np.pi * f)
    E1 = np.interp(0.0, np.log10(dev.tables["dma"]["freq"]), dev.tables["dma"]["storage"])
    np.testing.assert_allclose(E.real, E1 * f ** alpha, rtol=0.03)
    np.testing.assert_allclose(E.imag / E.real, shape["ve_tan_delta"], rtol=0.15)
    slow = pr(2j * np.pi * np.array([f_lo / 300, f_lo / 3000]))
    assert abs(slow[0] / slow[1] - 1) < 0.01 and slow[0].real < 0.97 * E1 * f_lo ** alpha
    # without ve_f_lo the shape starts at the table's lowest frequency, as before
    a = ve.polymer_modulus({**dev.params, **shape}, False)
    b = ve.polymer_modulus({**dev.params, **shape, "ve_f_lo": float(dev.tables["dma"]["freq"].min())}, False)
    assert a == b


# --- humidity ---------------------------------------------------------------------------
def test_resonance_moves_with_rh_as_sqrt_of_table_V_modulus():
    table_v = {40: 0.49, 60: 0.39, 80: 0.225, 100: 0.18}  # GPa, thesis Table V
    d = load_device("ipmc_pt_eg").with_params(beta_f=1e-7)
    f1 = {}
    for rh in table_v:
        guess = frequency_response(d, "humidity", [1.0], rh=rh).natural_frequencies[0]
        f = np.linspace(0.98 * guess, 1.02 * guess, 4001)
        f1[rh] = f[np.argmax(frequency_response(d, "humidity", f, rh=rh).magnitude)]
    for rh, Y in table_v.items():
        assert f1[rh] / f1[100] == pytest.approx(np.sqrt(Y / table_v[100]), rel=5e-3)


def test_humidity_needs_rh_and_rejects_bad_values():
    with pytest.raises(physics.InputError, match="give rh"):
        frequency_response("ipmc_pt_eg", "humidity", F)
    with pytest.raises(physics.InputError, match="0–100"):
        frequency_response("ipmc_pt_eg", "humidity", F, rh=120)


def test_rh_outside_the_table_warns():
    with pytest.warns(UserWarning, match="outside the 40–100 % range"):
        frequency_response("ipmc_pt_eg", "humidity", F, rh=20)


def test_an_rh_series_warns_once_per_map_with_its_range_and_stays_silent_inside():
    import warnings
    from physics.effects.humidity import Humidity
    h = Humidity(load_device("ipmc_pt_eg"))
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        f = h.factors(np.array([30.0, 45.0, 60.0]))
    assert sorted(str(w.message) for w in got) == [
        f"RH 30–60 % is outside the 40–100 % range of the {name} map of device 'ipmc_pt_eg'; the end value is used"
        for name in sorted(f)]
    assert float(f["Y"][0]) == pytest.approx(float(h.factors(40.0)["Y"]))     # the end value is used
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h.factors(np.array([40.0, 70.0, 100.0]))
        h.factors(np.array([]))


def test_hygrometer_jitter_about_a_maps_end_levels_does_not_warn():
    """A map identified per RH level spans the levels' means (here 40.2–79.8 %); the readings of
    the records it came from jitter about them: within RH_MARGIN the end value is used silently,
    beyond it the warning names the range with enough digits to tell the two apart."""
    import dataclasses
    import warnings
    from physics.effects.humidity import RH_MARGIN, Humidity
    dev = load_device("ipmc_pt_eg")
    m = dev.humidity_maps["Y"]
    narrow = dataclasses.replace(m, rh=np.array([40.2, 60.3, 79.8]),
                                 values=np.interp([40.2, 60.3, 79.8], m.rh, m.values))
    h = Humidity(dataclasses.replace(dev, humidity_maps={"Y": narrow}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = h.factors(np.array([40.16, 60.0, 79.85, 40.2 - 0.9 * RH_MARGIN]))
    assert float(f["Y"][0]) == pytest.approx(float(h.factors(40.2)["Y"]))
    with pytest.warns(UserWarning, match=r"RH 38\.9–60 % is outside the 40\.2–79\.8 % range of the Y map"):
        h.factors(np.array([40.2 - 1.3 * RH_MARGIN, 60.0]))


# --- thesis behaviour ---------------------------------------------------------------------
def test_ipmc_at_full_hydration_is_an_underdamped_resonator_inside_1_50_Hz():
    f = np.logspace(0, np.log10(50), 400)
    fr = frequency_response("ipmc_pt_eg", "default", f, rh=100)
    fres, peak = fr.resonance()
    assert 1.0 < fres < 50.0
    assert peak > 2.0 * fr.magnitude[0]                       # resonant amplification
    drop = fr.phase_deg[0] - fr.phase_deg[-1]
    assert 150.0 < drop < 230.0                                # second-order phase roll-off


def test_ip2c_low_frequency_response_is_fractional():
    """Eq. 16: below the resonance the IP2C's gain falls with a fractional slope."""
    f = np.logspace(-1, 0.5, 20)
    fr = frequency_response("ip2c_pedot_water", "fractional_coupling", f, rh=100)
    slope = np.polyfit(np.log(f), np.log(fr.magnitude), 1)[0]
    assert -0.8 < slope < -0.5
