"""Real-pole (relaxation) realisations of frequency-dependent pieces for the time solver.

The double layer, solvent back-diffusion B(s), fractional couplings 1/(s^a (s+p)^b)
and DMA moduli are all relaxation-type functions: analytic off the negative real
axis, well approximated by  H(s) ≈ d + Σ_k r_k / (s + p_k)  with real poles p_k > 0
spread log-uniformly over the band (the discrete form of a Stieltjes integral).
Residues and the direct term are found by linear least squares on the relative error;
the realisation is accepted only if its worst relative error on the band is below the
tolerance, otherwise the pole density is raised.  A diagonal state space follows.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import nnls

from ..errors import ModelError
from .lti import StateSpace

#: The pole grid's second try extends this many times farther beyond the band (first: ``margin``).
WIDE_MARGIN = 100.0


@dataclass
class PoleResidue:
    """H(s) = d + Σ_k r[:, k] / (s + p[k]) for each output row (p in rad/s)."""

    poles: np.ndarray      # (n,) > 0
    residues: np.ndarray   # (n_out, n)
    direct: np.ndarray     # (n_out,)
    max_rel_error: float = 0.0

    def __call__(self, s) -> np.ndarray:
        s = np.atleast_1d(s)
        return self.direct[:, None] + self.residues @ (1.0 / (s[None, :] + self.poles[:, None]))

    def statespace(self) -> StateSpace:
        """Diagonal realisation with one input and len(direct) outputs."""
        n = self.poles.size
        return StateSpace(-np.diag(self.poles), np.ones((n, 1)), self.residues, self.direct[:, None])


def fit_pole_residue(func: Callable[[np.ndarray], np.ndarray], band: tuple[float, float], *,
                     extra_poles=(), per_decade: float = 3.0, tol: float = 1e-3,
                     margin: float = 10.0, nonneg: bool = False, fix_dc: bool = True,
                     what: str = "transfer function") -> PoleResidue:
    """Fit ``func`` (s -> array (n_out, len(s)) or (len(s),)) on ``band`` = (w_lo, w_hi) rad/s.

    Poles are log-spaced over [w_lo/margin, w_hi*margin] plus ``extra_poles`` (known
    physical rates); when no pole density meets ``tol`` there, the grid is widened to
    :data:`WIDE_MARGIN` × ``margin`` and the densities tried again (a relaxation whose corner lies
    far outside the band, e.g. a solvent back-diffusion time h²/Ds of weeks, still shapes the
    band through its slow tail).  ``nonneg`` constrains residues and direct term to be >= 0 (a
    passive Stieltjes function).  ``fix_dc`` weights the s = 0 value heavily so static
    gains are exact.  Raises :class:`ModelError` if ``tol`` cannot be met.
    """
    w_lo, w_hi = band
    if not (0 < w_lo < w_hi):
        raise ValueError("band must satisfy 0 < w_lo < w_hi")
    w_chk = np.logspace(np.log10(w_lo), np.log10(w_hi), 400)
    Hc = np.atleast_2d(func(1j * w_chk))
    H0 = np.atleast_2d(func(np.array([0.0]))).real if fix_dc else None
    extra = np.asarray([p for p in extra_poles if p > 0], dtype=float)
    best = None
    for m in (margin, WIDE_MARGIN * margin):
        lo, hi = np.log10(w_lo / m), np.log10(w_hi * m)
        w_fit = np.logspace(lo, hi, 40 * int(np.log10(w_hi / w_lo) + 4))
        Hf = np.atleast_2d(func(1j * w_fit))
        for density in (per_decade, 1.5 * per_decade, 2.5 * per_decade, 4 * per_decade):
            poles = np.logspace(lo, hi, max(2, int(np.ceil((hi - lo) * density)) + 1))
            if extra.size:
                # drop grid poles too close to a physical pole (keeps the basis well conditioned)
                close = np.min(np.abs(np.log10(poles[:, None]) - np.log10(extra[None, :])), axis=1) < 0.5 / density
                poles = np.sort(np.concatenate([poles[~close], extra]))
            fit = _solve(poles, w_fit, Hf, H0, nonneg)
            err = _rel_error(fit, w_chk, Hc)
            fit.max_rel_error = err
            if best is None or err < best.max_rel_error:
                best = fit
            if err <= tol:
                return fit
    raise ModelError(f"could not realise the {what} to a relative error of {tol:g} on "
                     f"{w_lo / 2 / np.pi:.3g}–{w_hi / 2 / np.pi:.3g} Hz (best {best.max_rel_error:.2e})")


def _solve(poles, w, H, H0, nonneg) -> PoleResidue:
    s = 1j * w
    basis = np.hstack([1.0 / (s[:, None] + poles[None, :]), np.ones((w.size, 1))])  # (n_w, n_p+1)
    n_out = H.shape[0]
    R = np.empty((n_out, poles.size))
    d = np.empty(n_out)
    for i in range(n_out):
        scale = 1.0 / np.maximum(np.abs(H[i]), 1e-300)
        A = basis * scale[:, None]
        b = H[i] * scale
        Ar, br = np.vstack([A.real, A.imag]), np.concatenate([b.real, b.imag])
        if H0 is not None:
            wdc = 30.0 / max(abs(H0[i, 0]), 1e-3 * float(np.median(np.abs(H[i]))))
            Ar = np.vstack([Ar, wdc * np.concatenate([1.0 / poles, [1.0]])[None, :]])
            br = np.append(br, wdc * H0[i, 0])
        col = np.linalg.norm(Ar, axis=0)
        col[col == 0] = 1.0
        if nonneg:
            x, _ = nnls(Ar / col, br, maxiter=50 * Ar.shape[1])
        else:
            x = np.linalg.lstsq(Ar / col, br, rcond=1e-13)[0]
        x = x / col
        R[i], d[i] = x[:-1], x[-1]
    return PoleResidue(poles, R, d)


def _rel_error(fit: PoleResidue, w, H) -> float:
    Hfit = fit(1j * w)
    return float(np.max(np.abs(Hfit - H) / np.maximum(np.abs(H), 1e-300)))
