"""Physics outside the catalog, shared by the independent families (written here from their
textbook forms, never from the package's residual forms):

* :func:`creep_response` — a creeping output, tip × (1 + g/(1 + sτ)) (the polymer or its
  clamp yields slowly under a held bend);
* :func:`lowpass2_response` — a second-order sensor low-pass, 1/(1 + 2ζ s/ω_c + (s/ω_c)²)
  (a laser head's internal averaging, a filter the export forgot to mention);
* :func:`thermal_drift` — an additive drift of each record, different in every record (the
  sensor warming up: A(1 − e^(−t/τ)) plus a slow wander);
* :func:`play` — backlash of total width ``width`` between the strip and what the laser sees
  (a loose reflector);
* :func:`dead_zone` — a dead zone of the drive: no voltage reaches the polymer below ``d``
  (a contact that needs a threshold, an amplifier's crossover);
* :func:`bow` — a displacement sensor's bowed characteristic, y + b y²/S (a triangulation
  head's linearity error: even order, b of the stroke S at its ends);
* :func:`clip` — a sensor whose range the largest stroke leaves: what is logged stops at ±c.

Large-signal laws of the double layer's charge (the in-catalog ``nonlinear_charge`` analogues;
each returns the charge as the *equivalent small-signal voltage* Q(U)/C0 so that the linear
chain after it is unchanged):

* :func:`steric_sqrt` — a layer whose capacitance falls as 1/sqrt(U) at large voltage (the
  crowded, steric-limited layer: Kornyshev 2007; Kilic, Bazant & Ajdari 2007):
  Q/C0 = U_s (sqrt(1 + 2|U|/U_s) − 1) sign U;
* :func:`log_saturation` — a capacitance C0/(1 + |U|/U_s): Q/C0 = U_s ln(1 + |U|/U_s) sign U.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def creep_response(f: np.ndarray, g: float, tau: float) -> np.ndarray:
    s = 2j * np.pi * np.asarray(f, dtype=float)
    return 1.0 + g / (1.0 + s * tau)


def lowpass2_response(f: np.ndarray, fc: float, zeta: float) -> np.ndarray:
    x = 1j * np.asarray(f, dtype=float) / fc
    return 1.0 / (1.0 + 2.0 * zeta * x + x * x)


def thermal_drift(t: np.ndarray, rng, amplitude: float) -> np.ndarray:
    """A(1 − e^(−t/τ)) with A = ±U(0.5, 1)·``amplitude``, τ U(10, 40) s, plus a smooth wander
    of RMS 0.3·``amplitude`` (time scale ~8 s) [m]."""
    a = float(rng.uniform(0.5, 1.0)) * amplitude * float(rng.choice([-1.0, 1.0]))
    tau = float(rng.uniform(10.0, 40.0))
    fs = 1.0 / float(t[1] - t[0])
    c = math.exp(-1.0 / (8.0 * fs))
    w = lfilter([1 - c], [1, -c], lfilter([1 - c], [1, -c], rng.standard_normal(t.size)))
    w = w - w.mean()
    return a * (1.0 - np.exp(-t / tau)) + 0.3 * amplitude * w / max(float(np.std(w)), 1e-300)


def play(y: np.ndarray, width: float) -> np.ndarray:
    """Backlash: the output stays put until the input has moved ``width``/2 past it."""
    half = 0.5 * width
    out = np.empty_like(y)
    z = float(y[0])
    for i, x in enumerate(y):
        if x > z + half:
            z = x - half
        elif x < z - half:
            z = x + half
        out[i] = z
    return out


def dead_zone(v: np.ndarray, d: float) -> np.ndarray:
    return np.sign(v) * np.maximum(np.abs(v) - d, 0.0)


def bow(y: np.ndarray, b: float, stroke: float) -> np.ndarray:
    return y + b * y * y / stroke


def clip(y: np.ndarray, level: float) -> np.ndarray:
    return np.clip(y, -level, level)


def steric_sqrt(u: np.ndarray, u_s: float) -> np.ndarray:
    return np.sign(u) * u_s * (np.sqrt(1.0 + 2.0 * np.abs(u) / u_s) - 1.0)


def log_saturation(u: np.ndarray, u_s: float) -> np.ndarray:
    return np.sign(u) * u_s * np.log1p(np.abs(u) / u_s)
