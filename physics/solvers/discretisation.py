"""Discretisation along the strip: quadrature for the closed-form (frequency) solver and
segment grids for the time solver, plus the projections of a segment-wise actuation
couple onto the beam modes.

The actuation is a distributed couple mu(z) = 2 h w kf Cs(z) [N m/m]: the interface
tractions kf·Cs (eq. 9–10) on the two Nafion/electrode interfaces at ±h, acting along
the strip, with Cs the interface solvent excess.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .beam import CantileverModes


@lru_cache(maxsize=32)
def quadrature(L: float, panels: int = 8, order: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Composite Gauss–Legendre nodes and weights on [0, L], panels halving towards the
    clamp (where the voltage of a resistive electrode decays fastest)."""
    edges = np.concatenate([[0.0], L * 0.5 ** np.arange(panels - 1, -1, -1)])
    x, w = np.polynomial.legendre.leggauss(order)
    a, b = edges[:-1, None], edges[1:, None]
    z = (0.5 * (b - a) * x[None, :] + 0.5 * (a + b)).ravel()
    wt = (0.5 * (b - a) * w[None, :]).ravel()
    return z, wt


@lru_cache(maxsize=32)
def line_functionals(L: float, n_modes: int) -> np.ndarray:
    """The three linear functionals the frequency solver takes of a per-volt voltage U(z) along
    the strip, as quadrature weights on the nodes of :func:`quadrature`: column 0 gives ∫U dz
    [m], columns 1..n_modes the modal loads ∫U phi_i' dz (per unit couple) and the last
    column ∫U(a) a (L − a/2) da [m³] (the static tip numerator). Shape (n_q, n_modes + 2);
    read-only, shared between calls."""
    z, w = quadrature(L)
    out = np.column_stack([w, (CantileverModes(L, n_modes).dphi(z) * w).T, w * z * (L - 0.5 * z)])
    out.flags.writeable = False
    return out


def segment_edges(L: float, n: int, grading: float = 1.0) -> np.ndarray:
    """Segment edges on [0, L]; ``grading`` > 1 refines towards the clamp (z = 0)."""
    return L * np.linspace(0.0, 1.0, n + 1) ** grading


@dataclass
class Projection:
    """Linear maps from segment-wise interface excess to the mechanical load channels.

    For a couple mu_k = coef * excess_k on segment k: modal loads Q_i = modal @ excess,
    and the residual (quasi-static higher modes) numerator R = residual @ excess, such
    that the tip deflection of the static part not carried by the retained modes is
    R / EI."""

    modal: np.ndarray      # (n_modes, n_seg) [N per unit excess]
    residual: np.ndarray   # (n_seg,)         [N m² per unit excess]


def projection(modes: CantileverModes, edges, coef: float) -> Projection:
    psi = modes.couple_modal_loads(edges)
    stat = modes.couple_static_tip(edges)
    trunc = (modes.tip / (modes.beta ** 4 * modes.L)) @ psi
    return Projection(coef * psi, coef * (stat - trunc))
