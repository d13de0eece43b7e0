"""Fixed (not learned) input front-ends shared by the neural models.

* **Memory filters** (long input memory): a bank of first-order low-pass filters of the
  normalised voltage, with time constants spaced logarithmically between
  ``memory_min_s`` and ``memory_max_s`` (s).  A sum of such terms approximates the slow
  fractional / diffusive dynamics of the actuator (f^-0.6 coupling down to 0.01 Hz,
  solvent back-diffusion over tens of seconds), as in Oustaloup's approximation of
  fractional operators, which no tapped delay line of reasonable length can cover
  (40 s = 10 000 samples at 250 Hz).  They are the generalised, orthonormal-basis-like
  form of an NFIR model's delay line: the networks stay static maps of (filtered)
  past inputs.  Each filter is discretised exactly for a zero-order hold,
  x[k] = a x[k-1] + (1 - a) u[k] with a = exp(-1/(fs tau)), and starts in equilibrium
  with the first input sample (the record starts from steady state, the convention of
  the physics simulator and of ``eap generate``).  With ``memory_abs`` the same filters
  of the voltage's magnitude |V| are added: slow measures of the drive level, for
  behaviour that depends on how hard the actuator is driven (a saturating double layer).
* **RH hat channels**: a piecewise-linear ("hat") encoding of the relative humidity on
  knots ``rh_knots`` (%): channel k is 1 at knot k and falls linearly to 0 at the
  neighbouring knots; outside the knots the end channels stay at 1.  The lag models use
  them to *schedule* their linear bypass (a linear-parameter-varying ARX/FIR part whose
  coefficients interpolate linearly in RH between knots) and the MLP sees them as inputs.

Everything here is numpy, deterministic and computed from whole records, so training
windows cut from the middle of a record see exactly the filter states of the record.

:class:`InputFeatures` is the settings part every model composes (the hyper-parameters
``memory_filters``, ``memory_min_s``, ``memory_max_s``, ``memory_abs``, ``rh_knots``,
``inputs``, declared once here); fitting it to the training records gives a
:class:`FeatureMap` (``model.features_``): the time constants and RH knots actually used,
and the map from a record in physical units to the normalised channels of a core.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import signal

from physics.errors import InputError, InputNotice

from .params import MAX_FILTERS, Part, flag, pos_float, size

__all__ = ["memory_taus", "memory_filters", "rh_hats", "check_knots", "auto_knots", "InputFeatures",
           "FeatureMap", "MEMORY_MIN_SAMPLES", "MEMORY_MAX_FRACTION"]

#: The fastest memory filter spans at least this many sample periods ...
MEMORY_MIN_SAMPLES = 2.0
#: ... and the slowest at most this fraction of the (median) training record.
MEMORY_MAX_FRACTION = 0.5


def memory_taus(n: int, min_s: float, max_s: float) -> np.ndarray:
    """``n`` time constants (s) spaced logarithmically from ``min_s`` to ``max_s``."""
    if n <= 0:
        return np.zeros(0)
    if n == 1:
        return np.array([float(min_s)])
    return np.logspace(math.log10(min_s), math.log10(max_s), int(n))


def memory_filters(u: np.ndarray, taus: np.ndarray, fs: float, last: np.ndarray | None = None) -> np.ndarray:
    """Low-pass filter bank of ``u`` (one column per time constant ``taus`` in s) at the
    sampling rate ``fs`` (Hz); shape (len(u), len(taus)), each filter in equilibrium with
    ``u[0]`` before the first sample, or continuing from its output ``last[j]`` at the sample
    before (a record filtered in pieces gives the values of the whole)."""
    u = np.asarray(u, dtype=float)
    out = np.empty((u.size, len(taus)))
    for j, tau in enumerate(taus):
        a = math.exp(-1.0 / (fs * float(tau)))
        start = u[0] if last is None else last[j]
        out[:, j], _ = signal.lfilter([1.0 - a], [1.0, -a], u, zi=np.array([a * start]))
    return out


def check_knots(knots) -> str | None:
    """Validation message for ``rh_knots`` (None when valid): ``"auto"`` or a list of
    increasing RH values (%) in 0-100, empty or at least two of them."""
    if knots == "auto":
        return None
    if not isinstance(knots, (list, tuple)):
        return "a list of increasing relative humidities in % (e.g. [40, 60, 80, 100]) or []"
    try:
        k = [float(v) for v in knots]
    except (TypeError, ValueError):
        return "a list of numbers (relative humidity in %)"
    if len(k) == 1:
        return "at least two knots (or [] for an RH-independent bypass)"
    if any(not (0 <= v <= 100) for v in k) or any(b <= a for a, b in zip(k, k[1:])):
        return "strictly increasing relative humidities within 0-100 %"
    return None


def rh_hats(rh: np.ndarray, knots) -> np.ndarray:
    """Hat (piecewise-linear interpolation) weights of ``rh`` (%) on ``knots`` (%):
    shape (len(rh), len(knots)); every row sums to 1."""
    rh = np.asarray(rh, dtype=float)
    k = np.asarray(knots, dtype=float)
    r = np.clip(rh, k[0], k[-1])
    i = np.clip(np.searchsorted(k, r, side="right") - 1, 0, k.size - 2)
    w = (r - k[i]) / (k[i + 1] - k[i])
    out = np.zeros((rh.size, k.size))
    rows = np.arange(rh.size)
    out[rows, i] = 1.0 - w
    out[rows, i + 1] += w
    return out


def auto_knots(rh_series, tol: float = 2.5) -> list[float]:
    """Knots for ``rh_knots: auto`` from the training records' RH (one array per record,
    %): the distinct levels of the records whose RH stays within ``tol`` % (rounded to
    1 %; levels closer than ``tol`` merged), widened to the RH range of all records.
    Fewer than two levels: four knots spread over the range (none if the range is
    narrower than ``tol``)."""
    levels: list[float] = []
    lo, hi = np.inf, -np.inf
    for rh in rh_series:
        rh = np.asarray(rh, dtype=float)
        lo, hi = min(lo, float(rh.min())), max(hi, float(rh.max()))
        if np.ptp(rh) <= tol:
            lev = float(np.round(np.median(rh)))
            if all(abs(lev - v) > tol for v in levels):
                levels.append(lev)
    levels.sort()
    if len(levels) < 2:
        if not np.isfinite(lo) or hi - lo <= tol:
            return []
        return [float(v) for v in np.round(np.linspace(lo, hi, 4), 1)]
    if lo < levels[0] - tol:
        levels.insert(0, float(np.floor(lo)))
    if hi > levels[-1] + tol:
        levels.append(float(np.ceil(hi)))
    return levels



# ---------------------------------------------------------------------- the settings part
@dataclass
class InputFeatures(Part):
    """Which input features a model sees: ``memory_filters`` low-pass filters of the voltage
    with time constants ``memory_min_s``..``memory_max_s`` (s; adapted to the data, see
    :meth:`fit`), with ``memory_abs`` the same filters of |V|; ``rh_knots`` (%, ``"auto"``:
    the training RH levels, None/[]: none) schedule the linear paths on RH; ``inputs``:
    ``auto`` (voltage, + RH when the records carry it), ``voltage`` or ``voltage+rh``;
    ``linear_start``: the network starts from the best linear model of the training data
    (:func:`nnmodel.linear.fit_linear`): its free-run output is a reference channel and the
    network's output is that reference plus a correction that starts at zero."""

    ATTR = "features"
    CHECKS = {
        "memory_filters": size(MAX_FILTERS, zero=True),
        "memory_min_s": pos_float,
        "memory_max_s": pos_float,
        "memory_abs": flag,
        "rh_knots": lambda v: None if v is None else check_knots(v),
        "inputs": lambda v: None if v in ("auto", "voltage", "voltage+rh") else "'auto', 'voltage' or 'voltage+rh'",
        "linear_start": flag,
    }

    memory_filters: int = 0
    memory_min_s: float = 0.02
    memory_max_s: float = 100.0
    memory_abs: bool = False
    rh_knots: list | str | None = None
    inputs: str = "auto"
    linear_start: bool = False

    def uses_rh(self, kind: str, has_rh: bool) -> bool:
        """Whether a model fitted on records with (``has_rh``) or without RH takes RH."""
        if self.inputs == "voltage+rh" and not has_rh:
            raise InputError(f"model {kind!r} was asked for inputs voltage+rh but the training "
                             "records carry no relative humidity")
        return has_rh and self.inputs != "voltage"

    def fit(self, kind: str, fs: float, records, use_rh: bool, val=None, val_fraction: float = 0.2) -> "FeatureMap":
        """The features for these training records: the RH knots (``"auto"``: the records'
        levels, :func:`auto_knots`) and the memory time constants fitted to the data — none
        faster than :data:`MEMORY_MIN_SAMPLES` sample periods, none slower than
        :data:`MEMORY_MAX_FRACTION` of the median record; the recipe's range is kept where
        the data support it (a warning says when it is not); with ``linear_start`` the
        linear model fitted on ``records`` and validated on ``val`` (or the last
        ``val_fraction`` of each record)."""
        if self.rh_knots == "auto":
            knots = auto_knots([r.rh for r in records]) if use_rh else []
        else:
            knots = [float(k) for k in (self.rh_knots or [])]
        rng = None
        if self.memory_filters:
            want = (float(self.memory_min_s), float(self.memory_max_s))
            ceiling = MEMORY_MAX_FRACTION * float(np.median([len(r) for r in records])) / fs
            lo = max(want[0], MEMORY_MIN_SAMPLES / fs)
            hi = min(want[1], ceiling)
            if hi <= lo * 1.01:   # records too short for the range: one decade above the fastest
                hi = lo * 10.0
            if (lo, hi) != want:
                warnings.warn(f"model {kind!r}: memory filters {want[0]:g}–{want[1]:g} s do not fit these data "
                              f"(sample period {1 / fs:.3g} s, records of ~{ceiling / MEMORY_MAX_FRACTION:.3g} s); "
                              f"using {lo:.3g}–{hi:.3g} s", InputNotice, stacklevel=4)    # adapted as documented: a note
            rng = (lo, hi)
        linear = None
        if self.linear_start:
            from ..linear import fit_linear
            linear = fit_linear(records, val, val_fraction, use_rh=use_rh)
        return FeatureMap(float(fs), bool(use_rh), knots, rng, int(self.memory_filters), bool(self.memory_abs),
                          linear)

    def card(self, fm: "FeatureMap") -> dict:
        """Bundle-card entries of fitted features (what :meth:`restore` needs)."""
        out = {}
        if self.rh_knots == "auto":
            out["rh_knots_pct"] = list(fm.knots)
        if fm.memory_range:
            out["memory_range_s"] = [float(x) for x in fm.memory_range]
        if fm.linear is not None:
            out["linear_start"] = fm.linear.card()
        return out

    def restore(self, kind: str, fs: float, use_rh: bool, card: dict) -> "FeatureMap":
        """The fitted features from a bundle card's entries (see :meth:`card`)."""
        if self.rh_knots == "auto":
            if card.get("rh_knots_pct") is None:
                raise InputError(f"model {kind!r} with rh_knots 'auto' needs the knots found in "
                                 "training (card entry rh_knots_pct); the bundle lacks them")
            knots = [float(k) for k in card["rh_knots_pct"]]
        else:
            knots = [float(k) for k in (self.rh_knots or [])]
        rng = card.get("memory_range_s")
        if rng is None and self.memory_filters:   # cards written before the range adapted to the data
            rng = (self.memory_min_s, self.memory_max_s)
        rng = None if rng is None else (float(rng[0]), float(rng[1]))
        linear = None
        if self.linear_start:
            from ..linear import LinearModel
            if card.get("linear_start") is None:
                raise InputError(f"model {kind!r} with linear_start needs its linear model (card entry "
                                 "linear_start); the bundle lacks it")
            linear = LinearModel.from_card(card["linear_start"], "card entry linear_start")
        return FeatureMap(float(fs), bool(use_rh), knots, rng, int(self.memory_filters), bool(self.memory_abs),
                          linear)


@dataclass
class FeatureMap:
    """Fitted input features: records in physical units -> normalised core channels.

    ``u`` channels: normalised voltage, then (``linear``) the free run of the linear start in
    the output's normalisation, then the memory filters (each divided by its standard
    deviation over the training records, held by the :class:`~.normalise.Normalized` module
    as ``mem_std``); ``rh`` channels: normalised RH, then one hat per RH knot."""

    fs: float
    use_rh: bool
    knots: list
    memory_range: tuple | None
    n_filters: int
    memory_abs: bool
    linear: object = None

    @property
    def n_ref(self) -> int:
        """Reference channels (the linear start's output) after the voltage."""
        return 0 if self.linear is None else 1

    @property
    def taus(self) -> np.ndarray:
        """Memory time constants (s)."""
        if not self.n_filters:
            return np.zeros(0)
        return memory_taus(self.n_filters, *self.memory_range)

    @property
    def n_mem(self) -> int:
        """Memory channels: the filters of the voltage (and of |V| with ``memory_abs``)."""
        return 2 * self.n_filters if self.memory_abs else self.n_filters

    @property
    def n_rh(self) -> int:
        """RH channels given to the core: normalised RH, then one hat per knot."""
        return (1 + len(self.knots)) if self.use_rh else 0

    @property
    def n_sched(self) -> int:
        """Hat channels that schedule a linear path on RH."""
        return len(self.knots) if self.use_rh else 0

    def memory_raw(self, u: np.ndarray, net, last: np.ndarray | None = None) -> np.ndarray:
        """Memory filters of the normalised voltage (and of |V| / std(V) with
        ``memory_abs``) for a voltage record ``u`` in V, unscaled; ``last``: their values at
        the sample before ``u`` (a record in pieces), else at rest with ``u[0]``."""
        n = self.n_filters
        m = memory_filters(net.norm("u", u), self.taus, self.fs, None if last is None else last[:n])
        if self.memory_abs:
            _, sd = net.stat("u")
            m = np.concatenate([m, memory_filters(np.abs(u) / sd, self.taus, self.fs,
                                                  None if last is None else last[n:])], 1)
        return m

    def memory(self, u: np.ndarray, net) -> np.ndarray:
        """Memory channels of a voltage record ``u`` (V), each at unit scale over training."""
        m = self.memory_raw(u, net)
        return m / net.mem_std.numpy() if hasattr(net, "mem_std") else m

    def set_scale(self, records, net) -> None:
        """Store the standard deviation of every memory channel over ``records`` in ``net``."""
        if self.n_mem:
            import torch
            M = np.concatenate([self.memory_raw(r.u, net) for r in records])
            sd = M.std(0)
            sd[~np.isfinite(sd) | (sd <= 1e-12)] = 1.0
            net.mem_std.copy_(torch.as_tensor(sd))

    def rh_channels(self, rh: np.ndarray | None, net) -> np.ndarray | None:
        """Normalised RH and its hat weights (None when the model ignores humidity)."""
        if rh is None or not self.use_rh:
            return None
        parts = [net.norm("rh", rh)[:, None]]
        if self.knots:
            parts.append(rh_hats(rh, self.knots))
        return np.concatenate(parts, 1) if len(parts) > 1 else parts[0]

    def channels(self, u: np.ndarray, rh: np.ndarray | None, net,
                 y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """(``u`` channels (n, 1 + n_ref + n_mem), ``rh`` channels (n, n_rh) or None) of a
        record; ``y``: measured outputs from the record's start (only the linear start uses
        them, to start its free run)."""
        return self.channels_continued(u, rh, net, None, y)[:2]

    def channels_continued(self, u: np.ndarray, rh: np.ndarray | None, net, last, y: np.ndarray | None = None):
        """:meth:`channels` of a piece of a record whose filters ended in the state ``last``
        (None: the first piece, started from ``y`` as :meth:`channels` says), and the state at
        its last sample (for the next piece): the memory filters' values and the linear
        start's free-run state."""
        mem_last, lin_last = (None, None) if last is None else last
        cols = [net.norm("u", u)[:, None]]
        if self.linear is not None:
            lin = self.linear
            y0 = None if y is None or len(y) == 0 else np.asarray(y, float)[:lin.n_init]
            ref, lin_last = lin.free_run(u, rh if lin.uses_rh else None, y_init=y0, state=lin_last)
            cols.append(net.norm("y", ref)[:, None])
        raw = None
        if self.n_mem:
            raw = self.memory_raw(u, net, mem_last)
            cols.append(raw / net.mem_std.numpy() if hasattr(net, "mem_std") else raw)
        U = np.concatenate(cols, 1) if len(cols) > 1 else cols[0]
        return U, self.rh_channels(rh, net), (None if raw is None else raw[-1].copy(), lin_last)
