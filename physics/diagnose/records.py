"""Measurement records as the diagnosis uses them.

Each time-series record is

* **classified** by its excitation — ``broadband`` (swept sine, multisine, noise: an H1
  frequency response over a band), ``tone`` (one sine: a stepped-sine point), ``steps``
  (square pulses, steps: time only) — from the metadata written by ``eap simulate`` /
  :mod:`physics.signals` when present, otherwise from the voltage itself
  (:func:`physics.analysis.frf_estimation.detect_excitation`);
* given an **amplitude level** [V] (robust peak of |v − median v|; records whose
  amplitudes differ by less than a factor :data:`AMPLITUDE_RATIO` share a level) and an
  **RH level** [%] (:func:`physics.compare.cluster_rh`);
* **decimated** for the time-domain work to ``fs_d`` ≥ :data:`OVERSAMPLING` × the highest
  frequency that matters: the excited band and the response standing above the noise
  (a step excites the resonance whatever its "band"; scipy's polyphase FIR with zero
  phase, applied to the voltage and the deflection alike, so a linear model driven by the
  decimated voltage is compared with the equally filtered measurement); in a step record
  each jump is placed within its sample interval by the response after it
  (:func:`physics.diagnose.candidates.place_edges`);
* given its **noise floor** [m], from the measurement alone, never from a model's misfit:
  the RMS of what a perfect model would leave — the sensor's white noise and quantisation and
  the part of its drift that the nuisance terms do not absorb — from the record's sensor
  metadata (written by :class:`physics.io.sensor.SensorModel`) or, failing that, estimated from
  the deflection spectrum where the response has fallen away, or from its quietest segments or
  the difference of a periodic record's successive periods where that reads clearly lower
  (:func:`deflection_spectrum`: the white part only, and the source says so);
* given its **nuisance terms** (:meth:`PreparedRecord.nuisance`): the least-squares offset and linear
  drift of a residual, bounded by what a sensor's zero does — the drift's rise over the record
  by :data:`STATED_DRIFT_FACTOR` × the drift the sensor states, or :data:`DRIFT_SHARE` of the
  signal's peak-to-peak; the offset, when the record has a rest before the drive, within
  :data:`OFFSET_SHARE` of the peak-to-peak of the level at rest — so that a slow
  back-relaxation or a wrong static gain stays in the error, where it is evidence;
* when it is **periodic** (a multisine of two or more periods) and recorded once settled,
  entered in its steady state: the model is driven through the record's own periods first
  (:func:`periodic_lead`); one whose drive starts inside the record is entered at rest.

Frequency-response targets for the fits come from the broadband records through
:func:`physics.identify.build_targets` (H1, thinned to log-spaced lines) and from tone
records through :func:`physics.analysis.frf_estimation.stepped_sine`.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import signal as sps

from ..compare import (FRFOptions, cluster_rh, load_measurements, model_rh, sensor_bandwidth_of,
                       sensor_response, source_name)
from ..errors import InputError, arg
from ..analysis.frf_estimation import (detect_excitation, leading_transient, noise_level, periodic_noise_level,
                                       quiet_noise_level, stepped_sine)
from ..io.frfdata import FRFData
from ..analysis.metrics import NUISANCE_TERMS, nuisance_terms, remove_nuisance
from ..io.timeseries import TimeSeries

#: fs_d / highest frequency that matters after decimation: the solver's cubic hold then errs by
#: < 0.1 % near a resonance (a thesis strip driven to 20 Hz: 1.5 % at 5×, 0.04 % at 12×), below a
#: laser's noise on a millimetre stroke.
OVERSAMPLING = 12.0
#: Amplitudes within this ratio form one amplitude level.
AMPLITUDE_RATIO = 1.25
#: Minimum span [%] between two RH levels for them to count as different humidities.
RH_SPAN = 10.0

_BROADBAND = ("sweep", "multisine", "noise")
_STEPS = ("square", "steps")


@dataclass
class PreparedRecord:
    """A view of one measured record for the diagnosis: the record itself
    (:class:`~physics.io.record.TimeSeries`, ``ts``, the one record type) with what the
    diagnosis derives from it — excitation kind, band, decimated drive and response, noise
    floor, nuisance bounds (SI units)."""

    source: str
    ts: TimeSeries                 # as read (full rate)
    kind: str                      # broadband | tone | steps | other
    amplitude: float               # V, robust peak of |v − median|
    rh: float                      # nominal RH of the record's humidity level [%] (a label)
    rh_model: object               # RH given to the time solver (constant or series at fs_d)
    band: tuple[float, float]      # excited band [Hz]
    tone_hz: float | None
    q: int                         # decimation factor
    v_sim: np.ndarray              # decimated voltage with the pre-roll [V] (what the model is driven with)
    y_d: np.ndarray                # decimated deflection [m]
    sensor_bandwidth: float | None
    noise_floor: float             # m, full rate
    noise_source: str
    i0: int = 0                    # pre-roll samples at fs_d before the record starts
    amplitude_level: float = 0.0   # V (set by prepare_records)
    steps: np.ndarray = field(default_factory=lambda: np.zeros(0, int))   # step indices at fs_d
    kind_how: str = ""             # how the excitation kind was decided
    rh_measured: float = math.nan  # the record's own (median) RH [%], what a model is evaluated at
    signal_range: float = math.nan  # robust peak-to-peak of the measured deflection [m] (the nuisance bounds)
    drift_bound: float = math.inf   # largest drift over the record a sensor's zero may take [m] (:meth:`nuisance`)
    offset_bound: float = math.inf  # largest distance of the offset from the level at the start [m]
    start_window: int = 1           # samples (full rate) whose residual gives the level at the start

    @property
    def fs(self) -> float:
        return self.ts.fs

    @property
    def tone_amplitude(self) -> float:
        """Amplitude [V] of the sine with this drive's power, sqrt(2)·RMS(v − mean): a sweep's
        peak, about half a multisine's (crest factor ≈ 3).  A describing function computed for
        tones stands in for a multisine at this amplitude, not at its peak, whose rare
        excursions hardly load the nonlinearity (Gelb & Vander Velde 1968, ch. 3: the Gaussian
        input's gain is set by its RMS)."""
        return float(math.sqrt(2.0) * np.std(self.ts.voltage))

    @property
    def fs_d(self) -> float:
        return self.ts.fs / self.q

    @property
    def v_d(self) -> np.ndarray:
        """Decimated voltage over the record [V]."""
        return self.v_sim[self.i0:]

    @property
    def t_sim(self) -> np.ndarray:
        return np.arange(self.v_sim.size) / self.fs_d

    @property
    def hold(self) -> str:
        return "linear" if self.kind == "steps" else "cubic"

    @property
    def noise_floor_d(self) -> float:
        """Noise floor after decimation: white noise and quantisation scale with the kept
        bandwidth (1/q of the power), the slow drift does not."""
        meta = self.ts.meta.get("sensor") if isinstance(self.ts.meta.get("sensor"), dict) else None
        if meta and all(isinstance(meta.get(k), (int, float)) for k in ("deflection_noise", "deflection_step",
                                                                          "deflection_drift")):
            white = meta["deflection_noise"] ** 2 + meta["deflection_step"] ** 2 / 12.0
            return math.sqrt(white / self.q + WALK_AFTER_TREND * meta["deflection_drift"] ** 2)
        return self.noise_floor / math.sqrt(self.q)

    def nuisance(self, e: np.ndarray, t: np.ndarray | None = None) -> "Nuisance":
        """The record's nuisance terms in the residual ``e`` (full rate, ``t`` [s] default its
        time axis): the least-squares offset and linear drift — a laser's zero is arbitrary and
        drifts slowly; neither is physics — *within bounds that keep them from eating physics*
        (:func:`bounded_nuisance`)."""
        t = self.ts.time if t is None else t
        return bounded_nuisance(e, t, self.drift_bound, self.offset_bound, self.start_window)

    def detrend_d(self, e_d: np.ndarray) -> np.ndarray:
        """A decimated residual with the record's bounded nuisance terms removed (:meth:`nuisance`)."""
        t = self.t_d
        nz = bounded_nuisance(e_d, t, self.drift_bound, self.offset_bound, max(1, self.start_window // self.q))
        return nz.remove(e_d, t)

    @property
    def t_d(self) -> np.ndarray:
        """Time [s] of the decimated samples over the record."""
        return self.ts.time[0] + np.arange(self.y_d.size) / self.fs_d

    def describe(self) -> dict:
        return {"source": self.source, "kind": self.kind, "samples": self.ts.n, "fs_Hz": self.fs,
                "duration_s": self.ts.duration, "amplitude_V": self.amplitude,
                "amplitude_level_V": self.amplitude_level, "rh_pct": self.rh, "rh_measured_pct": self.rh_measured,
                "band_Hz": list(self.band), "tone_Hz": self.tone_hz, "decimation": self.q,
                "fs_analysis_Hz": self.fs_d, "sensor_bandwidth_Hz": self.sensor_bandwidth,
                "white_noise_m": self.noise_floor, "white_noise_source": self.noise_source,
                "excitation_from": self.kind_how,
                "steps": int(self.steps.size), "signal_range_m": self.signal_range,
                "nuisance_bounds": {"drift_over_record_m": self.drift_bound, "offset_from_start_m": self.offset_bound,
                                    "start_window_s": self.start_window / self.fs}}


def classify(ts: TimeSeries) -> tuple[str, tuple[float, float], float | None, str]:
    """(kind, excited band [Hz], tone frequency [Hz] or None, how it was decided) of a
    record's excitation: from its metadata when they say, otherwise from the voltage
    (:func:`physics.analysis.frf_estimation.detect_excitation`)."""
    sig = ts.meta.get("signal") if isinstance(ts.meta.get("signal"), dict) else {}
    kind = str(sig.get("kind", ""))
    if kind in _BROADBAND and "f_start_Hz" in sig and "f_stop_Hz" in sig:
        return "broadband", (float(sig["f_start_Hz"]), float(sig["f_stop_Hz"])), None, f"metadata: {kind}"
    if kind == "tone" and "frequency_Hz" in sig:
        f0 = float(sig["frequency_Hz"])
        return "tone", (f0, f0), f0, "metadata: tone"
    if kind in _STEPS:
        return "steps", _steps_band(ts), None, f"metadata: {kind}"
    try:
        ex = detect_excitation(ts.voltage, ts.fs)
    except InputError:
        raise InputError(f"{ts.source or 'record'}: the voltage is constant; nothing is excited") from None
    how = f"from the voltage: {ex.how}"
    if ex.kind == "steps":
        return "steps", _steps_band(ts), None, how
    if ex.kind == "tone":
        return "tone", ex.band, ex.tone_hz, how
    return ("broadband" if ex.kind in ("sweep", "periodic", "noise") else "other"), ex.band, None, how


def _steps_band(ts: TimeSeries) -> tuple[float, float]:
    return (1.0 / max(ts.duration, 1e-9), min(ts.fs / 2, 50.0))


def find_steps(v: np.ndarray, fs: float) -> np.ndarray:
    """Indices where the voltage jumps by more than 30 % of its range within 20 ms."""
    span = np.ptp(v)
    if span <= 0:
        return np.zeros(0, int)
    k = max(1, int(round(0.02 * fs)))
    jump = np.abs(v[k:] - v[:-k]) > 0.3 * span
    idx = np.flatnonzero(jump[1:] & ~jump[:-1]) + 1
    if jump.size and jump[0]:                  # a step right at the start of the record
        idx = np.concatenate([[0], idx])
    return idx


#: A periodic record needs at least this many periods for the model to be run into its steady state.
MIN_PERIODS = 2
#: The model is driven through the record's periods for up to this long [s] (at least one period)
#: before it starts: slow dynamics (creep, back-diffusion, τ of tens of seconds) settle too.
LEAD_S = 60.0


def record_period(ts: TimeSeries, how: str) -> float | None:
    """The period [s] of a record holding at least :data:`MIN_PERIODS` of them, or None: from
    the metadata (``period_s``, ``periods``) or, when ``how`` (:func:`classify`) says the kind was
    read from the voltage, the voltage's own (:func:`detect_excitation`)."""
    sig = ts.meta.get("signal") if isinstance(ts.meta.get("signal"), dict) else {}
    period = None
    if isinstance(sig.get("period_s"), (int, float)) and float(sig.get("periods", 1) or 1) >= MIN_PERIODS:
        period = float(sig["period_s"])
    elif how.startswith("from the voltage"):
        try:
            ex = detect_excitation(ts.voltage, ts.fs)
        except InputError:
            ex = None
        period = ex.period_s if ex is not None and ex.kind == "periodic" else None
        if period is not None and ts.duration < MIN_PERIODS * period * (1 - 1e-6):
            period = None
    return period if period and period > 0 else None


def periodic_lead(ts: TimeSeries, period: float | None, q: int) -> int:
    """Samples (full rate, a multiple of ``q``) of the periods that precede a periodic record
    of at least :data:`MIN_PERIODS` periods — a multisine recorded once its response has
    settled is entered in its steady state: the model is driven through the record's own
    periods (whole ones, up to :data:`LEAD_S`) before it starts; 0 for other records and for
    one whose first period is not yet periodic (a fade-in, the response settling from rest:
    :func:`~physics.analysis.frf_estimation.leading_transient`), which the model enters at rest
    as the strip did.  ``period`` [s] is :func:`record_period`'s."""
    if period is None:
        return 0
    if leading_transient(ts.voltage, ts.deflection, ts.fs, period):
        return 0                    # the drive starts inside the record: the model starts at rest, as the strip did
    p = int(round(period * ts.fs))
    p -= p % q
    if not 0 < p <= ts.n // MIN_PERIODS:
        return 0
    k = max(1, min(ts.n // p, int(LEAD_S * ts.fs) // p))     # whole periods, up to LEAD_S
    return k * p


def _decimation(fs: float, f_hi: float, fs_max: float | None) -> int:
    target = max(OVERSAMPLING * f_hi, 1e-9)
    if fs_max is not None:
        target = min(max(target, 2.5 * f_hi), fs_max)
    return max(1, int(math.floor(fs / target)))


#: Pre-roll and post-roll [samples at fs_d]: the record is extended by its first and last
#: values (the device at rest before the record, held after it) so that the zero-phase
#: anti-aliasing filter has no edge transient inside the record and the model starts at
#: rest at the record's true first voltage (a step at t = 0 stays a step).
PAD = 32


def _decimate(x: np.ndarray, q: int) -> np.ndarray:
    """[x[0]]*PAD·q + x + [x[-1]]*PAD·q, decimated by q; the pre-roll is the first PAD samples."""
    x = np.asarray(x, dtype=float)
    xp = np.concatenate([np.full(PAD * q, x[0]), x, np.full(PAD * q, x[-1])])
    if q == 1:
        return xp[:PAD + x.size]
    xd = sps.resample_poly(xp, 1, q, padtype="line")
    return xd[:PAD + int(math.ceil(x.size / q))]


#: Mean square of a unit random walk (value 1 at the end) left after removing its
#: least-squares offset and linear drift: 1/15 (the nuisance terms of :func:`remove_nuisance`).
WALK_AFTER_TREND = 1.0 / 15.0

#: Without a drift stated by the sensor, a record's nuisance drift may rise over the record by at
#: most this share of the largest robust peak-to-peak of the records (a laser's zero drifts by
#: micrometres over strokes of millimetres; an IPMC's back-relaxation is tens of percent of its
#: deflection) ...
DRIFT_SHARE = 0.01
#: ... and at least this × its white noise (a sensor's zero wanders by a few noise levels over a record).
DRIFT_NOISE = 5.0
#: A drift the sensor states (random walk of std d at the record's end) bounds the record's drift at
#: this × d.
STATED_DRIFT_FACTOR = 4.0
#: The offset may stand at most this share of the signal's robust peak-to-peak from the level the
#: residual has during the rest before the drive (the device at rest: no model's response there) ...
OFFSET_SHARE = 0.02
#: ... and, when the record's white noise is known, at most this × that noise: the rest measures
#: the sensor's zero to within its noise, so a larger departure is slow physics the model lacks.
OFFSET_NOISE = 3.0
#: A record whose voltage holds still for at least this long [s] (and 8 samples) before the drive has
#: a rest that anchors its offset; without one the offset is the least-squares one.
START_S = 0.1


@dataclass
class Nuisance:
    """A record's nuisance terms (:func:`bounded_nuisance`)."""

    offset: float            # at the record's start [m]
    drift: float             # [m/s]
    offset_ls: float         # the unbounded least-squares values
    drift_ls: float
    offset_clipped: bool
    drift_clipped: bool
    level: float = math.nan  # the residual's level over the start window [m] (the device at rest)
    offset_free: float = math.nan   # the least-squares offset given the (bounded) drift [m]

    def remove(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.asarray(e, dtype=float) - self.offset - self.drift * (np.asarray(t, dtype=float) - t[0])

    def __iter__(self):
        return iter((self.offset, self.drift))


def bounded_nuisance(e: np.ndarray, t: np.ndarray, drift_bound: float, offset_bound: float,
                     start: int) -> Nuisance:
    """Offset and drift of the residual ``e`` at times ``t`` [s]: the least-squares line, its
    rise over the record held within ±``drift_bound`` [m], then its offset (refitted with that
    drift) held within ±``offset_bound`` [m] of the level of the first ``start`` samples, where
    the device is at rest and no model's response can hide in the offset.  A least-squares
    offset and drift take whatever slow error a model leaves (a wrong static gain, a
    back-relaxation), and that error is evidence; the bounds keep them to what a sensor's zero
    does.  Clipped terms are reported (:func:`.verdict.nuisance_summary`)."""
    e = np.asarray(e, dtype=float)
    t = np.asarray(t, dtype=float)
    o_ls, b_ls = nuisance_terms(e, t)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    b = b_ls
    if span > 0 and math.isfinite(drift_bound) and abs(b_ls) * span > drift_bound:
        b = math.copysign(drift_bound / span, b_ls)
    o = o_free = float(np.mean(e - b * (t - t[0])))
    o_clip, level = False, math.nan
    if math.isfinite(offset_bound):
        k = max(1, min(int(start), e.size))
        level = float(np.mean(e[:k] - b * (t[:k] - t[0])))
        if abs(o - level) > offset_bound:
            o, o_clip = level + math.copysign(offset_bound, o - level), True
    return Nuisance(o, b, o_ls, b_ls, o_clip, b != b_ls, level, o_free)


def nuisance_bounds(ts: TimeSeries, scale: float | None = None, white: float = math.nan) -> tuple[float, float, float, int]:
    """(robust peak-to-peak of the deflection [m], drift bound [m], offset bound [m], start
    window [samples]) of a record: the drift's rise over the record within
    :data:`STATED_DRIFT_FACTOR` × the drift its sensor states, else within :data:`DRIFT_SHARE` ×
    ``scale`` (the largest robust peak-to-peak of the records taken with the same sensor,
    default this record's: a sensor's drift does not shrink with a smaller stroke) and at least
    :data:`DRIFT_NOISE` × its ``white`` noise [m]; the offset within :data:`OFFSET_SHARE` ×
    ``scale`` of the level at rest when the record has a rest before the drive (:data:`START_S`),
    else unbounded."""
    y = ts.deflection
    rng = float(np.percentile(y, 99.5) - np.percentile(y, 0.5))
    scale = rng if scale is None else max(float(scale), rng)
    sensor = ts.meta.get("sensor") if isinstance(ts.meta.get("sensor"), dict) else {}
    d = sensor.get("deflection_drift")
    if isinstance(d, (int, float)) and math.isfinite(d) and d >= 0:
        drift = max(STATED_DRIFT_FACTOR * float(d), 1e-12)
    else:
        drift = max(DRIFT_SHARE * scale, DRIFT_NOISE * white if math.isfinite(white) else 0.0)
    v = ts.voltage
    tol = 0.01 * float(np.ptp(v)) if np.ptp(v) > 0 else 0.0
    moved = np.flatnonzero(np.abs(v - v[0]) > tol)
    rest = int(moved[0]) if moved.size else v.size
    if rest < max(8, int(round(START_S * ts.fs))):
        return rng, drift, math.inf, 0          # no rest before the drive: nothing anchors the offset
    offset = OFFSET_SHARE * scale
    if math.isfinite(white) and white > 0:
        offset = min(offset, OFFSET_NOISE * white)
    return rng, drift, offset, min(rest, max(ts.n // 4, 1))


def sensor_noise_floor(ts: TimeSeries) -> tuple[float, str] | None:
    """The noise floor [m] the record's sensor metadata state, or None: white noise,
    quantisation and the part of a random-walk drift that a linear trend does not remove,
    sqrt(σ² + q²/12 + d²/15); a bare ``noise_floor_m`` as given."""
    sensor = ts.meta.get("sensor") if isinstance(ts.meta.get("sensor"), dict) else None
    if not sensor:
        return None
    if all(isinstance(sensor.get(k), (int, float)) for k in ("deflection_noise", "deflection_step",
                                                             "deflection_drift")):
        white = sensor["deflection_noise"] ** 2 + sensor["deflection_step"] ** 2 / 12.0
        return math.sqrt(white + WALK_AFTER_TREND * sensor["deflection_drift"] ** 2), "sensor metadata"
    if isinstance(sensor.get("noise_floor_m"), (int, float)) and sensor["noise_floor_m"] > 0:
        return float(sensor["noise_floor_m"]), "sensor metadata"
    return None


def stated_drift(ts: TimeSeries) -> float:
    """The slow wander [m RMS] the record's sensor metadata allow beyond the linear trend: a
    random-walk drift d leaves sqrt(d²/15) (:data:`WALK_AFTER_TREND`); 0 when no drift is stated."""
    sensor = ts.meta.get("sensor") if isinstance(ts.meta.get("sensor"), dict) else {}
    d = sensor.get("deflection_drift")
    return math.sqrt(WALK_AFTER_TREND) * abs(float(d)) if isinstance(d, (int, float)) and math.isfinite(d) else 0.0


def deflection_spectrum(ts: TimeSeries, period: float | None = None) -> tuple[float, float, str]:
    """(white noise level as an RMS over the full band [m], highest frequency where the
    response stands above it [Hz], how the level was found) from the deflection alone
    (:func:`physics.analysis.frf_estimation.noise_level`).  A sensor whose range the strip
    leaves, a play or a bowed characteristic spread harmonics over the whole spectrum, and its
    white level rises with them; two more readings are immune to part of that: the record's
    quietest segments (:func:`~physics.analysis.frf_estimation.quiet_noise_level`: a sweep's
    harmonics pass each band only for a while) and, for a record of whole periods (``period``
    [s], an integer number of samples), the difference of its successive periods
    (:func:`~physics.analysis.frf_estimation.periodic_noise_level`: a multisine's harmonics
    repeat every period).  The lower of the two replaces the spectrum's level when it is below
    :data:`CLEANER_SHARE` of it; on a record without such harmonics all three agree within a few
    per cent and the spectrum's level stays."""
    level, f_resp, (a, b) = noise_level(ts.deflection, ts.fs)
    if not math.isfinite(level):
        return math.nan, ts.fs / 2, "unknown (the record is too short or too slowly sampled to estimate it)"
    how = (f"estimated from the deflection spectrum (white level in {a:.3g}–{b:.3g} Hz, where the response has "
           "fallen away; drift and anything below that level not included)")
    lq, (qa, qb) = quiet_noise_level(ts.deflection, ts.fs)
    other = [(lq, f"white level in {qa:.3g}–{qb:.3g} Hz of its quietest quarter of 4 s segments, where a "
                  "sweep's harmonics are not")]
    p = period * ts.fs if period else 0.0
    if p >= 1 and abs(p - round(p)) < PERIOD_SAMPLES_TOL:
        lp, (pa, pb) = periodic_noise_level(ts.deflection, ts.fs, int(round(p)))
        other.append((lp, f"white level in {pa:.3g}–{pb:.3g} Hz of the difference of successive periods, where "
                          "everything periodic cancels"))
    lo, text = min(((v, t) for v, t in other if math.isfinite(v)), default=(math.inf, ""))
    if lo < CLEANER_SHARE ** 2 * level:
        level, how = lo, f"estimated from the deflection spectrum ({text}; drift and anything below that level not included)"
    return math.sqrt(level * ts.fs / 2), f_resp, how


#: A period is differenced only when it spans a whole number of samples within this many.
PERIOD_SAMPLES_TOL = 0.01
#: The noise floor [RMS] read from the quietest segments or the difference of successive periods
#: replaces the spectrum's when below this share of it.  On 176 periodic records of an independent
#: family (circuit_lab, seeds 21–73) without a static nonlinearity on the sensor the period
#: difference and the spectrum agreed within 0.94–1.03; a clipped sensor and a play gave 0.35–0.58.
CLEANER_SHARE = 0.8


def estimate_noise_floor(ts: TimeSeries, f_hi: float | None = None) -> tuple[float, str]:
    """(noise floor [m], how it was obtained): the sensor metadata
    (:func:`sensor_noise_floor`), else the deflection spectrum (:func:`deflection_spectrum`)."""
    known = sensor_noise_floor(ts)
    if known is not None:
        return known
    level, _, how = deflection_spectrum(ts)
    return level, how


def prepare_records(measurements: Sequence, *, rh: float | None = None, sensor_bandwidth="auto",
                    fs_max: float | None = None, noise_floor: float | None = None,
                    rh_tolerance: float = 1.0) -> list[PreparedRecord]:
    """Prepare loaded time series (see the module doc).  FRF files are refused: the
    diagnosis needs time records (residuals in time, steps, amplitudes)."""
    ms = load_measurements(measurements, rh=rh)
    out: list[PreparedRecord] = []
    rhs = []
    for k, m in enumerate(ms):
        where = source_name(m, k)
        if isinstance(m, FRFData):
            raise InputError(f"{where}: a frequency-response file; eap diagnose needs time-series records "
                             "(voltage_V, deflection_m, rh_pct) to analyse residuals in time")
        if m.deflection is None:
            raise InputError(f"{where}: no deflection; the diagnosis needs measured deflection_m")
        if m.rh is None and rh is None:
            raise InputError(f"{where}: no relative humidity; add an rh_pct column or give {arg('rh')}")
        rh_series = m.rh if m.rh is not None else np.full(m.n, float(rh))
        if m.n < 64:
            raise InputError(f"{where}: only {m.n} samples; a diagnosis needs a record of at least 64")
        kind, band, tone_hz, how = classify(m)
        period = record_period(m, how) if kind == "broadband" else None
        level, f_resp, spec_how = deflection_spectrum(m, period)
        # decimate to keep what the sensor saw: the excited band and the response above the noise
        q = _decimation(m.fs, max(band[1], min(f_resp, m.fs / 2)), fs_max)
        if fs_max is not None and m.n // q < 64:    # a cap below the record's own scale: refused before any array of it is made
            raise InputError(f"{arg('fs_max')} {fs_max:g} Hz leaves {m.n // q} samples of {where} at the analysis "
                             f"rate; a diagnosis needs at least 64 — give at least {64 * m.fs / m.n:.3g} Hz")
        lead = periodic_lead(m, period, q)
        v_sim = _decimate(np.concatenate([m.voltage[m.n - lead:], m.voltage]) if lead else m.voltage, q)
        y_d = _decimate(m.deflection, q)[PAD:]
        n_d = int(math.ceil(m.n / q))
        rm = model_rh(rh_series, m.fs, rh_tolerance)
        if np.ndim(rm):
            rm = np.concatenate([np.full(PAD + lead // q, rm[0]), np.asarray(rm)[::q][:n_d]])
        if noise_floor is not None:
            nf, src = float(noise_floor), "given"
        else:
            nf, src = sensor_noise_floor(m) or (level, spec_how)
        amp = float(np.percentile(np.abs(m.voltage - np.median(m.voltage)), 99.5))
        if amp <= 0:
            raise InputError(f"{where}: the voltage is constant; nothing is excited")
        rec = PreparedRecord(where, m, kind, amp, 0.0, rm, band, tone_hz, q, v_sim, y_d,
                     sensor_bandwidth_of(m, sensor_bandwidth), nf, src, i0=PAD + lead // q, kind_how=how)
        if lead:
            rec.kind_how += (f"; periodic: the model is driven through {lead / m.fs:.3g} s of its periods before it "
                             "starts (its steady state)")
        rec.steps = find_steps(rec.v_d, rec.fs_d) if kind == "steps" else np.zeros(0, int)
        rec.rh_measured = float(np.median(rh_series))
        out.append(rec)
        rhs.append(float(np.median(rh_series)))
    if not out:
        raise InputError("no measurement given")
    scale = max(float(np.percentile(r.ts.deflection, 99.5) - np.percentile(r.ts.deflection, 0.5)) for r in out)
    for r in out:
        r.signal_range, r.drift_bound, r.offset_bound, r.start_window = nuisance_bounds(r.ts, scale, r.noise_floor)
    for rec, lv in zip(out, cluster_rh(rhs, rh_tolerance)):
        rec.rh = lv
    for rec, lv in zip(out, amplitude_levels([r.amplitude for r in out])):
        rec.amplitude_level = lv
    return out


def amplitude_levels(amps: Sequence[float]) -> list[float]:
    """Group amplitudes [V] whose ratio to the previous (sorted) one is below
    :data:`AMPLITUDE_RATIO`; each level is its group's geometric mean."""
    a = np.asarray(amps, dtype=float)
    order = np.argsort(a)
    groups: list[list[int]] = []
    for i in order:
        if groups and a[i] / a[groups[-1][-1]] < AMPLITUDE_RATIO:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    lv = np.empty(a.size)
    for g in groups:
        lv[g] = float(np.exp(np.mean(np.log(a[g]))))
    return lv.tolist()


def frf_measurements(records: Sequence[PreparedRecord]) -> tuple[list, list[PreparedRecord]]:
    """Measurements for FRF targets (broadband TimeSeries, stepped-sine FRFData per tone
    record) and the records they come from, in the same order."""
    ms, src = [], []
    for r in records:
        if r.kind == "broadband":
            ms.append(r.ts)
            src.append(r)
        elif r.kind == "tone" and r.tone_hz is not None:
            settle = min(0.5 * r.ts.duration, max(3.0 / r.tone_hz, 1.0))
            est = stepped_sine([(r.ts.voltage, r.ts.deflection, r.fs, r.tone_hz)], settle=settle)
            if not est.excited[0]:
                continue
            meta = {"sensor": r.ts.meta.get("sensor")} if isinstance(r.ts.meta.get("sensor"), dict) else {}
            eps = float(est.rel_error[0])
            coh = 1.0 / (1.0 + 2.0 * eps ** 2)          # γ² with ε = sqrt((1−γ²)/(2γ²))
            ms.append(FRFData(est.freq, est.response, np.array([coh]), rh=r.rh_measured, meta=meta,
                              source=r.source))
            src.append(r)
    return ms, src


def sensor_filter(y: np.ndarray, fs: float, bandwidth: float | None) -> np.ndarray:
    """Apply the first-order sensor response 1/(1 + j f/f_c) in the frequency domain
    (:func:`response_filter`)."""
    if bandwidth is None:
        return y
    return response_filter(y, fs, lambda f: sensor_response(f, bandwidth))


def response_filter(y: np.ndarray, fs: float, response) -> np.ndarray:
    """``y`` sampled at ``fs`` [Hz] through the continuous-time response ``response(f)`` (f in
    Hz, H(0) = 1), applied in the frequency domain from rest at y[0] (:func:`spectral_filter`)."""
    return spectral_filter(y, fs)(response)


def spectral_filter(y: np.ndarray, fs: float):
    """``apply(response)``: ``y`` sampled at ``fs`` [Hz] through the continuous-time response
    ``response(f)`` (f in Hz, H(0) = 1), applied in the frequency domain from rest at y[0]
    (an FFT over twice the record: the response time ≪ the record, so there is no wrap-around);
    y's spectrum is taken once, for many responses.  Past its end the record is continued by its
    point reflection about the last sample (value and slope go on) faded to rest by a half cosine,
    then rest: a record ending away from y[0] or in motion has no jump or kink for a lead or a
    fractional delay to ring on, and a slow response has the rest of the pad to settle in."""
    y = np.asarray(y, dtype=float)
    y0, n = y[0], y.size
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    k = np.arange(1, min(n - 1, (nfft - n) // 2) + 1)
    tail = (2.0 * y[-1] - y[n - 1 - k] - y0) * 0.5 * (1.0 + np.cos(np.pi * k / (k.size + 1)))
    Y = np.fft.rfft(np.concatenate([y - y0, tail]), nfft)
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    return lambda response: np.fft.irfft(Y * response(f), nfft)[:n] + y0


def upsample(y_d: np.ndarray, q: int, n: int) -> np.ndarray:
    """A decimated, band-limited prediction back at the full rate (polyphase FIR)."""
    if q == 1:
        return y_d[:n]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y = sps.resample_poly(y_d, q, 1, padtype="line")
    if y.size < n:
        y = np.concatenate([y, np.full(n - y.size, y[-1])])
    return y[:n]


def rh_levels(records: Sequence[PreparedRecord]) -> list[float]:
    return sorted({r.rh for r in records})


def amplitude_groups(records: Sequence[PreparedRecord]) -> dict[float, list[float]]:
    """{RH level: sorted amplitude levels} over records that give frequency information."""
    out: dict[float, set] = {}
    for r in records:
        if r.kind in ("broadband", "tone", "steps"):
            out.setdefault(r.rh, set()).add(r.amplitude_level)
    return {k: sorted(v) for k, v in out.items()}


__all__ = ["PreparedRecord", "Nuisance", "bounded_nuisance", "nuisance_bounds", "prepare_records", "classify", "find_steps", "frf_measurements", "sensor_filter", "response_filter", "spectral_filter",
           "upsample", "estimate_noise_floor", "stated_drift", "remove_nuisance", "nuisance_terms", "NUISANCE_TERMS", "amplitude_levels", "rh_levels", "amplitude_groups",
           "FRFOptions"]
