"""Mechanics against closed-form Euler–Bernoulli beam theory."""
import numpy as np
import pytest

from physics.solvers.beam import CantileverModes, clamped_free_roots
from physics.constants import FARADAY, GAS_CONSTANT
from physics.device import load_device
from physics.solvers.frequency import frequency_response

TEXTBOOK_BETA_L = [1.8751, 4.6941, 7.8548, 10.9955]  # cos x cosh x = -1


def test_roots_match_textbook():
    np.testing.assert_allclose(clamped_free_roots(4), TEXTBOOK_BETA_L, atol=5e-5)


def test_modes_are_orthonormal_and_satisfy_the_boundary_conditions():
    m = CantileverModes(0.021, 6)
    z = np.linspace(0, m.L, 40001)
    P = m.phi(z)
    G = np.trapezoid(P[:, None, :] * P[None, :, :], z, axis=2) / m.L
    np.testing.assert_allclose(G, np.eye(6), atol=2e-6)
    np.testing.assert_allclose(m.phi([0.0])[:, 0], 0.0, atol=1e-12)          # clamped: w = 0
    np.testing.assert_allclose(m.dphi([0.0])[:, 0], 0.0, atol=1e-9)         # clamped: w' = 0
    np.testing.assert_allclose(m.ddphi([m.L])[:, 0] * m.L ** 2, 0.0, atol=1e-6)  # free: no moment
    np.testing.assert_allclose(np.abs(m.tip), 2.0, rtol=1e-9)


def test_uniform_active_moment_static_tip_is_ML2_over_2EI():
    """Modal expansion of a uniform eigen-moment M converges to M L²/(2 EI)."""
    L, EI, M = 0.021, 4.9e-7, 1e-6
    m = CantileverModes(L, 12)
    Q = M * m.moment_modal_loads([0.0, L])[:, 0]
    tip = np.sum(m.tip * Q / m.modal_stiffness(EI))
    assert tip == pytest.approx(M * L ** 2 / (2 * EI), rel=5e-3)
    # the exact static influence used for the quasi-static residual
    assert m.moment_static_tip([0.0, L])[0] * M / EI == pytest.approx(M * L ** 2 / (2 * EI), rel=1e-12)


def test_uniform_distributed_couple_static_tip_is_muL3_over_3EI():
    L, EI, mu = 0.021, 4.9e-7, 1e-3
    m = CantileverModes(L, 12)
    Q = mu * m.couple_modal_loads([0.0, L])[:, 0]
    assert np.sum(m.tip * Q / m.modal_stiffness(EI)) == pytest.approx(mu * L ** 3 / (3 * EI), rel=5e-3)


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_static_gain_of_the_whole_chain_equals_closed_form(device):
    """DC tip deflection per volt = kf · n⁺ C⁻/(2 V_T) · 2 h w · L³/(3 EI) (uniform couple from
    the Boltzmann interface excess, no resistive drop, elastic homogeneous beam)."""
    d = load_device(device)
    p = d.params
    fr = frequency_response(d, "none", [1e-4], rh=None)
    V_T = GAS_CONSTANT * p["T_ext"] / FARADAY
    L = p["L_total"] - p["L_clamp"]
    EI = p["Y"] * p["width"] * p["t_polymer"] ** 3 / 12
    mu = p["kf"] * p["n_solvation"] * p["C_anion"] / (2 * V_T) * p["t_polymer"] * p["width"]
    assert fr.deflection[0].real == pytest.approx(mu * L ** 3 / (3 * EI), rel=1e-4)
    assert abs(fr.deflection[0].imag) < 1e-3 * abs(fr.deflection[0])


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_first_three_natural_frequencies(device):
    """Resonance peaks of the lightly damped model = (βnL)² sqrt(EI/ρA)/(2π L²) within 0.5 %."""
    d = load_device(device).with_params(beta_f=1e-7)
    p = d.params
    L = p["L_total"] - p["L_clamp"]
    EI = p["Y"] * p["width"] * p["t_polymer"] ** 3 / 12
    rhoA = p["rho_polymer"] * p["width"] * p["t_polymer"]
    for bl in TEXTBOOK_BETA_L[:3]:
        fn = bl ** 2 * np.sqrt(EI / rhoA) / (2 * np.pi * L ** 2)
        f = np.linspace(0.97 * fn, 1.03 * fn, 3001)
        mag = np.abs(frequency_response(d, "none", f, n_modes=4).deflection)
        assert f[np.argmax(mag)] == pytest.approx(fn, rel=5e-3)


def test_layered_section_matches_numerical_integration():
    """EI of the Pt/Nafion/Pt sandwich = ∫ E(y) y² dA (parallel-axis theorem, numerically)."""
    from physics.model import ActuatorModel
    m = ActuatorModel("ipmc_pt_eg", "layered_beam")
    p = dict(m.device.params)
    EI, rhoA = m.section(p)
    h, te, w = p["t_polymer"] / 2, p["t_electrode"], p["width"]
    y = np.linspace(-(h + te), h + te, 200001)
    E = np.where(np.abs(y) <= h, p["Y_polymer"], p["Y_electrode"])
    rho = np.where(np.abs(y) <= h, p["rho_polymer"], p["rho_electrode"])
    assert EI(np.array([0.0]))[0].real == pytest.approx(w * np.trapezoid(E * y ** 2, y), rel=1e-4)
    assert rhoA == pytest.approx(w * np.trapezoid(rho, y), rel=1e-4)
