"""The reference strip against the reduced model (small signal, where both must agree), against
the quasi-static Poisson–Boltzmann charge at large signal, and the shared-beam helper."""
import numpy as np
import pytest
from scipy.optimize import brentq

from physics.constants import GAS_CONSTANT
from physics.errors import InputError
from physics.solvers.frequency import frequency_response
from physics.reference.strip import ReferenceStrip
from physics.solvers.timedomain import simulate, tip_from_interface_excess


def _nrmse(a, b):
    return np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2))


@pytest.mark.parametrize("dev", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_small_signal_frf_reduced_vs_reference(dev):
    """Default effects (electrode line, solvent diffusion, DMA modulus, …): 1 % / 1° over 0.1–50 Hz."""
    f = np.logspace(-1, np.log10(50), 25)
    ref = ReferenceStrip(dev, "default", rh=100)
    r = ref.frequency_response(f)
    red = frequency_response(ref.model, None, f, rh=100)
    ratio = r["deflection"] / red.deflection
    assert np.max(np.abs(np.abs(ratio) - 1)) < 0.01
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 1.0
    assert np.max(np.abs(r["current"] / red.current - 1)) < 0.01
    assert np.max(np.abs(r["cs_up"] / red.cs_up - 1)) < 0.01


def test_small_amplitude_time_domain_reduced_vs_reference():
    dev, fx = "ip2c_pedot_water", ["solvent_diffusion", "fractional_coupling", "viscoelastic"]
    t = np.arange(0, 2.0 + 1e-9, 1e-3)
    v = 0.01 * np.sin(2 * np.pi * t)
    ref = ReferenceStrip(dev, fx, rh=100)
    rr = ref.simulate(t, v)
    red = simulate(ref.model, None, t, v, rh=100, hold="linear")
    last = t >= 1.0
    assert _nrmse(rr.deflection[last], red.deflection[last]) < 0.01
    assert _nrmse(rr.current[last], red.current[last]) < 0.01
    assert _nrmse(rr.cs_up[last], red.cs_up[last]) < 0.01
    assert np.allclose(rr.cs_low, -rr.cs_up, rtol=1e-6, atol=1e-9 * np.max(np.abs(rr.cs_up)))
    assert rr.conservation["cation"] < 1e-12 and rr.conservation["solvent"] < 1e-12


def test_large_signal_charge_is_quasi_static_poisson_boltzmann():
    """Far below the charging corner (8 kHz) the 2 V charge follows the PB law of the
    instantaneous voltage: q = sqrt(2 κe RT C⁻ G(x_a)), G(x) = x + e^{−x} − 1, with the anode
    and cathode potentials x_a − x_c = U/V_T, G(x_a) = G(x_c); 3× below the linear κe U/(2λ)."""
    ref = ReferenceStrip("ipmc_pt_eg", ["solvent_diffusion"], rh=100)
    prm = ref.prm
    t = np.linspace(0, 0.25, 251)
    v = 2.0 * np.sin(2 * np.pi * t)
    rr = ref.simulate(t, v)
    G = lambda x: x + np.expm1(-x)  # noqa: E731
    qs = np.sqrt(2 * prm.kappa * GAS_CONSTANT * prm.T * prm.C_anion)
    for i in (25, 100, 250):
        u = v[i] / prm.V_T
        xa = brentq(lambda x: G(x) - G(x - u), 0.5 * u, u)
        assert rr.charge[1, i] == pytest.approx(qs * np.sqrt(G(xa)), rel=2e-3)
    lin = prm.kappa / (2 * prm.lam) * 2.0
    assert rr.charge[1, -1] < 0.4 * lin
    # the current is the charge's rate plus the leakage
    dq = np.gradient(rr.charge[1], t) * ref.area.sum() + prm.G_leak * v * ref.area.sum()
    assert _nrmse(rr.current[5:-5], dq[5:-5]) < 5e-3


def test_tip_helper_reproduces_simulate():
    """The public helper is the same beam as simulate: fed simulate's own load it gives its tip."""
    t = np.arange(0, 1.0 + 1e-9, 1e-3)
    v = 0.5 * np.sin(2 * np.pi * 3 * t)
    res = simulate("ipmc_pt_eg", "default", t, v, rh=100, fields=("cation",))
    from physics.model import ActuatorModel
    from physics.solvers.timedomain import _line_grid
    m = ActuatorModel("ipmc_pt_eg", "default")
    edges = _line_grid(m, m.params_at(100), np.pi / 1e-3, None)
    ell = 0.5 * (res.fields["cation_upper"] - res.fields["cation_lower"])
    tip = tip_from_interface_excess(m, t, ell, edges, 100)
    assert np.max(np.abs(tip - res.deflection)) < 1e-9 * np.max(np.abs(res.deflection))


@pytest.mark.slow
def test_electrode_line_in_time_domain():
    """Slices through the electrode resistance: the voltage falls along the strip and the small-signal
    response matches the reduced transmission line (default effects, 10 Hz)."""
    t = np.arange(0, 0.3 + 1e-9, 2e-4)
    v = 0.01 * np.sin(2 * np.pi * 10 * t)
    ref = ReferenceStrip("ipmc_pt_eg", "default", rh=100)
    rr = ref.simulate(t, v)
    red = simulate(ref.model, None, t, v, rh=100, hold="linear")
    last = t >= 0.1
    amp = np.max(np.abs(rr.U[:, last]), axis=1)
    assert np.all(np.diff(amp) < 0)
    assert _nrmse(rr.deflection[last], red.deflection[last]) < 0.01
    assert _nrmse(rr.current[last], red.current[last]) < 0.01


@pytest.mark.slow
def test_eap_validate_writes_the_report(tmp_path):
    from nnmodel.app.cli import main
    assert main(["validate", "--quick", "--device", "ip2c_pedot_water", "--amplitudes-V", "0.05", "0.5", "2",
                 "--out", str(tmp_path)]) == 0
    import json
    figs = json.loads((tmp_path / "figures.json").read_text())
    ss = figs["ip2c_pedot_water"]["small_signal"]
    assert ss["max_mag_err_pct"] < 1 and ss["max_phase_err_deg"] < 1
    assert (tmp_path / "index.html").stat().st_size > 10000
    assert len(list(tmp_path.glob("*.png"))) == 3
    from browser_check import CHROMIUM, assert_clean, render
    if CHROMIUM:
        check, _ = render(tmp_path / "index.html")
        assert_clean(check, tmp_path / "index.html")


def _added_effects():
    """The shipped output effect (creep) and a throwaway load effect (a lag on the load)."""
    from pathlib import Path
    from physics.effects import LoadEffect, effect_classes_in_file
    from physics.parameters import ParamSpec
    (creep,) = effect_classes_in_file(Path(__file__).resolve().parents[1] / "examples" / "effects" / "creep.py")

    class LoadLag(LoadEffect):
        id = "load_lag_ref"
        params = (ParamSpec("lag_tau", "s", 1e-4, 10.0, "lag time constant", default=0.05),)

        def load_tf(self, p):
            return [1.0], [self.value(p, "lag_tau"), 1.0]
    return [creep, LoadLag]


@pytest.mark.parametrize("cls", _added_effects(), ids=lambda c: c.id)
def test_reference_path_keeps_added_output_and_load_effects(cls):
    """Regression (issue 26): tip_from_interface_excess (the reference solver's path to the tip)
    skipped the output effects that simulate applies; the reference FRF skipped both kinds."""
    from physics.effects import register, unregister
    from physics.model import ActuatorModel
    from physics.solvers.timedomain import _line_grid
    register(cls)
    try:
        t = np.arange(0, 2.0 + 1e-9, 1e-3)
        v = 0.5 * np.sin(2 * np.pi * 3 * t) + 0.3
        m = ActuatorModel("ipmc_pt_eg", f"default,+{cls.id}")
        res = simulate(m, None, t, v, rh=100, fields=("cation",))
        edges = _line_grid(m, m.params_at(100), np.pi / 1e-3, None)
        ell = 0.5 * (res.fields["cation_upper"] - res.fields["cation_lower"])
        tip = tip_from_interface_excess(m, t, ell, edges, 100)
        assert np.max(np.abs(tip - res.deflection)) < 1e-9 * np.max(np.abs(res.deflection))
        # the reference FRF carries the factor exactly: with / without = the effect's own factor
        f = np.array([0.01, 0.1, 1.0, 5.0])
        with_it = ReferenceStrip(m, rh=100).frequency_response(f)["deflection"]
        without = ReferenceStrip("ipmc_pt_eg", "default", rh=100).frequency_response(f)["deflection"]
        p, s = m.params_at(100), 2j * np.pi * f
        factor = m.output_response(s, p) * m.product("load_factor", s, p)
        assert np.max(np.abs(factor - 1)) > 0.05            # the effect matters at these frequencies
        np.testing.assert_allclose(with_it / without, factor, rtol=1e-9)
    finally:
        unregister(cls.id)


def test_reference_refuses_what_an_effect_says_it_cannot_reproduce():
    from physics.effects import CHAIN, register, unregister
    charge_law = next(c for c in CHAIN if c.stage == "charge_law")

    class OtherCharge(charge_law):          # another electrochemistry, silent about the reference
        id = "other_charge"
    register(OtherCharge)
    try:
        with pytest.raises(InputError, match="other_charge .it does not declare reference support"):
            ReferenceStrip("ipmc_pt_eg", "default,+other_charge", rh=100)
        OtherCharge.reference = "reproduced"    # a claim made on the class itself counts
        assert ReferenceStrip("ipmc_pt_eg", "default,+other_charge", rh=100).model is not None
    finally:
        unregister("other_charge")
    with pytest.raises(InputError, match="isothermal"):
        ReferenceStrip("ipmc_pt_eg", "default,+thermal", rh=100)
