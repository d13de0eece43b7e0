"""The linearised PNP double layer against its analytic limits."""
import numpy as np
import pytest

from physics.constants import EPS0, FARADAY, GAS_CONSTANT
from physics.device import load_device
from physics.effects.double_layer import DoubleLayer
from physics.solvers.frequency import frequency_response


def debye(p):
    return np.sqrt(EPS0 * p["eps_r"] * GAS_CONSTANT * p["T_ext"] / (FARADAY ** 2 * p["C_anion"]))


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_low_frequency_capacitance_is_two_debye_layers_in_series(device):
    d = load_device(device).with_params(sigma_polymer=0.0)
    p = d.params
    f = 1e-3
    Z = frequency_response(d, "none", [f]).impedance[0]
    area = p["width"] * p["L_total"]
    C_area = 1.0 / (2 * np.pi * f * abs(Z) * area)
    assert C_area == pytest.approx(EPS0 * p["eps_r"] / (2 * debye(p)), rel=1e-3)


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_charging_corner_is_D_over_2pi_lambda_h(device):
    """Phase of the impedance crosses −45° at f_c ≈ D/(2π λ h)."""
    d = load_device(device).with_params(sigma_polymer=0.0)
    p = d.params
    fc = p["D_cation"] / (2 * np.pi * debye(p) * p["t_polymer"] / 2)
    f = fc * np.logspace(-0.5, 0.5, 2001)
    ph = np.degrees(np.angle(frequency_response(d, "none", f).impedance))
    assert f[np.argmin(np.abs(ph + 45.0))] == pytest.approx(fc, rel=0.02)


@pytest.mark.parametrize("eps_r", [41.4, 4e3, 4e5])
def test_interface_excess_is_the_linearised_boltzmann_factor(eps_r):
    """ΔC⁺(h)/U → C⁻/(2 V_T) at low frequency, whatever the permittivity."""
    p = dict(load_device("ipmc_pt_eg").params, eps_r=eps_r)
    d = DoubleLayer.props(p)
    c = DoubleLayer.charge_per_volt(np.array([1e-6j]), d)[1][0]
    V_T = GAS_CONSTANT * p["T_ext"] / FARADAY
    assert c.real == pytest.approx(p["C_anion"] / (2 * V_T), rel=1e-6)


@pytest.mark.parametrize("eps_r,D", [(41.4, 1.4e-9), (4e5, 4.9e-11), (4e7, 4.9e-11)])
def test_time_domain_branch_realises_the_exact_response(eps_r, D):
    """Both branch realisations (single pole when K ≫ band, real-pole fit otherwise)."""
    p = dict(load_device("ipmc_pt_eg").params, eps_r=eps_r, D_cation=D)
    d = DoubleLayer.props(p)
    w_hi = np.pi * 1000
    ss = DoubleLayer.realize(d, w_hi)
    s = 1j * np.logspace(-2, np.log10(w_hi), 60)
    q, c = DoubleLayer.charge_per_volt(s, d)
    H = ss.freqresp(s)[:, 0, :]
    np.testing.assert_allclose(H[0], s * q + d.G_leak, rtol=1e-3)
    np.testing.assert_allclose(H[1], c, rtol=1e-3)
    np.testing.assert_allclose(H[2], q, rtol=1e-3)
