"""Through-thickness ionic charging: the linearised Poisson–Nernst–Planck equations solved by
finite volumes, in the frequency domain (our own discretisation; no closed form is used).

One mobile cation of diffusivity D and bulk concentration C0 (= the fixed anions), permittivity
κe, across a membrane of thickness 2h with blocking electrodes at x = ±h held at ±V/2.  With
c = C⁺ − C0 (small):

    s c = −∂f/∂x,  f = −D (∂c/∂x + (F C0 / RT) ∂φ/∂x),  κe ∂²φ/∂x² = −F c,  f(±h) = 0.

The solution is odd in x, so only [0, h] is discretised (c = φ = 0 at x = 0), on a mesh graded
geometrically towards the electrode (first cell λ/20, λ the Debye length, growth 1.1) — the
layer is sub-nanometre with the bulk permittivity.  :func:`charge_per_volt` returns the charge
moved into the cathode half per area and per volt, q(s)/V [C/m²/V].

Analytic limits it must reproduce (Bazant, Thornton & Ajdari, Phys. Rev. E 70, 021506, 2004):
two Debye–Hückel layers in series, q/V → κe/(2λ) at low frequency, charged through the bulk
resistance 2h/σ with σ = F² C0 D/(RT), i.e. the RC time τ = λh/D.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

FARADAY, R_GAS = 96485.33212, 8.314462618
EPS0 = 8.8541878128e-12


def debye_length(eps_r: float, c0: float, T: float = 298.15) -> float:
    """λ = sqrt(κe R T / (F² C0)) [m]."""
    return math.sqrt(EPS0 * eps_r * R_GAS * T / (FARADAY ** 2 * c0))


def graded_mesh(h: float, lam: float, *, growth: float = 1.1, bulk_cells: int = 40) -> np.ndarray:
    """Nodes on [0, h]: cells growing by ``growth`` from λ/20 at x = h up to h/``bulk_cells``,
    uniform beyond."""
    d_bulk = h / bulk_cells
    cells, d = [], lam / 20.0
    while d < d_bulk and sum(cells) < 0.5 * h:
        cells.append(d)
        d *= growth
    rest = h - sum(cells)
    n_u = max(2, int(math.ceil(rest / d_bulk)))
    cells += [rest / n_u] * n_u
    return np.concatenate([[0.0], np.cumsum(cells[::-1])])     # fine cells at x = h


def charge_per_volt(freq: np.ndarray, *, h: float, eps_r: float, D: float, c0: float, T: float = 298.15
                    ) -> np.ndarray:
    """q(j2πf)/V [C/m²/V]: cation charge moved into the cathode half per area and per volt of
    drive across the membrane (module doc)."""
    x = graded_mesh(h, debye_length(eps_r, c0, T))
    n = x.size - 1                     # nodes 1..n unknown (node 0: c = φ = 0)
    dx = np.diff(x)                    # dx[i] between nodes i and i+1
    vol = np.empty(n + 1)
    vol[1:n] = 0.5 * (dx[:-1] + dx[1:])
    vol[n] = 0.5 * dx[-1]
    vol[0] = 0.5 * dx[0]
    kappa = EPS0 * eps_r
    a = FARADAY * c0 / (R_GAS * T)
    # unknowns: c_1..c_n (index 0..n-1), φ_1..φ_{n-1} (index n..2n-2); φ_n = V/2 = 1/2 per volt
    nc, nphi = n, n - 1
    rows, cols, vals = [], [], []
    rhs = np.zeros(nc + nphi)

    def ic(i):                          # column of c_i (i >= 1)
        return i - 1

    def iphi(i):                        # column of φ_i (1 <= i <= n-1)
        return nc + i - 1

    # Nernst–Planck at node i: s c_i vol_i + f_{i+1/2} − f_{i−1/2} = 0, f_{k+1/2} = −D[(c_{k+1}−c_k) + a(φ_{k+1}−φ_k)]/dx_k
    for i in range(1, n + 1):
        r = ic(i)
        for k, sgn in ((i, +1.0), (i - 1, -1.0)):         # flux at k+1/2 enters with sign sgn
            if k == n:                                   # blocking electrode: no flux
                continue
            g = sgn * (-D / dx[k])
            # g * [(c_{k+1} - c_k) + a (φ_{k+1} - φ_k)]
            for node, coef in ((k + 1, g), (k, -g)):
                if node >= 1:
                    rows.append(r); cols.append(ic(node)); vals.append(coef)
                if 1 <= node <= n - 1:
                    rows.append(r); cols.append(iphi(node)); vals.append(a * coef)
                elif node == n:
                    rhs[r] -= a * coef * 0.5
    # Poisson at nodes 1..n-1: κ[(φ_{i+1}−φ_i)/dx_i − (φ_i−φ_{i−1})/dx_{i−1}] + F c_i vol_i = 0
    for i in range(1, n):
        r = nc + i - 1
        for node, coef in ((i + 1, kappa / dx[i]), (i, -kappa / dx[i] - kappa / dx[i - 1]), (i - 1, kappa / dx[i - 1])):
            if 1 <= node <= n - 1:
                rows.append(r); cols.append(iphi(node)); vals.append(coef)
            elif node == n:
                rhs[r] -= coef * 0.5
        rows.append(r); cols.append(ic(i)); vals.append(FARADAY * vol[i])
    K = sp.csc_matrix((vals, (rows, cols)), shape=(nc + nphi, nc + nphi), dtype=complex)
    Mdiag = np.zeros(nc + nphi)
    Mdiag[:nc] = vol[1:]
    M = sp.diags(Mdiag).tocsc()
    out = np.empty(np.size(freq), dtype=complex)
    for j, f in enumerate(np.atleast_1d(freq)):
        sol = spla.spsolve(2j * np.pi * f * M + K, rhs)
        out[j] = -FARADAY * (vol[1:] @ sol[:nc])
    return out
