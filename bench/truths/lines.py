"""Distributed lines solved by finite volumes in the frequency domain, vectorised over
frequency (a Thomas sweep per frequency column):

* :func:`electrode_ladder` — the voltage across the polymer along a strip whose electrodes have
  a sheet resistance: series links 2 R_s dz / w (top and bottom face), shunt admittance of
  each segment, drive at the clamp end, open at the tip;
* :func:`solvent_moment` — solvent released in a cathode layer of thickness δ and diffusing
  back through the thickness (no flux at the faces): the first moment of the solvent excess
  relative to its value without diffusion.  Its δ → 0 limit is the classical
  1 − tanh(g)/g, g = h sqrt(s/D_s) (Crank, *The Mathematics of Diffusion*, §4.3).
"""
from __future__ import annotations

import numpy as np


def thomas(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Solve tridiagonal systems a_i x_{i−1} + b_i x_i + c_i x_{i+1} = d_i; arrays (n, m): one
    system per column."""
    n = b.shape[0]
    cp = np.empty_like(b)
    dp = np.empty_like(b)
    cp[0] = c[0] / b[0]
    dp[0] = d[0] / b[0]
    for i in range(1, n):
        den = b[i] - a[i] * cp[i - 1]
        cp[i] = c[i] / den
        dp[i] = (d[i] - a[i] * dp[i - 1]) / den
    x = np.empty_like(b)
    x[-1] = dp[-1]
    for i in range(n - 2, -1, -1):
        x[i] = dp[i] - cp[i] * x[i + 1]
    return x


def electrode_ladder(shunt: np.ndarray, r_link: np.ndarray) -> np.ndarray:
    """Voltage per volt of drive at each segment (n_seg × n_freq).  ``shunt`` [S]: admittance of
    each segment (n_seg × n_freq); ``r_link`` [Ω]: series resistance from the drive to segment 0
    and between consecutive segments (n_seg)."""
    g = 1.0 / np.asarray(r_link, dtype=float)
    n, m = shunt.shape
    g_right = np.append(g[1:], 0.0)
    a = np.zeros((n, m), dtype=complex)
    c = np.zeros((n, m), dtype=complex)
    a[1:] = -g[1:, None]
    c[:-1] = -g[1:, None]
    b = shunt + (g + g_right)[:, None]
    d = np.zeros((n, m), dtype=complex)
    d[0] = g[0]
    return thomas(a, b, c, d)


def solvent_moment(freq: np.ndarray, h: float, D_s: float, delta: float, n_cells: int = 120) -> np.ndarray:
    """First moment of the solvent excess over [0, h] relative to its no-diffusion value
    (module doc), at frequencies ``freq`` [Hz]."""
    s = 2j * np.pi * np.asarray(freq, dtype=float)
    x = np.linspace(0.0, h, n_cells + 1)[1:]           # unknown nodes 1..N (S = 0 at mid-plane)
    dx = h / n_cells
    vol = np.full(n_cells, dx)
    vol[-1] = 0.5 * dx
    src = np.where(x >= h - delta, 1.0, 0.0) * vol
    src /= src.sum()
    k = D_s / dx
    m = s.size
    a = np.full((n_cells, m), -k, dtype=complex)
    c = np.full((n_cells, m), -k, dtype=complex)
    a[0] = 0.0
    c[-1] = 0.0
    diag = np.full(n_cells, 2 * k)
    diag[-1] = k                                       # no flux at the face
    b = diag[:, None] + vol[:, None] * s[None, :]
    d = src[:, None] * s[None, :]
    S = thomas(a, b, c, d)
    return ((x * vol) @ S) / float(x @ src)
