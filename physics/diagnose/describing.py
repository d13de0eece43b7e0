"""Describing function of the large-signal double layer (``nonlinear_charge``) for FRF fits.

A swept sine of amplitude A through the nonlinear charge law is, at each instantaneous
frequency f, close to a tone of amplitude A: its H1 estimate is approximately the
*describing function* of the chain (Gelb & Vander Velde, *Multiple-input describing
functions and nonlinear system design*, McGraw-Hill 1968, ch. 2)

    H_A(f) ≈ N(A, f) · H_ss(f),

H_ss the model's small-signal response (closed form, :func:`physics.solvers.frequency.response_per_volt`)
and N(A, f) = X_A(f)/A ÷ X_ε(f)/ε the ratio of the fundamental phasors of the response to
tones of amplitude A and ε = 1 mV, from short time simulations.

Only the electrochemistry is nonlinear, and everything after it (solvent factor, kf(s),
beam) is linear, so N is computed on the interface solvent excess averaged over the strip
(``cs_up`` of :func:`physics.solvers.timedomain.simulate`) of a reduced model holding only the
effects that shape the charge (those filling the electrochemical stages, e.g.
``nonlinear_charge``, ``electrode_resistance``): it
settles within a few periods (double layer ~µs, electrode line ~ms) and does not depend
on kf, βf or the modulus.  (With the electrode line the tip weights the strip's distal
part more than a plain average does; the difference is second order and the final score
of the fitted model uses the full time simulation.)  N is tabulated on a grid of
the large-signal effect's own coordinate (its ``describing_grid`` hook: for
``nonlinear_charge`` 1/diffuse_share, how much of the voltage its compact layers hold) and,
when an effect replacing the line stage makes it frequency dependent, on a few frequencies,
and interpolated linearly in the coordinate and log f.

Cost: (grid points) × (amplitude levels + 1) × (frequencies) tone simulations of
≈ 100 samples each — about 1–3 s once per diagnosis.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..effects import EFFECTS, stage_of
from ..errors import ModelError
from ..model import ActuatorModel
from ..solvers.timedomain import simulate
from .specs import spec_of

EPS_V = 1e-3
SAMPLES_PER_PERIOD = 32
#: Stages between the core and the load that shape the interface excess (the electrochemistry).
CHARGE_STAGES = ("charge_law", "line")


def charge_effects(effects) -> tuple[str, ...]:
    """The effects of ``effects`` that shape the interface excess: the model's core (a stage
    default with an id), those filling one of :data:`CHARGE_STAGES`, and the large-signal
    effects (spec ``describing_function``)."""
    out = []
    for e in effects:
        cls = EFFECTS[e]
        stage = stage_of(cls)
        if stage is cls or (stage is not None and stage.stage in CHARGE_STAGES) \
                or spec_of(e).get("describing_function"):
            out.append(e)
    return tuple(out)


def _replaces(cls, slot: str) -> bool:
    """True when the effect class replaces the stage ``slot`` (not the stage's own default)."""
    stage = stage_of(cls)
    return stage is not None and stage is not cls and stage.stage == slot


class DescribingFunction:
    """N(A, f; θ) for a device (see the module doc): ``amplitudes`` [V]; ``band`` (Hz); θ the
    large-signal parameter that the effect's ``describing_grid`` hook names, tabulated on the
    hook's coordinate c = scale/θ (``coordinates``: override the hook's grid)."""

    def __init__(self, device, effects: Sequence[str], amplitudes: Sequence[float], band: tuple[float, float],
                 rh: float | None = None, coordinates: Sequence[float] | None = None, n_freqs: int = 5):
        self.effects = charge_effects(effects)
        large = [e for e in self.effects if spec_of(e).get("describing_function")]
        if not large:
            raise ModelError("a describing function needs a large-signal effect (spec 'describing_function')")
        self.param, grid, self.scale = EFFECTS[large[0]].describing_grid(device)
        self.device = device
        self.rh = rh
        self.amplitudes = sorted({float(a) for a in amplitudes})
        lo, hi = band
        distributed = any(_replaces(EFFECTS[e], "line") for e in self.effects)   # N then depends on f
        self.freqs = np.geomspace(lo, hi, max(1, int(n_freqs))) if distributed else np.array([math.sqrt(lo * hi)])
        self.nu = np.array(sorted(grid if coordinates is None else coordinates), dtype=float)
        self.table = np.empty((self.nu.size, len(self.amplitudes), self.freqs.size), dtype=complex)
        self.n_sims = 0
        for i, nu in enumerate(self.nu):
            dev = device.with_params(**{self.param: self.value(nu)})
            model = ActuatorModel(dev, self.effects)
            for k, f in enumerate(self.freqs):
                ref = self._phasor(model, f, EPS_V) / EPS_V
                for j, a in enumerate(self.amplitudes):
                    self.table[i, j, k] = self._phasor(model, f, a) / a / ref
        self._logtab = np.log(self.table)

    def value(self, coordinate: float) -> float:
        """The large-signal parameter at a grid coordinate (∞ at 0)."""
        return np.inf if coordinate == 0 else self.scale / coordinate

    def coordinate(self, value: float) -> float:
        return 0.0 if not math.isfinite(value) else self.scale / value

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

    def __call__(self, amplitude: float, freq: np.ndarray, value: float) -> np.ndarray:
        """N at ``amplitude`` [V] (nearest tabulated level), frequencies [Hz], large-signal
        parameter ``value`` (SI)."""
        j = int(np.argmin([abs(math.log(a / amplitude)) for a in self.amplitudes]))
        if self.nu.size == 1:
            row = self._logtab[0, j]
        else:
            nu = min(max(self.coordinate(value), self.nu[0]), self.nu[-1])
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
    def sensitivity(self) -> float:
        """Largest relative change of |N| across the grid (any amplitude, frequency): how much
        the large-signal parameter shapes the response beyond a gain (0 with one grid point)."""
        if self.nu.size < 2:
            return 0.0
        g = np.abs(self.table)
        return float(np.max(g.max(axis=0) / g.min(axis=0) - 1.0))

    def gain_table(self) -> dict:
        """JSON-ready table of |N| (mid frequency) by ν and amplitude."""
        k = self.freqs.size // 2
        return {"coordinate": self.nu.tolist(), "parameter": self.param,
                "values": [None if n == 0 else self.value(n) for n in self.nu],
                "amplitudes_V": self.amplitudes, "freq_Hz": float(self.freqs[k]),
                "gain": np.abs(self.table[:, :, k]).T.tolist(), "simulations": self.n_sims}
