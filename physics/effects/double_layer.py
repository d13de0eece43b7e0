"""``double_layer``: linearised Poisson–Nernst–Planck charge dynamics through the thickness.

Thesis eq. 1–6 with fixed anions C⁻, one mobile cation (charge z, diffusivity D),
blocking electrodes at x = ±h (h = t/2) and a voltage U across the polymer.  Linearised
about electroneutrality the charge density obeys ∂ρ/∂t = D ∂²ρ/∂x² − K ρ with
K = D/λ², Debye length λ = sqrt(κe R T / (z² F² C⁻)), κe = ε0 εr.  With
β(s) = sqrt((s + K)/D) the closed-form results used here are (docs/reference/physics.md):

- electrode charge per area and volt  Q/U = κe β (s + K) / (2 (s β h + K tanh βh)),
  low-frequency limit κe/(2λ) (two double layers in series);
- interface cation excess per volt  ΔC⁺(h)/U = K κe β² tanh βh / (2 z F (s β h + K tanh βh)),
  whose low-frequency limit is C⁻/(2 V_T), V_T = RT/(zF) (the linearised Boltzmann factor);
- polymer admittance per area  Y_p = s Q/U + σ/(2h), σ the electronic leakage of eq. 1.

Below the charging corner ≈ D/(2π λ h) the double layer is a capacitor κe/(2λ) in series
with the bulk ionic resistance ≈ 2h/σ_ion, σ_ion = κe K.  The mobility follows eq. 6,
µ = D/(RT), so temperature enters through λ and σ_ion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import EPS0, FARADAY, GAS_CONSTANT
from ..solvers.lti import StateSpace
from ..solvers.realize import fit_pole_residue
from .base import Effect


@dataclass(frozen=True)
class DoubleLayerProps:
    """Derived double-layer quantities (SI units)."""

    kappa: float        # effective permittivity κe [F/m]
    lam: float          # Debye length λ [m]
    K: float            # K = D/λ² [1/s]
    D: float            # cation diffusivity [m²/s]
    h: float            # half thickness [m]
    z: float            # charge number
    C0: float           # low-frequency capacitance per area [F/m²]
    tau: float          # charging time constant (single-pole fit at low frequency) [s]
    c0: float           # low-frequency interface cation excess per volt [mol/(m³ V)]
    G_leak: float       # electronic leakage conductance per area σ/(2h) [S/m²]
    sigma_ion: float    # ionic conductivity [S/m]
    V_T: float          # thermal voltage RT/(zF) [V]
    C_anion: float      # [mol/m³]

    @property
    def R_bulk(self) -> float:
        """Series resistance per area of the equivalent R–C branch [Ω m²]."""
        return self.tau / self.C0

    @property
    def corner_hz(self) -> float:
        return 1.0 / (2.0 * np.pi * self.tau)


def _charge(s, kappa, K, D, h):
    beta = np.sqrt((s + K) / D)
    th = np.tanh(beta * h)
    den = 2.0 * (s * beta * h + K * th)
    return kappa * beta * (s + K) / den, K * kappa * beta ** 2 * th / den


class DoubleLayer(Effect):
    id = "double_layer"
    stage = "double_layer"
    reference = "reproduced"
    summary = "linearised PNP charge dynamics through the thickness (always on)"
    explanation = __doc__
    requires = ("eps_r", "sigma_polymer", "D_cation", "C_anion", "z_cation", "T_ext", "t_polymer")

    @staticmethod
    def props(p, T=None) -> DoubleLayerProps:
        """Derived quantities for parameters ``p`` (dict, SI) at temperature ``T`` [K]
        (default: ``T_ext``).  ``D_cation`` is taken at ``T_ext``; an Arrhenius activation
        energy ``E_a`` (thermal effect, default 0 = eq. 6 only) scales it with T."""
        T = p["T_ext"] if T is None else T
        z, C = p["z_cation"], p["C_anion"]
        h = 0.5 * p["t_polymer"]
        kappa = EPS0 * p["eps_r"]
        Ea = p.get("E_a", 0.0)
        D = p["D_cation"] * np.exp(-Ea / GAS_CONSTANT * (1.0 / T - 1.0 / p["T_ext"]))
        lam = np.sqrt(kappa * GAS_CONSTANT * T / (z ** 2 * FARADAY ** 2 * C))
        K = D / lam ** 2
        q0, c0 = _charge(0.0, kappa, K, D, h)
        q0 = q0 - kappa / (2.0 * h)
        eps = 1e-4 / (lam * h / D + 1e-300)  # complex-step derivative well inside the corner
        q = _charge(1j * eps, kappa, K, D, h)[0] - kappa / (2.0 * h)
        tau = -np.imag(np.log(q)) / eps
        return DoubleLayerProps(kappa=kappa, lam=lam, K=K, D=D, h=h, z=z, C0=np.real(q0), tau=tau,
                                c0=np.real(c0) / (z * FARADAY), G_leak=p["sigma_polymer"] / (2.0 * h),
                                sigma_ion=kappa * K, V_T=GAS_CONSTANT * T / (z * FARADAY), C_anion=C)

    @staticmethod
    def charge_per_volt(s, d: DoubleLayerProps):
        """(Q/U [C/(m² V)], ΔC⁺(h)/U [mol/(m³ V)]) at complex frequencies ``s`` [rad/s].

        Q is the ionic part of the electrode charge: the geometric (dielectric)
        capacitance κe/(2h), a fraction λ/h of the double-layer capacitance, is left out
        in both solvers."""
        q, c = _charge(np.asarray(s, dtype=complex), d.kappa, d.K, d.D, d.h)
        return q - d.kappa / (2.0 * d.h), c / (d.z * FARADAY)

    @classmethod
    def admittance(cls, s, d: DoubleLayerProps):
        """Polymer admittance per area Y_p(s) = s Q/U + σ/(2h) [S/m²]."""
        return s * cls.charge_per_volt(s, d)[0] + d.G_leak

    @classmethod
    def realize(cls, d: DoubleLayerProps, w_hi: float, law=None) -> StateSpace:
        """Time-domain branch: input U [V]; outputs current density j [A/m²], interface
        excess ΔC⁺(h) [mol/m³] and electrode charge Q [C/m²].  When K ≫ the band the exact
        response is, to O(s/K), the single pole Q = C0 U/(1 + s tau); otherwise the exact
        functions are fitted with real poles over the band (1/tau and K included).  ``law``:
        the charge law's (functions, lowest frequency [rad/s]) when they are not the double
        layer's own (:meth:`~physics.effects.nonlinear_charge.LinearCharge.realized_charge`)."""
        charge, w_lo = ((lambda s: cls.charge_per_volt(s, d)), np.inf) if law is None else law
        if law is None and d.K > 1e3 * w_hi:
            a = 1.0 / d.tau
            return StateSpace([[-a]], [[d.C0 * a]], [[-a], [d.c0 / d.C0], [1.0]],
                              [[d.C0 * a + d.G_leak], [0.0], [0.0]])

        def funcs(s):
            q, c = charge(s)
            return np.vstack([s * q, c, q])

        band = (min(0.1 / d.tau, 1e-3 * w_hi, w_lo), w_hi)
        # a law whose current still rises at the band's top (a constant-phase charge, s^(1−a)) gets
        # three poles beyond the fit's grid (which ends 10× above the band), not a denser grid
        top = () if law is None else tuple(10.0 * w_hi * np.array([3.0, 10.0, 30.0]))
        fit = fit_pole_residue(funcs, band, extra_poles=(1.0 / d.tau, d.K) + top, per_decade=3.0, tol=1e-3,
                               what="double-layer response")
        D = fit.direct[:, None].copy()
        D[0, 0] += d.G_leak
        return StateSpace(-np.diag(fit.poles), np.ones((fit.poles.size, 1)), fit.residues, D)
