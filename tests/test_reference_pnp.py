"""Reference PNP + solvent solver against closed forms and analytic limits (not against the
reduced model's code): Poisson–Boltzmann equilibrium, linearised PNP admittance, solvent
diffusion factor, Debye-layer resolution, mass conservation, temperature via eq. 6."""
import numpy as np
import pytest
from scipy.optimize import brentq

from physics.constants import EPS0, FARADAY, GAS_CONSTANT
from physics.device import load_device
from physics.reference.pnp import Integrator, Slab, SlabParams, graded_mesh


def _params(dev="ipmc_pt_eg"):
    return dict(load_device(dev).params)


def _slab(dev="ipmc_pt_eg", T=None, **mesh):
    prm = SlabParams.from_params(_params(dev), T)
    return Slab(prm, graded_mesh(prm.h, prm.lam, **mesh))


def _closed_form(p, s, T=None):
    """Linearised PNP (PHYSICS.md §3, written out here): ionic electrode charge per volt (the
    geometric κe/(2h) removed), interface cation excess per volt, Debye length, D."""
    T = p["T_ext"] if T is None else T
    kappa, C, D, h, z = EPS0 * p["eps_r"], p["C_anion"], p["D_cation"], 0.5 * p["t_polymer"], p["z_cation"]
    lam = np.sqrt(kappa * GAS_CONSTANT * T / (z ** 2 * FARADAY ** 2 * C))
    K = D / lam ** 2
    beta = np.sqrt((s + K) / D)
    th = np.tanh(beta * h)
    den = 2 * (s * beta * h + K * th)
    q = kappa * beta * (s + K) / den - kappa / (2 * h)
    c = K * kappa * beta ** 2 * th / den / (z * FARADAY)
    return q, c, lam, D, h, kappa


@pytest.mark.parametrize("dev", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_small_signal_admittance_matches_linearised_pnp(dev):
    p = _params(dev)
    slab = _slab(dev)
    f = np.logspace(-1, 4, 11)
    s = 2j * np.pi * f
    r = slab.small_signal(s)
    q, c, lam, D, h, kappa = _closed_form(p, s)
    assert np.max(np.abs(r["Q"] / q - 1)) < 2e-3
    assert np.max(np.abs(r["c_up"] / c - 1)) < 2e-3
    # low-frequency capacitance: two Debye layers in series
    assert r["Q"][0].real == pytest.approx(kappa / (2 * lam), rel=2e-3)
    # charging corner (−45° of Q/U) at D/(2πλh)
    fw = np.logspace(0, 5, 400)
    ph = -np.angle(slab.small_signal(2j * np.pi * fw)["Q"])
    corner = np.exp(np.interp(np.pi / 4, ph, np.log(fw)))
    assert corner == pytest.approx(D / (2 * np.pi * lam * h), rel=1e-2)


@pytest.mark.parametrize("dev", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_solvent_first_moment_follows_the_diffusion_factor(dev):
    """First moment of the solvent excess / (n⁺ × that of the cations) = 1 − tanh(g)/g, g = h sqrt(s/Ds)."""
    p = _params(dev)
    slab = _slab(dev)
    f = np.logspace(-1, np.log10(50), 6)
    s = 2j * np.pi * f
    r = slab.small_signal(s)
    g = 0.5 * p["t_polymer"] * np.sqrt(s / p["D_solvent"])
    B = 1 - np.tanh(g) / g
    ratio = 2 * r["m_up"] / (p["n_solvation"] * r["m_cat"])
    assert np.max(np.abs(ratio / B - 1)) < 2e-3


def test_under_resolved_debye_layer_is_detected():
    """With cells of tens of Debye lengths at the faces the charge is badly wrong: the closed-form
    check above has teeth, and the default mesh is the resolved one."""
    p = _params()
    s = 2j * np.pi * np.array([1.0])
    q = _closed_form(p, s)[0]
    lam = SlabParams.from_params(p).lam
    coarse = _slab(first=20 * lam, growth=1.2).small_signal(s)["Q"]
    fine = _slab().small_signal(s)["Q"]
    assert abs(coarse[0] / q[0] - 1) > 0.1
    assert abs(fine[0] / q[0] - 1) < 2e-3


def _pb_charge(U, T, kappa, C, z):
    """Plain Poisson–Boltzmann double layers in series at voltage U: the diffuse charge
    q(x) = sqrt(2 κe R T C⁻ G(x)), G(x) = x + e^{−x} − 1 (x = zFψ/RT across each layer), equal on
    both faces, potentials adding up to U.  Returns (charge [C/m²], cathode potential x_c < 0)."""
    u = z * FARADAY * U / (GAS_CONSTANT * T)
    G = lambda x: x + np.expm1(-x)  # noqa: E731
    x_a = brentq(lambda xa: G(xa) - G(xa - u), 0.5 * u, u)
    return np.sqrt(2 * kappa * GAS_CONSTANT * T * C * G(x_a)), x_a - u


@pytest.mark.parametrize("U", [0.1, 0.5, 2.0])
def test_equilibrium_is_poisson_boltzmann(U):
    slab = _slab()
    prm = slab.prm
    y, _ = Integrator(slab).equilibrium(U)
    o = slab.outputs(y, U)
    q, x_c = _pb_charge(U, prm.T, prm.kappa, prm.C_anion, prm.z)
    assert o["Q"][0] == pytest.approx(q, rel=1e-3)
    assert o["c_up"][0] + prm.C_anion == pytest.approx(prm.C_anion * np.exp(-x_c), rel=5e-3)
    # electroneutral bulk
    mid = np.abs(slab.x) < 0.5 * prm.h
    assert np.max(np.abs(y[0, 1::3][mid] - 1)) < 1e-8


def test_mass_conservation_to_round_off():
    """Cations and solvent are conserved to round-off through polarity reversals at 2 V."""
    slab = _slab("ip2c_pedot_water")
    integ = Integrator(slab)
    t = np.array([0.0, 1e-3, 0.05, 0.051, 0.1, 0.101, 0.2])
    v = np.array([0.0, 2.0, 2.0, -2.0, -2.0, 0.0, 0.0])
    y0 = slab.rest_state()
    c0, s0 = slab.totals(y0)
    out, _, (y, _) = integ.run(t, v, y0=(y0, np.zeros(1)))
    c1, s1 = slab.totals(y)
    assert integ.stats["steps"] > 20
    assert abs(c1[0] / c0[0] - 1) < 1e-12
    assert abs(s1[0] / s0[0] - 1) < 1e-13
    # the solvent excess itself integrates to zero (relative to how much solvent moved)
    moved = slab.prm.C_anion * np.abs(y[0, 2::3]) @ slab.V
    assert moved > 0 and abs(slab.prm.C_anion * y[0, 2::3] @ slab.V) < 1e-10 * moved


def test_mobility_follows_eq6_temperature():
    """µ = D/(RT): λ ∝ sqrt(T), so the low-frequency capacitance scales as T^(−1/2)."""
    p = _params("ip2c_pedot_water")
    s = 2j * np.pi * np.array([0.1, 100.0])
    T2 = 330.0
    r1, r2 = _slab("ip2c_pedot_water").small_signal(s), _slab("ip2c_pedot_water", T=T2).small_signal(s)
    assert r2["Q"][0].real / r1["Q"][0].real == pytest.approx(np.sqrt(p["T_ext"] / T2), rel=1e-3)
    q2 = _closed_form(p, s, T=T2)[0]
    assert np.max(np.abs(r2["Q"] / q2 - 1)) < 2e-3
