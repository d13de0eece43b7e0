"""Interference lines: a narrow line in every record's residual that the voltage does not drive.

A deflection sensor or its cable picks up the mains (50 or 60 Hz) or a nearby instrument's clock:
a steady sinusoid added to the measured deflection, the same frequency in every record, whatever
the drive.  No effect of the actuator makes it (a nonlinearity puts its harmonics where the drive
has power, or where a sweep passes, not at one fixed frequency in every record), and a verdict that
calls it "a mismatch of the model's own base forms" sends the user after the wrong thing.

:func:`find_line` looks in each record's residual (the final model's, at the analysis rate) for
its strongest narrow line above :data:`MIN_HZ`: the periodogram's (Hann window) power within
±:data:`HALF_WIDTH` bins of the peak, less the residual's local median level, must hold at least
:data:`MIN_SHARE` of the residual's power and stand :data:`MIN_PROMINENCE` × above that median.
The drive must not make it: the model's prediction holds less than :data:`MAX_DRIVEN` of the
line's power in the same bins (a square drive's far harmonics, filtered by the strip, hold far
less), and the line is no low harmonic (:data:`HARMONICS`) of a periodic drive's strongest line (a
nonlinearity's).  A line is reported only when *every* record (at least two) holds one at the
same frequency (within the coarser record's bin width, and 1 %) and the records' drives differ
(two kinds of excitation, or two strongest lines): a disturbance of the setup, not a distortion
product that identical drives would put at one frequency in each.  Its RMS (amplitude/√2 of the
sinusoid) is estimated from the line's share of the residual's power.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..analysis.frf_estimation import power_spectrum

#: Lines below this [Hz] are left to the drift and wander terms.
MIN_HZ = 1.0
#: Half-width [bins] of a line's window (a Hann window spreads a sinusoid over ±2 bins).
HALF_WIDTH = 3
#: The line's share of the residual's power for it to count.
MIN_SHARE = 0.1
#: The line's peak over the residual's local median level (a narrow line, not a band).
MIN_PROMINENCE = 100.0
#: The prediction's power within the line's bins relative to the line's, at most.
MAX_DRIVEN = 0.01
#: Harmonics of a periodic drive's strongest line that a line may not sit on (a nonlinearity's).
HARMONICS = range(2, 11)


@dataclass
class Line:
    """A line in every record's residual at ``freq_hz`` [Hz] that the voltage does not drive."""

    freq_hz: float
    rms_m: list              # its RMS [m] in each record
    share: list              # its share of each record's residual power

    @property
    def rms(self) -> float:
        """Its RMS over the records [m] (root mean square of the per-record values)."""
        return float(np.sqrt(np.mean(np.square(self.rms_m))))

    def text(self, rmse: float, floor: float, ratio: float) -> str:
        """What remains, said of the line: the model's RMS error ``rmse`` [m] without it against
        the noise floor ``floor`` [m] and the adequacy ``ratio``."""
        lo, hi = 100 * min(self.share), 100 * max(self.share)
        share = f"{lo:.0f} %" if round(lo) == round(hi) else f"{lo:.0f}–{hi:.0f} %"
        rest = math.sqrt(max(rmse ** 2 - self.rms ** 2, 0.0))
        within = "within" if rest <= ratio * floor else "still above"
        return (f"a narrow line at {self.freq_hz:.4g} Hz in every record's residual ({1e6 * self.rms:.3g} µm RMS, "
                f"{share} of its power) that the drive does not make: a disturbance added to the measured deflection "
                "(interference on the sensor or its cable, e.g. mains pickup), not the actuator's physics, and no "
                f"effect can model it; without it the model leaves {1e6 * rest:.3g} µm = {rest / floor:.2f}× the noise "
                f"floor, {within} {ratio}× — remove it at the source, or notch it out of the records, and diagnose again")


def _periodogram(x: np.ndarray) -> np.ndarray:
    """|X_k|² of ``x`` less its mean through a Hann window (a line spreads over ±2 bins, not the
    whole spectrum)."""
    return power_spectrum((x - x.mean()) * np.hanning(x.size))


def _line_of(e: np.ndarray, y: np.ndarray, v: np.ndarray, fs: float) -> "tuple[float, float, float, float] | None":
    """(frequency [Hz], RMS [m], share of the residual's power, the drive's strongest line [Hz]) of
    the strongest narrow undriven line of one record's residual ``e`` (the model's prediction ``y``,
    the voltage ``v``, all at ``fs`` [Hz]), or None."""
    n = e.size
    if n < 64 or y.size != n or v.size != n:
        return None
    pe, py, pv = _periodogram(e), _periodogram(y), _periodogram(v)
    df = fs / n
    k_lo = max(int(math.ceil(MIN_HZ / df)), HALF_WIDTH + 1)
    if pe.size - HALF_WIDTH - 1 <= k_lo:
        return None
    k = k_lo + int(np.argmax(pe[k_lo:pe.size - HALF_WIDTH - 1]))
    win = slice(k - HALF_WIDTH, k + HALF_WIDTH + 1)
    near = pe[max(1, k - 50):k + 51]
    floor = float(np.median(near))
    line = float(pe[win].sum() - floor * (2 * HALF_WIDTH + 1))
    total = float(pe[1:].sum())
    if total <= 0 or line <= 0 or pe[k] < MIN_PROMINENCE * floor or line < MIN_SHARE * total:
        return None
    if py[win].sum() > MAX_DRIVEN * line:
        return None
    kv = 1 + int(np.argmax(pv[1:]))            # the drive's strongest line: its low harmonics are a nonlinearity's
    if any(abs(k - h * kv) <= HALF_WIDTH for h in HARMONICS):
        return None
    # Parseval on the windowed series: RMS² of the residual ≈ its power share × its variance
    rms = math.sqrt(line / total * float(np.var(e)))
    return k * df, rms, line / total, kv * df


def find_line(records: Sequence, resid_d: Sequence[np.ndarray], pred_d: Sequence[np.ndarray]) -> Line | None:
    """The interference line every record's residual holds (module doc), or None.  ``records``:
    :class:`.records.PreparedRecord` (``v_d``, ``fs_d``); ``resid_d``, ``pred_d``: the model's
    residual and prediction of each [m]."""
    if len(records) < 2 or not len(resid_d) == len(pred_d) == len(records):
        return None
    found = []
    for r, e, y in zip(records, resid_d, pred_d):
        got = _line_of(*(np.asarray(a, float) for a in (e, y, r.v_d)), float(r.fs_d))
        if got is None:
            return None
        found.append((got, r.fs_d / len(e)))
    f0 = found[0][0][0]
    width = max(max(df for _, df in found), 0.01 * f0)
    if any(abs(g[0] - f0) > width for g, _ in found):
        return None
    drives = {round(g[3] / width) for g, _ in found}
    if len({r.kind for r in records}) < 2 and len(drives) < 2:
        return None
    return Line(float(np.mean([g[0] for g, _ in found])), [g[1] for g, _ in found], [g[2] for g, _ in found])
