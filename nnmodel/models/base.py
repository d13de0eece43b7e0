"""The contract every neural model follows (scikit-learn style, SysIdentPy-style predict).

* Hyper-parameters are the keyword arguments of ``__init__`` (``get_params`` reads them back);
  learned state lives in attributes ending in ``_`` and exists only after :meth:`fit`.
* Callers use physical units: the normalisation of every channel (voltage, humidity,
  output) is learned in :meth:`fit` and stored inside the model (:class:`Normalized`).
* ``fit(train, val=None)`` takes lists of :class:`nnmodel.data.Record`; without ``val`` the
  last ``val_fraction`` of every training record is held out for early stopping.
* ``simulate(u, rh=None, y_init=None)`` is a free-run simulation: no measured output is fed
  back; ``y_init`` (the first measured outputs) may only initialise the state.
* ``predict(u, rh=None, y=None, steps_ahead=None | k)``: ``None`` is a free run (initialised
  from the first ``n_init_`` samples of ``y`` when given), ``k`` is k-step-ahead
  prediction: each output is simulated ``k`` steps from the measured past.

Inside, a model is a torch *core* (:class:`SequenceCore`) working on normalised tensors
with two methods kept apart as in torchid/dynoNet: ``init_state`` (the initial-state
estimator: measured history -> state) and ``simulate`` (state + inputs -> outputs).  All
models are trained with the same Lightning loop (:mod:`nnmodel.training`).
"""
from __future__ import annotations

import contextlib
import copy
import inspect
import math
import time
import warnings
from dataclasses import asdict
from typing import Any

import numpy as np
import torch
from torch import nn

from physics.errors import InputError

from ..data import Record, check_records, check_voltage, rh_range, split_index
from .config import TRAINING_FIELDS, TrainingConfig, training_config

__all__ = ["SequenceCore", "Normalized", "NeuralModel", "NotFittedError"]


#: The fastest memory filter spans at least this many sample periods ...
MEMORY_MIN_SAMPLES = 2.0
#: ... and the slowest at most this fraction of the (median) training record.
MEMORY_MAX_FRACTION = 0.5
#: Samples per piece of a free run (bounds the activations held at once on long records).
SIM_CHUNK = 1 << 16


class NotFittedError(InputError):
    """The model was used before :meth:`NeuralModel.fit` (or loading)."""


class SequenceCore(nn.Module):
    """Interface of a torch core; all tensors are normalised, shapes (batch, time).

    ``n_init`` is the number of past samples ``init_state`` needs.
    """

    n_init: int = 1

    def init_state(self, u_hist, y_hist, rh_hist):  # pragma: no cover - interface
        raise NotImplementedError

    def simulate(self, state, u, rh):  # pragma: no cover - interface
        raise NotImplementedError

    def advance(self, state, u, rh):
        """(outputs, state after the last sample) of :meth:`simulate`, so that a long record
        can be simulated in chunks with the same result; ``None`` as the state means the
        core cannot continue (the caller then simulates in one piece)."""
        return self.simulate(state, u, rh), None


class Normalized(nn.Module):
    """A core plus the affine normalisation of each channel (stored as buffers, so it is
    saved with the weights)."""

    def __init__(self, core: SequenceCore, n_mem: int = 0):
        super().__init__()
        self.core = core
        for name in ("u", "y", "rh"):
            self.register_buffer(f"{name}_mean", torch.zeros((), dtype=torch.float64))
            self.register_buffer(f"{name}_std", torch.ones((), dtype=torch.float64))
        if n_mem:  # scale of each memory filter's output (they shrink with the time constant)
            self.register_buffer("mem_std", torch.ones(int(n_mem), dtype=torch.float64))

    def set_stats(self, records: list[Record], use_rh: bool) -> None:
        def stats(x):
            m, s = float(np.mean(x)), float(np.std(x))
            if not np.isfinite(s) or s <= 1e-12 * max(1.0, abs(m)):
                s = 1.0  # a constant channel: centre it, do not blow it up
            return m, s
        u = np.concatenate([r.u for r in records])
        y = np.concatenate([r.y for r in records])
        for name, x in (("u", u), ("y", y)):
            m, s = stats(x)
            getattr(self, f"{name}_mean").fill_(m)
            getattr(self, f"{name}_std").fill_(s)
        if use_rh:
            m, s = stats(np.concatenate([r.rh for r in records]))
            self.rh_mean.fill_(m)
            self.rh_std.fill_(s)

    def stat(self, name: str) -> tuple[float, float]:
        return float(getattr(self, f"{name}_mean")), float(getattr(self, f"{name}_std"))

    def norm(self, name: str, x: np.ndarray) -> np.ndarray:
        m, s = self.stat(name)
        return (np.asarray(x, float) - m) / s

    def denorm(self, name: str, x: np.ndarray) -> np.ndarray:
        m, s = self.stat(name)
        return np.asarray(x, float) * s + m


class _Seq:
    """A normalised record used by the training code: ``u`` (n, input channels), ``y``
    (n,), ``rh`` (n, RH channels) or None."""

    __slots__ = ("u", "y", "rh")

    def __init__(self, u, y, rh):
        self.u, self.y, self.rh = u, y, rh

    def __len__(self):
        return len(self.u)

    def __getitem__(self, sl: slice) -> "_Seq":
        return _Seq(self.u[sl], self.y[sl], None if self.rh is None else self.rh[sl])


@contextlib.contextmanager
def torch_threads(n: int | None):
    """Temporarily limit torch intra-op threads and BLAS threads to ``n`` (None: leave).

    The networks here are small: on a shared 2-core machine one thread is several times
    faster than two (measured: 14 s vs 94 s for two NARX epochs on Silverbox while other
    jobs ran), because waiting threads spin against the other processes."""
    if not n:
        yield
        return
    from threadpoolctl import threadpool_limits  # a scikit-learn dependency

    old = torch.get_num_threads()
    torch.set_num_threads(int(n))
    try:
        with threadpool_limits(limits=int(n), user_api="blas"):
            yield
    finally:
        torch.set_num_threads(old)


def seed_all(seed: int) -> None:
    """Seed Python, numpy and torch (same seed -> same initial weights and batches)."""
    import random
    random.seed(seed)
    np.random.seed(seed % (2 ** 32))
    torch.manual_seed(seed)


# Hyper-parameters shared by every model: (default, check) where check returns an error text.
def _pos_int(v, zero=False):
    ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and (v >= 0 if zero else v >= 1)
    return None if ok else ("a non-negative integer" if zero else "a positive integer")


def _pos_float(v, zero=False):
    ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and math.isfinite(v) \
        and (v >= 0 if zero else v > 0)
    return None if ok else ("a non-negative number" if zero else "a positive number")


class NeuralModel:
    """Base class of the neural models (see the module docstring for the contract)."""

    #: registry name ("ff", "rbf", ...), set by subclasses
    kind = "base"
    #: card entries (besides the standard ones) that learned_state() may write and
    #: restore() reads back
    CARD_EXTRA: tuple[str, ...] = ("rh_knots_pct", "memory_range_s")
    #: parameter name -> validator(value) -> error text or None (subclasses extend)
    _checks: dict = {
        "seed": lambda v: _pos_int(v, zero=True),
        "lr": _pos_float,
        "weight_decay": lambda v: _pos_float(v, zero=True),
        "batch_size": _pos_int,
        "max_epochs": lambda v: _pos_int(v, zero=True),
        "max_time": lambda v: None if v is None else _pos_float(v),
        "patience": _pos_int,
        "val_fraction": lambda v: None if (_pos_float(v, zero=True) is None and v < 1) else "a number in [0, 1)",
        "grad_clip": lambda v: None if v is None else _pos_float(v),
        "progress_bar": lambda v: None if isinstance(v, bool) else "true or false",
        "num_threads": lambda v: None if v is None else _pos_int(v),
        "accelerator": lambda v: None if isinstance(v, str) else "a Lightning accelerator name such as 'cpu'",
        "inputs": lambda v: None if v in ("auto", "voltage", "voltage+rh") else "'auto', 'voltage' or 'voltage+rh'",
        "checkpoint_dir": lambda v: None if v is None or isinstance(v, str) else "a folder path or null",
        "memory_filters": lambda v: _pos_int(v, zero=True),
        "memory_min_s": _pos_float,
        "memory_max_s": _pos_float,
        "memory_abs": lambda v: None if isinstance(v, bool) else "true or false",
        "structures": lambda v: None if v is None or (isinstance(v, list) and all(isinstance(c, dict) for c in v))
        else "null or a list of hyper-parameter mappings, e.g. [{}, {na: 10, nb: 10}]",
    }

    #: where this model's training defaults differ from :class:`TrainingConfig`'s
    TRAINING_DEFAULTS: dict = {}

    # ------------------------------------------------------------------ parameters
    @classmethod
    def _model_params(cls) -> dict:
        """The constructor's own (model) parameters with their defaults."""
        sig = inspect.signature(cls.__init__)
        return {k: p.default for k, p in sig.parameters.items()
                if k != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD}

    @classmethod
    def param_names(cls) -> list[str]:
        """Every hyper-parameter: the model's own, then the training settings."""
        return list(cls._model_params()) + list(TRAINING_FIELDS)

    @classmethod
    def default_params(cls) -> dict:
        return {**cls._model_params(), **asdict(TrainingConfig(**cls.TRAINING_DEFAULTS))}

    def get_params(self) -> dict:
        return {k: getattr(self, k) for k in self.param_names()}

    def _set_params_from(self, local_vars: dict) -> None:
        """Store the ``__init__`` arguments (the model's own as attributes, the training
        settings given as ``**training`` in :attr:`training`) and validate them
        (subclasses call ``self._set_params_from(locals())`` at the end of ``__init__``)."""
        self.training = training_config(self.kind, self.TRAINING_DEFAULTS, local_vars.get("training", {}))
        for k in self._model_params():
            setattr(self, k, local_vars[k])
        self._validate()

    def __getattr__(self, name):
        # training settings read as attributes (only called when normal lookup fails)
        if name in TRAINING_FIELDS and "training" in self.__dict__:
            return getattr(self.__dict__["training"], name)
        raise AttributeError(f"{type(self).__name__!s} has no attribute {name!r}")

    def __setattr__(self, name, value):
        if name in TRAINING_FIELDS:
            setattr(self.training, name, value)
        else:
            super().__setattr__(name, value)

    def set_params(self, **params) -> "NeuralModel":
        unknown = sorted(set(params) - set(self.param_names()))
        if unknown:
            raise InputError(f"unknown hyper-parameter(s) {unknown} for model {self.kind!r}; "
                             f"known: {', '.join(self.param_names())}")
        for k, v in params.items():
            setattr(self, k, v)
        self._validate()
        return self

    def _validate(self) -> None:
        checks = {}
        for klass in reversed(type(self).__mro__):
            checks.update(getattr(klass, "_checks", {}))
        for name in self.param_names():
            chk = checks.get(name)
            if chk is None:
                continue
            msg = chk(getattr(self, name))
            if msg:
                raise InputError(f"model {self.kind!r}: hyper-parameter {name}="
                                 f"{getattr(self, name)!r} is invalid; expected {msg}")

    def __repr__(self) -> str:
        defaults = self.default_params()
        diff = {k: v for k, v in self.get_params().items() if defaults.get(k) != v}
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in diff.items())})"

    # ------------------------------------------------------------------ to override
    def _build_core(self, n_rh: int) -> SequenceCore:
        raise NotImplementedError

    def _initialise(self, core: SequenceCore, train: list[_Seq]) -> None:
        """Non-gradient initialisation (least squares, k-means); default: nothing."""

    def _training_settings(self) -> dict:
        """Settings passed to :func:`nnmodel.training.fit_core`."""
        return dict(horizon=1, stride=1)

    def _gradient_epochs(self) -> int:
        return int(self.max_epochs)

    # ------------------------------------------------------------------ fitting
    def fit(self, train, val=None) -> "NeuralModel":
        """Train on ``train`` records (early stopping on the free-run error of ``val``)."""
        self._validate()
        train = check_records(train, "training")
        if val is not None:
            val = check_records(val, "validation")
            check_records(train + val, "training + validation")
        fs = train[0].fs
        has_rh = train[0].rh is not None
        if self.inputs == "voltage+rh" and not has_rh:
            raise InputError(f"model {self.kind!r} was asked for inputs voltage+rh but the training "
                             "records carry no relative humidity")
        use_rh = has_rh and self.inputs != "voltage"
        seed_all(self.seed)
        try:
            if len(getattr(self, "structures", None) or []) > 1:
                self._select_structure(train, val)
            else:
                self._fit(train, val, fs, use_rh)
        except BaseException:
            for attr in self._LEARNED:  # never leave a half-trained model behind
                self.__dict__.pop(attr, None)
            raise
        return self

    #: Overrides that turn a candidate structure into a cheap stand-in for scoring it (e.g.
    #: the linear least-squares start of a network); ``None``: candidates are fitted in full.
    _SELECTION_PROXY: dict | None = None

    def _select_structure(self, train, val) -> None:
        """Choose among ``structures`` (hyper-parameter overrides, e.g. with and without
        output feedback) the one with the lowest free-run NRMSE on the validation data, and
        fit it.  Each candidate is scored as fitted in full, or — for models with a
        :attr:`_SELECTION_PROXY` — as its cheap stand-in (the FF network's linear
        least-squares start), and only the winner is then trained.  Every score goes into
        the card (``structure_search``).  The choice uses validation data only, so one recipe
        serves plants that need output feedback (a resonance) and plants where it drifts."""
        known = set(self.param_names()) - {"structures"}
        for over in self.structures:
            if set(over) - known:
                raise InputError(f"model {self.kind!r}: structures entry {over} names unknown hyper-parameter(s) "
                                 f"{sorted(set(over) - known)}; known: {', '.join(sorted(known))}")
        proxy = self._SELECTION_PROXY or {}
        tried, best = [], None
        for over in self.structures:
            cand = copy.deepcopy(self)
            cand.set_params(**{**over, **proxy, "structures": None})
            with warnings.catch_warnings():
                if best is not None:        # the data-fit warnings were already given once
                    warnings.simplefilter("ignore", UserWarning)
                cand.fit(train, val)
            score = cand._validation_nrmse(train, val)
            tried.append({"structure": dict(over), "validation_free_run_nrmse": score,
                          "scored_as": "linear least-squares start" if proxy else "fitted model",
                          "fit_time_s": cand.fit_time_})
            if best is None or score < best[0]:
                best = (score, over, cand)
        chosen = best[2]
        if proxy:
            chosen = copy.deepcopy(self)
            chosen.set_params(**{**best[1], "structures": None})
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                chosen.fit(train, val)
        structures = self.structures
        self.__dict__.update(chosen.__dict__)
        self.structures = structures
        self.structure_search_ = tried

    def _validation_nrmse(self, train, val) -> float:
        """Pooled free-run NRMSE on ``val`` records, or (without them) on the last
        ``val_fraction`` of each training record simulated from its start; inf when the
        simulation diverges."""
        if val:
            parts = [(r, 0) for r in val]
        else:
            parts = [(r, split_index(len(r), self.val_fraction, self.n_init_ + 2) or 0) for r in train]
        e2 = v2 = 0.0
        for r, k in parts:
            with np.errstate(all="ignore"):
                yh = self.simulate(r.u, r.rh, y_init=r.y[:self.n_init_])
            s = max(k, self.n_init_)
            y, e = r.y[s:], yh[s:] - r.y[s:]
            if not np.all(np.isfinite(e)):
                return math.inf
            e2 += float(np.sum(e ** 2))
            v2 += float(np.sum((y - y.mean()) ** 2))
        return math.sqrt(e2 / v2) if v2 > 0 else math.inf

    _LEARNED = ("net_", "inputs_", "fs_", "rh_range_", "n_init_", "fit_time_", "history_", "training_summary_",
                "memory_range_", "structure_search_",
                "init_report_", "rh_knots_")

    def _fit(self, train, val, fs, use_rh) -> None:
        from ..training import fit_core  # Lightning is imported only when training

        with torch_threads(self.num_threads):
            if getattr(self, "rh_knots", None) == "auto":
                from .features import auto_knots
                self.rh_knots_ = auto_knots([r.rh for r in train]) if use_rh else []
            self._adapt_memory(fs, train)
            core = self._build_core(self._n_rh_channels(use_rh))
            min_len = core.n_init + 2
            # channels (memory filters, physics) are computed on whole records and then cut,
            # so a validation tail continues the filter states of its record
            cuts = None
            full = list(train)
            if val is None and self.val_fraction > 0:
                cuts = [split_index(len(r), self.val_fraction, min_len) for r in full]
                train = [r[:k] if k else r for r, k in zip(full, cuts)]
                val = []
            val = [r for r in (val or []) if len(r) >= min_len]
            net = Normalized(core, self._n_mem())
            net.set_stats(train, use_rh)
            self.net_ = net
            self.inputs_ = ["voltage", "rh"] if use_rh else ["voltage"]
            self.fs_ = fs
            self.rh_range_ = rh_range(train) if use_rh else None
            self.n_init_ = int(core.n_init)
            self._prepare_channels(full + val)
            if cuts is None:
                tr = [self._norm_record(r) for r in train]
                va = [self._norm_record(r) for r in val]
            else:
                seqs = [self._norm_record(r) for r in full]
                tr = [s[:k] if k else s for s, k in zip(seqs, cuts)]
                va = [s[k:] for s, k in zip(seqs, cuts) if k]
            self._release_channels()
            t0 = time.perf_counter()
            self._initialise(core, tr)
            history: list[dict] = []
            if self._gradient_epochs() > 0:
                settings = {**self.training.fit_settings(), "max_epochs": self._gradient_epochs(),
                            **self._training_settings()}
                history, self.training_summary_ = fit_core(core, tr, va, **settings)
            self.fit_time_ = time.perf_counter() - t0
            self.history_ = history
            core.eval()

    # ------------------------------------------------------------------ input channels
    def _memory_taus(self) -> np.ndarray:
        from .features import memory_taus
        n = int(getattr(self, "memory_filters", 0) or 0)
        lo, hi = getattr(self, "memory_range_", None) or (getattr(self, "memory_min_s", 0.02),
                                                           getattr(self, "memory_max_s", 100.0))
        return memory_taus(n, lo, hi)

    def _adapt_memory(self, fs: float, records) -> None:
        """Fit the memory filters' time constants to the data: none faster than
        :data:`MEMORY_MIN_SAMPLES` sample periods, none slower than :data:`MEMORY_MAX_FRACTION`
        of the median training record; the recipe's range is kept where the data support it
        (a warning says when it is not).  The chosen range is stored in the bundle card."""
        if not int(getattr(self, "memory_filters", 0) or 0):
            self.memory_range_ = None
            return
        want = (float(self.memory_min_s), float(self.memory_max_s))
        floor = MEMORY_MIN_SAMPLES / fs
        ceiling = MEMORY_MAX_FRACTION * float(np.median([len(r) for r in records])) / fs
        lo = max(want[0], floor)
        hi = min(want[1], ceiling)
        if hi <= lo * 1.01:   # records too short for the range: one decade above the fastest
            hi = lo * 10.0
        if (lo, hi) != want:
            warnings.warn(f"model {self.kind!r}: memory filters {want[0]:g}–{want[1]:g} s do not fit these data "
                          f"(sample period {1 / fs:.3g} s, records of ~{ceiling / MEMORY_MAX_FRACTION:.3g} s); "
                          f"using {lo:.3g}–{hi:.3g} s", UserWarning, stacklevel=3)
        self.memory_range_ = (lo, hi)

    def _n_mem(self) -> int:
        """Number of memory channels: the filters of the voltage, and with ``memory_abs``
        the same filters of its magnitude |V| (slow measures of the drive level)."""
        n = int(getattr(self, "memory_filters", 0) or 0)
        return 2 * n if getattr(self, "memory_abs", False) else n

    def _rh_knots(self) -> list:
        """RH knots of the scheduled bypass (%): the hyper-parameter, or for ``"auto"`` the
        knots found in the training data (:func:`features.auto_knots`)."""
        k = getattr(self, "rh_knots", None)
        if k == "auto":
            return list(getattr(self, "rh_knots_", None) or [])
        return list(k or [])

    def _n_rh_channels(self, use_rh: bool) -> int:
        """RH channels given to the core: normalised RH, then one hat per RH knot."""
        return (1 + len(self._rh_knots())) if use_rh else 0

    def _channels(self, u: np.ndarray, rh: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """Normalised input channels of a record in physical units: ``u`` (n, C) = voltage,
        then the memory filters of the normalised voltage; ``rh`` (n, C_rh) = normalised RH,
        then the RH hat weights (or None when the model ignores humidity)."""
        from .features import rh_hats
        n = self.net_
        un = n.norm("u", u)
        cols = [un[:, None]]
        if self._n_mem():
            cols.append(self._memory(u))
        U = np.concatenate(cols, 1) if len(cols) > 1 else cols[0]
        R = None
        if rh is not None and "rh" in self.inputs_:
            parts = [n.norm("rh", rh)[:, None]]
            if self._rh_knots():
                parts.append(rh_hats(rh, self._rh_knots()))
            R = np.concatenate(parts, 1) if len(parts) > 1 else parts[0]
        return U, R

    def _memory_raw(self, u: np.ndarray) -> np.ndarray:
        """Memory filters of the normalised voltage (and of |V| / std(V) with
        ``memory_abs``) for a voltage record ``u`` in V, unscaled."""
        from .features import memory_filters
        n = self.net_
        m = memory_filters(n.norm("u", u), self._memory_taus(), self.fs_)
        if getattr(self, "memory_abs", False):
            _, sd = n.stat("u")
            m = np.concatenate([m, memory_filters(np.abs(u) / sd, self._memory_taus(), self.fs_)], 1)
        return m

    def _memory(self, u: np.ndarray) -> np.ndarray:
        """Memory channels of a voltage record ``u`` (V), each divided by its standard
        deviation over the training records (unit scale for the gradient-trained networks)."""
        m = self._memory_raw(u)
        return m / self.net_.mem_std.numpy() if hasattr(self.net_, "mem_std") else m

    def _prepare_channels(self, records: list[Record]) -> None:
        """Hook before the training records are normalised: sets the scale of the memory
        filters (the hybrid also runs its physics here, once per record)."""
        if self._n_mem():
            M = np.concatenate([self._memory_raw(r.u) for r in records])
            sd = M.std(0)
            sd[~np.isfinite(sd) | (sd <= 1e-12)] = 1.0
            self.net_.mem_std.copy_(torch.as_tensor(sd))

    def _release_channels(self) -> None:
        """Hook after the training records are normalised (drop caches)."""

    def _norm_record(self, r: Record) -> _Seq:
        U, R = self._channels(r.u, r.rh if "rh" in self.inputs_ else None)
        return _Seq(U, self.net_.norm("y", r.y), R)

    # ------------------------------------------------------------------ inference
    def _check_fitted(self) -> None:
        if not hasattr(self, "net_"):
            raise NotFittedError(f"model {self.kind!r} is not trained yet: call fit() or load a bundle")

    @property
    def uses_rh(self) -> bool:
        self._check_fitted()
        return "rh" in self.inputs_

    def _prepare(self, u, rh, y=None, y_name="y"):
        """Validate inputs in physical units; returns (u, rh or None, y or None) arrays."""
        self._check_fitted()
        u = check_voltage(u)
        n = u.size
        if self.uses_rh:
            if rh is None:
                lo, hi = self.rh_range_
                raise InputError(f"this model takes relative humidity as an input (trained on "
                                 f"{lo:g}-{hi:g} %RH); pass rh= (a constant or one value per sample)")
            rh = np.asarray(rh, dtype=float)
            if rh.ndim == 0:
                rh = np.full(n, float(rh))
            if rh.shape != (n,):
                raise InputError(f"rh must be a constant or have one value per voltage sample "
                                 f"({n}), got shape {rh.shape}")
            if not np.all(np.isfinite(rh)):
                raise InputError("rh contains NaN or infinite values")
            if rh.min() < 0 or rh.max() > 100:
                raise InputError(f"relative humidity must lie in 0-100 %, got {rh.min():g}-{rh.max():g} %")
            lo, hi = self.rh_range_
            tol = 1e-9 * max(1.0, hi)
            if rh.min() < lo - tol or rh.max() > hi + tol:
                warnings.warn(f"relative humidity {rh.min():g}-{rh.max():g} % is outside the range "
                              f"seen in training ({lo:g}-{hi:g} %RH): the model extrapolates and "
                              "its predictions are not validated there", RuntimeWarning, stacklevel=3)
        elif rh is not None:
            warnings.warn("this model was trained without humidity; the rh argument is ignored",
                          RuntimeWarning, stacklevel=3)
            rh = None
        if y is not None:
            y = np.asarray(y, dtype=float)
            if y.ndim != 1:
                raise InputError(f"{y_name} must be a 1-D array, got shape {y.shape}")
            if not np.all(np.isfinite(y)):
                raise InputError(f"{y_name} contains NaN or infinite values")
        return u, rh, y

    def _padded(self, u, rh, y, pad: int):
        """Normalised channels (see :meth:`_channels`) with ``pad`` samples in front: with a
        measured output ``y``, held at the first samples (the steady state of the first input
        and output, so the memory filters start there whatever the record's start); without
        one, at rest (0 V, output 0, the first RH), the documented assumption of a free run."""
        n = self.net_
        known = y is not None and y.size > 0
        up = np.concatenate([np.full(pad, u[0] if known else 0.0), u])
        rhp = None if rh is None else np.concatenate([np.full(pad, rh[0]), rh])
        un, rhn = self._channels(up, rhp)
        yn = None if y is None else np.concatenate([np.full(pad, n.norm("y", float(y[0]) if known else 0.0)),
                                                    n.norm("y", y)])
        return un, rhn, yn

    @staticmethod
    def _t(x):
        return None if x is None else torch.as_tensor(np.ascontiguousarray(x), dtype=torch.float32)

    def simulate(self, u, rh=None, y_init=None) -> np.ndarray:
        """Free-run simulation in physical units.

        ``y_init``: the first measured outputs (any length m < len(u)); they only initialise
        the state (the last ``n_init_`` of them are used) and are returned unchanged as the
        first m outputs.  Without ``y_init`` the system is assumed at rest (0 V, 0 output)
        before the first sample.
        """
        u, rh, y_init = self._prepare(u, rh, y_init, "y_init")
        m = 0 if y_init is None else y_init.size
        if m >= u.size:
            raise InputError(f"y_init has {m} samples but the input only {u.size}; y_init must be "
                             "shorter than the record it initialises")
        k = self.n_init_
        pad = max(0, k - m)
        yfull = None if y_init is None else y_init
        un, rhn, yn = self._padded(u, rh, yfull if yfull is not None else np.zeros(0), pad)
        s = pad + m  # first simulated index in padded arrays
        core = self.net_.core
        out = np.empty(un.shape[0] - s)
        with torch.no_grad(), torch_threads(self.num_threads):
            state = core.init_state(self._t(un[None, s - k:s]), self._t(yn[None, s - k:s]),
                                    None if rhn is None else self._t(rhn[None, s - k:s]))
            # chunks bound the memory of long records (same result); a core that cannot
            # continue from a state (no advance) runs in one piece
            step = SIM_CHUNK if type(core).advance is not SequenceCore.advance else un.shape[0]
            for a in range(s, un.shape[0], step):
                b = min(un.shape[0], a + step)
                o, state = core.advance(state, self._t(un[None, a:b]), None if rhn is None else self._t(rhn[None, a:b]))
                out[a - s:b - s] = o[0].double().numpy()
        y_hat = self.net_.denorm("y", out)
        if m:
            y_hat = np.concatenate([y_init, y_hat])
        return y_hat

    def predict(self, u, rh=None, y=None, steps_ahead: int | None = None,
                chunk: int = 4096) -> np.ndarray:
        """SysIdentPy-style prediction.

        ``steps_ahead=None``: free run (initialised from the first ``n_init_`` samples of
        ``y`` when ``y`` is given, else from rest).  ``steps_ahead=k``: each output ``y[t]``
        is simulated over ``k`` steps starting from the measured ``y`` up to ``t - k``; the
        first ``k - 1`` outputs, whose start would lie before the record, are simulated from
        the steady state of the first samples (input ``u[0]`` and output ``y[0]`` held before the
        record), so a model without output feedback gives the same values as its free run.  ``k = 1`` is one-step-ahead prediction.
        """
        if steps_ahead is None:
            if y is None:
                return self.simulate(u, rh)
            return self.simulate(u, rh, y_init=np.asarray(y, float)[: self.n_init_])
        if isinstance(steps_ahead, bool) or not isinstance(steps_ahead, (int, np.integer)) or steps_ahead < 1:
            raise InputError(f"steps_ahead must be None or a positive integer, got {steps_ahead!r}")
        if y is None:
            raise InputError("k-step-ahead prediction needs the measured output y")
        u, rh, y = self._prepare(u, rh, y)
        if y.size != u.size:
            raise InputError(f"y has {y.size} samples but the voltage has {u.size}")
        N, n0 = u.size, self.n_init_
        k = int(min(steps_ahead, N))
        un, rhn, yn = self._padded(u, rh, y, n0)
        core = self.net_.core
        out = np.empty(N)
        hist_idx = np.arange(-n0, 0)
        sim_idx = np.arange(k)
        with torch.no_grad(), torch_threads(self.num_threads):
            for a in range(0, N, chunk):
                t = np.arange(a, min(N, a + chunk))
                start = np.maximum(t - k + 1, 0)  # first simulated sample of each prediction
                s = start + n0  # ... in the padded arrays
                H, S = s[:, None] + hist_idx, s[:, None] + sim_idx
                state = core.init_state(self._t(un[H]), self._t(yn[H]),
                                        None if rhn is None else self._t(rhn[H]))
                o = core.simulate(state, self._t(un[S]), None if rhn is None else self._t(rhn[S]))
                out[t] = o[np.arange(t.size), t - start].double().numpy()
        return self.net_.denorm("y", out)

    @property
    def n_parameters(self) -> int:
        """Number of learned parameters (weights, biases, centres, widths)."""
        self._check_fitted()
        return int(sum(p.numel() for p in self.net_.core.parameters()))

    # ------------------------------------------------------------------ persistence helpers
    def learned_state(self) -> dict[str, Any]:
        """JSON-able learned attributes other than the weights (used by bundles)."""
        self._check_fitted()
        out = {"inputs": list(self.inputs_), "fs": self.fs_,
               "rh_range": None if self.rh_range_ is None else list(self.rh_range_),
               "n_init": self.n_init_, "fit_time_s": getattr(self, "fit_time_", None)}
        if getattr(self, "rh_knots", None) == "auto":
            out["card_extra"] = {"rh_knots_pct": self._rh_knots()}
        if getattr(self, "memory_range_", None):
            out.setdefault("card_extra", {})["memory_range_s"] = [float(x) for x in self.memory_range_]
        if getattr(self, "structure_search_", None):
            out.setdefault("card_extra", {})["structure_search"] = self.structure_search_
        return out

    def restore(self, learned: dict, state_dict: dict) -> "NeuralModel":
        """Rebuild the network from ``learned_state()`` and load its weights."""
        self._validate()
        inputs = list(learned["inputs"])
        if inputs not in (["voltage"], ["voltage", "rh"]):
            raise InputError(f"unsupported model inputs {inputs}")
        if getattr(self, "rh_knots", None) == "auto":
            knots = (learned.get("card_extra") or {}).get("rh_knots_pct")
            if knots is None:
                raise InputError(f"model {self.kind!r} with rh_knots 'auto' needs the knots found in "
                                 "training (card entry rh_knots_pct); the bundle lacks them")
            self.rh_knots_ = [float(k) for k in knots]
        rng = (learned.get("card_extra") or {}).get("memory_range_s")
        self.memory_range_ = None if rng is None else (float(rng[0]), float(rng[1]))
        core = self._build_core(self._n_rh_channels("rh" in inputs))
        net = Normalized(core, self._n_mem())
        missing, unexpected = net.load_state_dict(state_dict, strict=False)
        if missing or unexpected:
            raise InputError(f"saved weights do not match a {self.kind!r} model with these "
                             f"hyper-parameters (missing {missing}, unexpected {unexpected})")
        net.eval()
        self.net_ = net
        self.inputs_ = inputs
        self.fs_ = float(learned["fs"])
        self.rh_range_ = None if learned.get("rh_range") is None else tuple(learned["rh_range"])
        self.n_init_ = int(core.n_init)
        self.fit_time_ = learned.get("fit_time_s")
        self.history_ = []
        return self
