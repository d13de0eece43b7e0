"""Describing function of the large-signal double layer (``nonlinear_charge``) for FRF fits.

A swept sine of amplitude A through the nonlinear charge law is, at each instantaneous
frequency f, close to a tone of amplitude A: its H1 estimate is approximately the
*describing function* of the chain (Gelb & Vander Velde, *Multiple-input describing
functions and nonlinear system design*, McGraw-Hill 1968, ch. 2)

    H_A(f) ≈ N(A, f) · H_ss(f),

H_ss the model's small-signal response (closed form, :func:`physics.frequency.response_per_volt`)
and N(A, f) = X_A(f)/A ÷ X_ε(f)/ε the ratio of the fundamental phasors of the response to
tones of amplitude A and ε = 1 mV, from short time simulations.

Only the electrochemistry is nonlinear, and everything after it (solvent factor, kf(s),
beam) is linear, so N is computed on the interface solvent excess averaged over the strip
(``cs_up`` of :func:`physics.timedomain.simulate`) of a reduced model holding only the
effects that shape the charge (``nonlinear_charge``, ``electrode_resistance``): it
settles within a few periods (double layer ~µs, electrode line ~ms) and does not depend
on kf, βf or the modulus.  (With the electrode line the tip weights the strip's distal
part more than a plain average does; the difference is second order and the final score
of the fitted model uses the full time simulation.)  N is tabulated on a grid of
ν = C⁻/C_max (the steric parameter) and, when the electrode line makes it frequency
dependent, on a few frequencies, and interpolated linearly in ν and log f.

Cost: (grid points) × (amplitude levels + 1) × (frequencies) tone simulations of
≈ 100 samples each — about 1–3 s once per diagnosis.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..model import ActuatorModel
from ..timedomain import simulate

NU_GRID = (0.0, 0.02, 0.06, 0.12, 0.2, 0.3, 0.42, 0.55, 0.68, 0.8, 0.9, 0.96)
EPS_V = 1e-3
SAMPLES_PER_PERIOD = 32


class DescribingFunction:
    """N(A, f; C_max) for a device (see the module doc).  ``amplitudes`` [V]; ``band`` (Hz)."""

    def __init__(self, device, effects: Sequence[str], amplitudes: Sequence[float], band: tuple[float, float],
                 rh: float | None = None, nu_grid: Sequence[float] | None = None, n_freqs: int = 5):
        keep = [e for e in effects if e in ("nonlinear_charge", "electrode_resistance")]
        if "nonlinear_charge" not in keep:
            keep.append("nonlinear_charge")
        self.effects = tuple(keep)
        self.device = device
        self.rh = rh
        self.amplitudes = sorted({float(a) for a in amplitudes})
        lo, hi = band
        if "electrode_resistance" in keep:
            self.freqs = np.geomspace(lo, hi, max(1, int(n_freqs)))
        else:
            self.freqs = np.array([math.sqrt(lo * hi)])
        c_anion = float(device.params["C_anion"])
        self.c_anion = c_anion
        self.nu = np.array(sorted(NU_GRID if nu_grid is None else nu_grid), dtype=float)
        self.table = np.empty((self.nu.size, len(self.amplitudes), self.freqs.size), dtype=complex)
        self.n_sims = 0
        for i, nu in enumerate(self.nu):
            cmax = np.inf if nu == 0 else c_anion / nu
            dev = device.with_params(C_max=cmax)
            model = ActuatorModel(dev, self.effects)
            for k, f in enumerate(self.freqs):
                ref = self._phasor(model, f, EPS_V) / EPS_V
                for j, a in enumerate(self.amplitudes):
                    self.table[i, j, k] = self._phasor(model, f, a) / a / ref
        self._logtab = np.log(self.table)

    def _phasor(self, model, f: float, amp: float) -> complex:
        fs = SAMPLES_PER_PERIOD * f
        settle = max(2, int(math.ceil(0.1 * f)))
        n = (settle + 1) * SAMPLES_PER_PERIOD
        t = np.arange(n) / fs
        v = amp * np.sin(2 * np.pi * f * t)
        y = simulate(model, None, t, v, rh=self.rh, hold="cubic").cs_up
        self.n_sims += 1
        k = settle * SAMPLES_PER_PERIOD
        return complex(2.0 * np.mean(y[k:] * np.exp(-2j * np.pi * f * t[k:])))

    def __call__(self, amplitude: float, freq: np.ndarray, c_max: float) -> np.ndarray:
        """N at ``amplitude`` [V] (nearest tabulated level), frequencies [Hz], C_max [mol/m³]."""
        j = int(np.argmin([abs(math.log(a / amplitude)) for a in self.amplitudes]))
        if self.nu.size == 1:
            row = self._logtab[0, j]
        else:
            nu = 0.0 if not math.isfinite(c_max) else min(max(self.c_anion / c_max, self.nu[0]), self.nu[-1])
            i = int(np.clip(np.searchsorted(self.nu, nu) - 1, 0, self.nu.size - 2))
            w = (nu - self.nu[i]) / (self.nu[i + 1] - self.nu[i])
            row = (1 - w) * self._logtab[i, j] + w * self._logtab[i + 1, j]
        f = np.asarray(freq, dtype=float)
        if self.freqs.size == 1:
            return np.full(f.shape, np.exp(row[0]), dtype=complex)
        lf = np.log(np.clip(f, self.freqs[0], self.freqs[-1]))
        lfg = np.log(self.freqs)
        return np.exp(np.interp(lf, lfg, row.real) + 1j * np.interp(lf, lfg, row.imag))

    @property
    def c_max_sensitivity(self) -> float:
        """Largest relative change of |N| across the ν grid (any amplitude, frequency): how
        much C_max shapes the large-signal response beyond a gain (0 with one grid point)."""
        if self.nu.size < 2:
            return 0.0
        g = np.abs(self.table)
        return float(np.max(g.max(axis=0) / g.min(axis=0) - 1.0))

    def gain_table(self) -> dict:
        """JSON-ready table of |N| (mid frequency) by ν and amplitude."""
        k = self.freqs.size // 2
        return {"nu": self.nu.tolist(), "C_max_mol_m3": [None if n == 0 else self.c_anion / n for n in self.nu],
                "amplitudes_V": self.amplitudes, "freq_Hz": float(self.freqs[k]),
                "gain": np.abs(self.table[:, :, k]).T.tolist(), "simulations": self.n_sims}
