"""Euler–Bernoulli clamped-free beam: mode shapes, modal quantities and exact statics.

Coordinates: ``z`` from the clamp (z = 0) to the free tip (z = L).  Mode shapes
phi_i(z) = cosh(b z) − cos(b z) − s_i (sinh(b z) − sin(b z)), b = beta_i, with
cos(beta_i L) cosh(beta_i L) = −1 (beta_i L = 1.8751, 4.6941, 7.8548, 10.9955, …)
and normalisation ∫_0^L phi_i² dz = L, so phi_i(L) = ±2 (e.g. Meirovitch,
*Fundamentals of Vibrations*, §8.7).  The hyperbolic terms are evaluated in a form
that does not cancel catastrophically for the higher modes.

Two kinds of actuation load are supported, both per unit of a given amplitude:
- a distributed couple mu(z) [N m/m] (interface tractions on the faces, eq. 9–10):
  generalised force Q_i = ∫ mu phi_i' dz, static tip deflection ∫ mu(a) a (L − a/2) da / EI;
- an active (eigen) bending moment M_a(z) [N m] (e.g. piezo-like swelling):
  Q_i = ∫ M_a phi_i'' dz, static tip deflection ∫ M_a(a) (L − a) da / EI.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.optimize import brentq


@lru_cache(maxsize=None)
def clamped_free_roots(n_modes: int) -> np.ndarray:
    """First ``n_modes`` roots beta_i L of cos(x) cosh(x) = −1 (dimensionless)."""
    f = lambda x: np.cos(x) * np.cosh(x) + 1.0  # noqa: E731
    return np.array([brentq(f, (n - 0.5) * np.pi - 0.6, (n - 0.5) * np.pi + 0.6, xtol=1e-15)
                     for n in range(1, n_modes + 1)])


class CantileverModes:
    """Mode shapes of a uniform clamped-free beam of free length ``L`` [m]."""

    def __init__(self, L: float, n_modes: int = 4):
        if L <= 0:
            raise ValueError("beam length must be positive")
        self.L = float(L)
        self.n_modes = int(n_modes)
        x = clamped_free_roots(self.n_modes)
        self.beta_L = x
        self.beta = x / self.L
        # 1 - sigma and 1 + sigma computed without cancellation.
        self._one_minus_sigma = (-np.exp(-x) + np.sin(x) - np.cos(x)) / (np.sinh(x) + np.sin(x))
        self._sigma = 1.0 - self._one_minus_sigma

    def _parts(self, z):
        z = np.atleast_1d(np.asarray(z, dtype=float))
        bz = self.beta[:, None] * z[None, :]
        a = 0.5 * self._one_minus_sigma[:, None] * np.exp(bz)
        b = 0.5 * (1.0 + self._sigma[:, None]) * np.exp(-bz)
        return bz, a, b, self._sigma[:, None]

    def phi(self, z) -> np.ndarray:
        """Mode shapes at ``z`` [m], shape (n_modes, len(z)), dimensionless."""
        bz, a, b, s = self._parts(z)
        return a + b - np.cos(bz) + s * np.sin(bz)

    def dphi(self, z) -> np.ndarray:
        """Slopes phi_i'(z) [1/m]."""
        bz, a, b, s = self._parts(z)
        return self.beta[:, None] * (a - b + np.sin(bz) + s * np.cos(bz))

    def ddphi(self, z) -> np.ndarray:
        """Curvatures phi_i''(z) [1/m²]."""
        bz, a, b, s = self._parts(z)
        return self.beta[:, None] ** 2 * (a + b + np.cos(bz) - s * np.sin(bz))

    @property
    def tip(self) -> np.ndarray:
        """phi_i(L) (= 2, −2, 2, …)."""
        return self.phi([self.L])[:, 0]

    def modal_stiffness(self, EI: float) -> np.ndarray:
        """k_i = EI ∫ phi_i''² dz = EI beta_i⁴ L [N/m]."""
        return EI * self.beta ** 4 * self.L

    def natural_frequencies(self, EI: float, rhoA: float) -> np.ndarray:
        """f_i = (beta_i L)² sqrt(EI/rhoA) / (2 pi L²) [Hz]."""
        return self.beta_L ** 2 * np.sqrt(EI / rhoA) / (2.0 * np.pi * self.L ** 2)

    # --- loads on segments [z0, z1] with a uniform amplitude on each -----------------
    def couple_modal_loads(self, edges) -> np.ndarray:
        """Q_i per unit uniform couple on each segment: ∫_seg phi_i' dz, shape (n_modes, n_seg) [1]."""
        p = self.phi(edges)
        return p[:, 1:] - p[:, :-1]

    def couple_static_tip(self, edges) -> np.ndarray:
        """Static tip deflection × EI per unit uniform couple on each segment:
        ∫_seg a (L − a/2) da [m³]."""
        e = np.asarray(edges, dtype=float)
        F = self.L * e ** 2 / 2.0 - e ** 3 / 6.0
        return F[1:] - F[:-1]

    def moment_modal_loads(self, edges) -> np.ndarray:
        """Q_i per unit uniform active moment on each segment: ∫_seg phi_i'' dz [1/m]."""
        d = self.dphi(edges)
        return d[:, 1:] - d[:, :-1]

    def moment_static_tip(self, edges) -> np.ndarray:
        """Static tip deflection × EI per unit uniform active moment on each segment:
        ∫_seg (L − a) da [m²]."""
        e = np.asarray(edges, dtype=float)
        F = self.L * e - e ** 2 / 2.0
        return F[1:] - F[:-1]
