"""The estimator contract every network follows (scikit-learn style, SysIdentPy-style predict).

* Hyper-parameters are the keyword arguments of ``__init__`` (what the network is) plus the
  fields of the settings parts every model composes (:data:`PARTS`: training, input
  features, structure search); ``get_params`` reads them all back as flat keys.  Learned
  state lives in attributes ending in ``_`` and exists only after :meth:`fit`.
* Callers use physical units: the normalisation of every channel (voltage, humidity,
  output) is learned in :meth:`fit` and stored inside the model (:class:`~.normalise.Normalized`).
* ``fit(train, val=None)`` takes lists of :class:`nnmodel.data.Experiment` (or of
  :class:`physics.io.record.TimeSeries`, viewed as such); without ``val``
  the last ``val_fraction`` of every training record is held out for early stopping.
* ``simulate(u, rh=None, y_init=None)`` is a free-run simulation: no measured output is fed
  back; ``y_init`` (the first measured outputs) may only initialise the state.
* ``predict(u, rh=None, y=None, steps_ahead=None | k)``: ``None`` is a free run (initialised
  from the first ``n_init_`` samples of ``y`` when given), ``k`` is k-step-ahead
  prediction: each output is simulated ``k`` steps from the measured past.

**A network is one module** (plus its recipe ``configs/train/KIND.yaml``): a subclass
with a ``kind``, a constructor that takes its own model parameters and ``**settings`` and
calls ``self._set_params_from(locals())``, value checks of those parameters (``CHECKS``),
``_build_core(features)`` returning a :class:`~.core.SequenceCore` for a fitted
:class:`~.features.FeatureMap`, and optionally ``_initialise(core, train)`` (least squares,
k-means ...), ``DEFAULTS`` (where its settings' defaults differ) and ``MODEL_PARTS`` (settings
parts of its own, flat keys like the shared ones: the hybrid's physics).  Everything else is
composed from small parts: :mod:`.params` (hyper-parameter API), :mod:`.config`
(training settings), :mod:`.features` (memory filters, RH knots), :mod:`.normalise`,
:mod:`.structure` (structure search), :mod:`.runtime` (threads, seeds), the Lightning
loop :mod:`nnmodel.training` and bundles :mod:`nnmodel.bundle`.
:func:`nnmodel.check_model` checks a class against this contract.
"""
from __future__ import annotations

import inspect
import math
import time
from typing import Any

import numpy as np
import torch

from physics.errors import InputError

from ..batches import GAIN_BLOCKS, GAIN_SE, gain_is_real
from ..data import check_prediction_inputs, check_records, rh_range, split_index
from ..startup import start_samples
from .config import TrainingConfig
from .core import SequenceCore
from .features import FeatureMap, InputFeatures
from . import crossval
from .normalise import Normalized, Seq
from .params import PartField, check_values
from .runtime import seed_all, torch_threads
from .structure import StructureSearch, select_structure

__all__ = ["NeuralModel", "NotFittedError", "PARTS", "SequenceCore"]

#: The settings parts every model composes (each a dataclass of flat hyper-parameters).
PARTS = (TrainingConfig, InputFeatures, StructureSearch)
#: Samples per piece of a free run (bounds the activations held at once on long records).
SIM_CHUNK = 1 << 16
#: Samples per piece whose input channels (memory filters) are computed at once in a free run.
PIECE = 1 << 20


class NotFittedError(InputError):
    """The model was used before :meth:`NeuralModel.fit` (or loading)."""


class NeuralModel:
    """Base class of the networks (see the module docstring for the contract)."""

    #: registry name ("ff", "rbf", ...), set by subclasses
    kind = "base"
    #: trained by ``train_compare`` / ``eap train-compare`` when no models are named
    #: (:func:`nnmodel.models.default_kinds`)
    IN_DEFAULT_SET: bool = False
    #: True for a grey box that starts from a physics model: ``train-compare`` hands it the
    #: dataset's device (or ``--physics``) as its ``device`` setting
    NEEDS_PHYSICS: bool = False
    #: value checks of the model's own parameters: name -> check(value) -> error text or None
    CHECKS: dict = {}
    #: where this model's settings defaults differ from the parts' (e.g. {"lr": 2e-3})
    DEFAULTS: dict = {}
    #: overrides that turn a candidate structure into a cheap stand-in for scoring it (e.g.
    #: the linear least-squares start of a network); None: candidates are fitted in full
    SELECTION_PROXY: dict | None = None
    #: small settings with which :func:`nnmodel.check_model` fits this model in seconds
    CHECK_PARAMS: dict = {}
    #: extra bundle-card entries this model writes (:meth:`_card_extra`) and reads back
    CARD_KEYS: tuple[str, ...] = ()
    #: settings parts of this model alone (each a :class:`~.params.Part` of flat
    #: hyper-parameters, listed before the constructor's own: e.g. the hybrid's physics)
    MODEL_PARTS: tuple = ()

    _LEARNED = ("net_", "features_", "inputs_", "fs_", "rh_range_", "n_init_", "fit_time_", "history_",
                "training_summary_", "structure_search_", "init_report_", "reference_start_", "cross_validation_")

    # ------------------------------------------------------------------ hyper-parameters
    @classmethod
    def _model_params(cls) -> dict:
        """The constructor's own (model) parameters with their defaults."""
        sig = inspect.signature(cls.__init__)
        return {k: p.default for k, p in sig.parameters.items()
                if k != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD}

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        for part in cls.__dict__.get("MODEL_PARTS", ()):    # model.device -> model.<part ATTR>.device
            for name in part.names():
                setattr(cls, name, PartField(part.ATTR, name))

    @classmethod
    def _parts(cls) -> tuple:
        """The settings parts this model composes: its own, then the shared :data:`PARTS`."""
        return tuple(cls.MODEL_PARTS) + PARTS

    @classmethod
    def param_names(cls) -> list[str]:
        """Every hyper-parameter: the model's own parts' fields, its constructor's, then the
        shared settings parts' fields."""
        return ([n for part in cls.MODEL_PARTS for n in part.names()] + list(cls._model_params())
                + [n for part in PARTS for n in part.names()])

    @classmethod
    def default_params(cls) -> dict:
        out = {}
        for part in cls.MODEL_PARTS:
            out.update(part.build(cls.kind, cls.DEFAULTS, {}).values())
        out.update(cls._model_params())
        for part in PARTS:
            out.update(part.build(cls.kind, cls.DEFAULTS, {}).values())
        return out

    @classmethod
    def card_keys(cls) -> tuple[str, ...]:
        """Bundle-card entries besides the standard ones that :meth:`restore` reads."""
        return ("rh_knots_pct", "memory_range_s", "linear_start", "structure_search",
                "reference_start", "cross_validation") + tuple(cls.CARD_KEYS)

    def get_params(self) -> dict:
        return {k: getattr(self, k) for k in self.param_names()}

    def _set_params_from(self, local_vars: dict) -> None:
        """Store the ``__init__`` arguments — the model's own as attributes, the settings
        given as ``**settings`` in their parts — and validate them (subclasses call
        ``self._set_params_from(locals())`` at the end of ``__init__``)."""
        given = dict(local_vars.get("settings") or {})
        unknown = sorted(set(given) - {n for part in self._parts() for n in part.names()})
        if unknown:
            raise InputError(f"unknown hyper-parameter(s) {unknown} for model {self.kind!r}")
        for part in self._parts():
            self.__dict__[part.ATTR] = part.build(self.kind, self.DEFAULTS, given)
        for k in self._model_params():
            setattr(self, k, local_vars[k])
        self._validate()

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
            checks.update(klass.__dict__.get("CHECKS", {}))
        for part in self.MODEL_PARTS:
            self.__dict__[part.ATTR].validate(self.kind)
        check_values(self.kind, {k: getattr(self, k) for k in self._model_params()}, checks)
        for part in PARTS:
            self.__dict__[part.ATTR].validate(self.kind)

    def __repr__(self) -> str:
        defaults = self.default_params()
        diff = {k: v for k, v in self.get_params().items() if defaults.get(k) != v}
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in diff.items())})"

    # ------------------------------------------------------------------ what a network defines
    def _build_core(self, features: FeatureMap) -> SequenceCore:
        raise NotImplementedError

    def _initialise(self, core: SequenceCore, train: list[Seq]) -> None:
        """Non-gradient initialisation (least squares, k-means); default: nothing."""

    def _prepare_channels(self, records) -> None:
        """Hook before the training records are normalised: sets the scale of the memory
        filters (the hybrid also runs its physics here, once per record)."""
        self.features_.set_scale(records, self.net_)

    def _release_channels(self) -> None:
        """Hook after the training records are normalised (drop caches)."""

    def _channels(self, u: np.ndarray, rh: np.ndarray | None,
                  y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Normalised core channels of a record in physical units (:meth:`FeatureMap.channels`;
        ``y``: measured outputs from the record's start, when known)."""
        return self.features_.channels(u, rh, self.net_, y)

    def _card_extra(self) -> dict:
        """Model-specific bundle-card entries (named in :attr:`CARD_KEYS`)."""
        return {}

    def _restore_extra(self, card_extra: dict) -> None:
        """Read back :meth:`_card_extra` before the core is rebuilt."""

    # ------------------------------------------------------------------ fitting
    def fit(self, train, val=None) -> "NeuralModel":
        """Train on ``train`` records (early stopping on the free-run error of ``val``)."""
        return self._fit_checked(train, val, decide=True)

    def fit_fold(self, train, val=None) -> "NeuralModel":
        """Train on one cross-validation fold (:mod:`.crossval`): as :meth:`fit` on one split,
        but a residual core keeps its trained correction whatever the fold's validation says —
        the folds together judge it, so one fold must not drop it on its own."""
        return self._fit_checked(train, val, decide=False)

    def _fit_checked(self, train, val, decide: bool) -> "NeuralModel":
        self._validate()
        train = check_records(train, "training")
        if val is not None:
            val = check_records(val, "validation")
            check_records(train + val, "training + validation")
        use_rh = self.features.uses_rh(self.kind, train[0].rh is not None)
        seed_all(self.seed)
        try:
            if self.search.active:     # each candidate is fitted (and cross-validated) in full
                select_structure(self, train, val)
            else:
                folds = crossval.plan(self, train, val) if decide else None
                self._fit(train, val, train[0].fs, use_rh, decide=decide and folds is None)
                if folds is not None:
                    self.cross_validation_ = crossval.cross_validate(self, train, val, folds)
        except BaseException:
            for attr in self._LEARNED:  # never leave a half-trained model behind
                self.__dict__.pop(attr, None)
            raise
        return self

    def _fit(self, train, val, fs, use_rh, decide: bool = True) -> None:
        """Fit on one split; ``decide``: whether the validation data decide here if a residual
        core keeps its trained correction (False: cross-validation decides, :mod:`.crossval`)."""
        from ..training import fit_core  # Lightning is imported only when training

        with torch_threads(self.num_threads):
            self.features_ = self.features.fit(self.kind, fs, train, use_rh, val, self.val_fraction)
            core = self._build_core(self.features_)
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
            net = Normalized(core, self.features_.n_mem)
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
            reference = self._reference()
            # a correction not trained after its start: dropping it there is the final decision, which a
            # cross-validation fold leaves to the folds together (fit_fold); trained, the start's reset is
            # part of the recipe in every fold
            start = keep_if_better(core, va, reference, decide=decide or self.max_epochs > 0) if reference else None
            history: list[dict] = []
            if self.max_epochs > 0:
                history, self.training_summary_ = fit_core(core, tr, va, self.training)
            if start is not None:
                self.reference_start_ = {"reference": reference, "start": start,
                                         "end": keep_if_better(core, va, reference, decide=decide)}
            self.fit_time_ = time.perf_counter() - t0
            self.history_ = history
            core.eval()

    def _reference(self) -> str | None:
        """What a residual core adds its correction to, which the model must never be worse
        than on validation (:func:`keep_if_better`): ``"linear"`` with a linear start, else
        None (the hybrid: ``"physics"``)."""
        return "linear" if self.features_.linear is not None else None

    def _norm_record(self, r) -> Seq:
        U, R = self._channels(r.u, r.rh if "rh" in self.inputs_ else None, r.y)
        return Seq(U, self.net_.norm("y", r.y), R)

    @property
    def rh_knots_(self) -> list:
        """RH knots (%) of the fitted model (the training levels for ``rh_knots: auto``)."""
        return self.__dict__["features_"].knots if "features_" in self.__dict__ else _missing("rh_knots_")

    @property
    def memory_range_(self) -> tuple | None:
        """Memory time constants (s) used: (fastest, slowest), None without filters."""
        return self.__dict__["features_"].memory_range if "features_" in self.__dict__ else _missing("memory_range_")

    # ------------------------------------------------------------------ inference
    def _check_fitted(self) -> None:
        if "net_" not in self.__dict__:
            raise NotFittedError(f"model {self.kind!r} is not trained yet: call fit() or load a bundle")

    @property
    def uses_rh(self) -> bool:
        self._check_fitted()
        return "rh" in self.inputs_

    def _prepare(self, u, rh, y=None, y_name="y"):
        """Validated inputs in physical units: (u, rh or None, y or None) arrays."""
        self._check_fitted()
        return check_prediction_inputs(u, rh, y, y_name, self.rh_range_ if self.uses_rh else None)

    def _padded(self, u, rh, y, pad: int):
        """Normalised channels (see :meth:`_channels`) with ``pad`` samples in front: with a
        measured output ``y``, held at the first samples (the steady state of the first input
        and output, so the memory filters start there whatever the record's start); without
        one, at rest (0 V, output 0, the first RH), the documented assumption of a free run."""
        up, rhp, yp, yn = self._pad(u, rh, y, pad)
        un, rhn = self._channels(up, rhp, yp)
        return un, rhn, yn

    def _pad(self, u, rh, y, pad: int):
        """(u, rh, y or None when unknown, normalised y) with ``pad`` samples in front, as
        :meth:`_padded` says."""
        known = y is not None and y.size > 0
        up = np.concatenate([np.full(pad, u[0] if known else 0.0), u])
        rhp = None if rh is None else np.concatenate([np.full(pad, rh[0]), rh])
        yp = np.concatenate([np.full(pad, y[0]), y]) if known else None
        yn = None if y is None else np.concatenate([np.full(pad, self.net_.norm("y", float(y[0]) if known else 0.0)),
                                                    self.net_.norm("y", y)])
        return up, rhp, yp, yn

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
        if self.streams and u.size > PIECE:   # a long record: its channels one piece at a time,
            cuts = range(0, u.size, PIECE)    # each piece's output written into the record's
            y_hat, i = np.empty(u.size), 0
            for piece in self.simulate_pieces(((u[a:a + PIECE], None if rh is None else rh[a:a + PIECE])
                                               for a in cuts), y_init):
                y_hat[i:i + piece.size] = piece
                i += piece.size
            return y_hat
        k = self.n_init_
        pad = max(0, k - m)
        un, rhn, yn = self._padded(u, rh, y_init if y_init is not None else np.zeros(0), pad)
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

    @property
    def streams(self) -> bool:
        """True when :meth:`simulate_pieces` applies: the core continues from a state and the
        channels are causal filters of the input (the hybrid's physics channel is not)."""
        return type(self.net_.core).advance is not SequenceCore.advance and \
            type(self)._channels is NeuralModel._channels

    def simulate_pieces(self, pieces, y_init=None):
        """Free run over a record given as consecutive pieces ``(u, rh)`` in physical units,
        yielding the output of each piece: the values :meth:`simulate` gives on the whole
        record (the memory filters and the core's state carry over), with one piece in
        memory at a time.  ``y_init`` as in :meth:`simulate`, shorter than the first piece."""
        if not self.streams:
            raise InputError(f"{type(self).__name__} cannot simulate a record in pieces; use simulate()")
        core, fm, k = self.net_.core, self.features_, self.n_init_
        state = last = None
        with torch.no_grad(), torch_threads(self.num_threads):
            for u, rh in pieces:
                u, rh, y0 = self._prepare(u, rh, y_init if state is None else None, "y_init")
                head, s = np.zeros(0), 0
                if state is None:
                    m = 0 if y0 is None else y0.size
                    if m >= u.size:
                        raise InputError(f"y_init has {m} samples but the first piece only {u.size}; y_init must be "
                                         "shorter than the piece it initialises")
                    pad = max(0, k - m)
                    u, rh, yp, yn = self._pad(u, rh, y0 if y0 is not None else np.zeros(0), pad)
                    head, s = (y0 if m else head), pad + m
                un, rhn, last = fm.channels_continued(u, rh, self.net_, last, yp if state is None else None)
                if state is None:
                    state = core.init_state(self._t(un[None, s - k:s]), self._t(yn[None, s - k:s]),
                                            None if rhn is None else self._t(rhn[None, s - k:s]))
                out = np.empty(un.shape[0] - s)
                for a in range(s, un.shape[0], SIM_CHUNK):
                    b = min(un.shape[0], a + SIM_CHUNK)
                    o, state = core.advance(state, self._t(un[None, a:b]), None if rhn is None else self._t(rhn[None, a:b]))
                    out[a - s:b - s] = o[0].double().numpy()
                yield np.concatenate([head, self.net_.denorm("y", out)])

    def predict(self, u, rh=None, y=None, steps_ahead: int | None = None,
                chunk: int = 4096) -> np.ndarray:
        """SysIdentPy-style prediction.

        ``steps_ahead=None``: free run, from rest without ``y``; with a measured ``y`` as long
        as the input, from its start-up window (:mod:`nnmodel.startup`: its first
        ``max(START_SAMPLES, n_init_)`` samples, returned as given); with a shorter ``y``, from
        all of it.  ``steps_ahead=k``: each output ``y[t]``
        is simulated over ``k`` steps starting from the measured ``y`` up to ``t - k``; the
        first ``k - 1`` outputs, whose start would lie before the record, are simulated from
        the steady state of the first samples (input ``u[0]`` and output ``y[0]`` held before
        the record), so a model without output feedback gives the same values as its free
        run.  ``k = 1`` is one-step-ahead prediction.
        """
        if steps_ahead is None:
            if y is None:
                return self.simulate(u, rh)
            y = np.asarray(y, float)
            return self.simulate(u, rh, y_init=y[:start_samples(self.n_init_)] if y.size >= np.size(u) else y)
        if isinstance(steps_ahead, bool) or not isinstance(steps_ahead, (int, np.integer)) or steps_ahead < 1:
            raise InputError(f"steps_ahead must be None or a positive integer, got {steps_ahead!r}")
        if y is None:
            raise InputError("k-step-ahead prediction needs the measured output y")
        u, rh, y = self._prepare(u, rh, y)
        if y.size != u.size:
            raise InputError(f"y has {y.size} samples but the voltage has {u.size}")
        N, n0 = u.size, self.n_init_
        k = int(min(steps_ahead, N))
        chunk = max(1, min(chunk, (1 << 18) // k))   # a chunk holds chunk × k steps: memory bounded for any k
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

    # ------------------------------------------------------------------ persistence
    def learned_state(self) -> dict[str, Any]:
        """JSON-able learned attributes other than the weights (used by bundles)."""
        self._check_fitted()
        extra = {**self.features.card(self.features_), **self._card_extra()}
        if self.__dict__.get("structure_search_"):
            extra["structure_search"] = self.structure_search_
        if self.__dict__.get("reference_start_"):
            extra["reference_start"] = self.reference_start_
        if self.__dict__.get("cross_validation_"):
            extra["cross_validation"] = self.cross_validation_
        out = {"inputs": list(self.inputs_), "fs": self.fs_,
               "rh_range": None if self.rh_range_ is None else list(self.rh_range_),
               "n_init": self.n_init_, "fit_time_s": self.__dict__.get("fit_time_")}
        if extra:
            out["card_extra"] = extra
        return out

    def restore(self, learned: dict, state_dict: dict | None) -> "NeuralModel":
        """Rebuild the network from ``learned_state()`` and load its weights (``None``: the
        shapes only, e.g. on torch's meta device to size a network before loading it)."""
        self._validate()
        inputs = list(learned["inputs"])
        if inputs not in (["voltage"], ["voltage", "rh"]):
            raise InputError(f"unsupported model inputs {inputs}")
        extra = learned.get("card_extra") or {}
        self._restore_extra(extra)
        features = self.features.restore(self.kind, learned["fs"], "rh" in inputs, extra)
        core = self._build_core(features)
        net = Normalized(core, features.n_mem)
        missing, unexpected = net.load_state_dict(state_dict, strict=False) if state_dict is not None else ((), ())
        if missing or unexpected:
            raise InputError(f"saved weights do not match a {self.kind!r} model with these "
                             f"hyper-parameters (missing {missing}, unexpected {unexpected})")
        net.eval()
        self.features_ = features
        self.net_ = net
        self.inputs_ = inputs
        self.fs_ = float(learned["fs"])
        self.rh_range_ = None if learned.get("rh_range") is None else tuple(learned["rh_range"])
        self.n_init_ = int(core.n_init)
        self.fit_time_ = learned.get("fit_time_s")
        self.history_ = []
        if extra.get("structure_search"):
            self.structure_search_ = extra["structure_search"]
        if extra.get("cross_validation"):
            self.cross_validation_ = extra["cross_validation"]
        if extra.get("reference_start"):
            self.reference_start_ = extra["reference_start"]
        return self


def keep_if_better(core, val, reference: str = "linear", decide: bool = True) -> dict:
    """A residual core (a linear start, the hybrid's physics) starts and ends no worse than
    its ``reference`` alone on validation: its correction (initialised by least squares, or
    trained) is kept only when it lowers the free-run squared error of ``val`` (normalised
    records) by more than its uncertainty, :data:`GAIN_SE` standard errors of the gain by
    batch means (:func:`nnmodel.batches.paired_gain`, :data:`GAIN_BLOCKS` blocks, none shorter
    than the errors' correlation time); with fewer than 2 such blocks the uncertainty is
    unknown and a lower error suffices.  A gain within its uncertainty leaves the reference
    (``core.zero_correction()``).  ``decide=False`` only measures (the correction is kept and
    the caller decides, e.g. by cross-validation)."""
    import copy

    from ..batches import free_run_errors, paired_gain
    if not val:
        return {"kept": "network", "reason": "no validation data"}
    e_net = free_run_errors(core, val)
    ref = copy.deepcopy(core)
    ref.zero_correction()
    e_ref = free_run_errors(ref, val)
    gain, se, blocks = paired_gain(e_ref, e_net, GAIN_BLOCKS)
    n = max(1, sum(e.size for e in e_net))
    r_net, r_ref = (min(float(np.sqrt(sum(float(x.sum()) for x in e) / n)), 1e6) for e in (e_net, e_ref))
    kept = "network" if not decide or gain_is_real(r_net, r_ref, gain, se) else reference
    out = {"kept": kept, "validation_nrmse_network": r_net, "validation_nrmse_reference": r_ref,
           "validation_gain": gain, "validation_gain_se": se if math.isfinite(se) else None,
           "validation_blocks": blocks}
    if kept == reference:
        core.load_state_dict(ref.state_dict())
        if r_net < r_ref:
            out["reason"] = (f"its validation gain is within its uncertainty (one standard error over {blocks} "
                             "independent blocks of validation data: too short or too few records to tell it "
                             "from chance)")
    return out


def _missing(name: str):
    raise AttributeError(f"{name} exists only after fit() or loading a bundle")


# flat hyper-parameters of the parts read and write through to them (model.lr -> model.training.lr)
for _part in PARTS:
    for _name in _part.names():
        setattr(NeuralModel, _name, PartField(_part.ATTR, _name))
