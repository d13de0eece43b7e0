"""``check_model``: the network contract as a runnable check (like scikit-learn's ``check_estimator``).

The model contract test runs it on every registered network; a third party runs it on
theirs before :func:`nnmodel.models.register`::

    from nnmodel import check_model
    check_model(MyNet)            # raises ContractError naming the failing check

Each check builds the class with its :attr:`~NeuralModel.CHECK_PARAMS` (small settings, so
the whole check takes seconds) and fits it on a small synthetic plant: a first-order lag
behind a tanh, at two RH levels with an RH-dependent gain.
"""
from __future__ import annotations

import inspect
import tempfile
import warnings
from pathlib import Path

import numpy as np

from physics.errors import InputError

__all__ = ["check_model", "model_checks", "ContractError", "CHECKS"]

FS = 50.0


class ContractError(AssertionError):
    """A network class breaks the contract; the message names the check."""


def _records(n: int = 600):
    from scipy.signal import lfilter

    from ..data import Experiment
    rng = np.random.default_rng(0)
    out = []
    for rh in (40.0, 80.0):
        u = np.convolve(rng.normal(size=n), np.ones(4) / 4, "same")
        y = lfilter([0.05], [1, -0.95], np.tanh(u)) * 1e-3 * (1 + rh / 100)
        out.append(Experiment(u=u, y=y, rh=np.full(u.size, rh), fs=FS, name=f"rh{rh:g}"))
    return out


def _expect(ok: bool, check: str, message: str) -> None:
    if not ok:
        raise ContractError(f"{check}: {message}")


def _raises(fn, exc, check: str, what: str, match: str | None = None) -> None:
    try:
        fn()
    except exc as err:
        _expect(match is None or match in str(err), check, f"{what} raised {err!r}, expected a message with {match!r}")
        return
    except Exception as err:  # noqa: BLE001 - report what came instead
        raise ContractError(f"{check}: {what} raised {type(err).__name__}: {err}, expected {exc.__name__}") from None
    raise ContractError(f"{check}: {what} did not raise {exc.__name__}")


def _params(cls, params):
    return {"progress_bar": False, "seed": 3, **cls.CHECK_PARAMS, **(params or {})}


# ---------------------------------------------------------------------- the checks
def check_class(cls, params=None, ctx=None) -> None:
    """A NeuralModel subclass with a kind; the constructor takes model parameters with
    defaults and ``**settings``, none of them a setting of the shared parts."""
    from .base import PARTS, NeuralModel
    _expect(isinstance(cls, type) and issubclass(cls, NeuralModel), "class", f"{cls!r} is not a NeuralModel subclass")
    _expect(isinstance(cls.kind, str) and cls.kind.isidentifier() and cls.kind != "base", "class",
            f"kind must be a name such as 'tcn', got {cls.kind!r}")
    sig = inspect.signature(cls.__init__)
    _expect(any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values()), "class",
            "__init__ must take **settings (training, features and structure settings go to their parts)")
    nodefault = [k for k, p in sig.parameters.items()
                 if k != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD and p.default is inspect.Parameter.empty]
    _expect(not nodefault, "class", f"constructor parameters without a default: {nodefault}")
    shared = set(cls._model_params()) & {n for part in PARTS for n in part.names()}
    _expect(not shared, "class", f"constructor repeats shared settings {sorted(shared)}; take them through **settings")


def check_params(cls, params=None, ctx=None) -> None:
    """Hyper-parameters follow the estimator conventions: flat get/set, defaults, settings
    in their parts, unknown names and invalid values refused, nothing learned before fit."""
    from .base import NotFittedError
    from .config import TrainingConfig
    m = cls()
    names = cls.param_names()
    _expect(len(set(names)) == len(names), "params", f"a hyper-parameter is declared twice: {names}")
    _expect(set(m.get_params()) == set(names) == set(cls.default_params()), "params",
            "get_params(), param_names() and default_params() must name the same hyper-parameters")
    _expect(m.get_params() == cls.default_params(), "params",
            "a default model's get_params() differs from default_params()")
    again = cls(**m.get_params())
    _expect(again.get_params() == m.get_params(), "params", "cls(**model.get_params()) does not rebuild the same model")
    t = cls(max_epochs=3, lr=5e-4)
    _expect(isinstance(t.training, TrainingConfig) and t.training.max_epochs == 3 and t.lr == 5e-4, "params",
            "training settings given as keywords must land in model.training and read back as attributes")
    t.set_params(patience=4)
    _expect(t.training.patience == 4 and t.get_params()["patience"] == 4, "params", "set_params() must reach model.training")
    _raises(lambda: cls(max_epochs=-1), InputError, "params", "cls(max_epochs=-1)", "max_epochs")
    _raises(lambda: cls(epochs_typo=3), InputError, "params", "an unknown keyword", "unknown hyper-parameter")
    _raises(lambda: m.set_params(epochs_typo=3), InputError, "params", "set_params with an unknown name",
            "unknown hyper-parameter")
    _expect(not [k for k in vars(m) if k.endswith("_")], "params", "learned attributes (ending in _) exist before fit")
    _raises(lambda: m.simulate(np.zeros(10)), NotFittedError, "params", "simulate() before fit()")


def check_fit_predict(cls, params=None, ctx=None) -> None:
    """Fit on the synthetic plant; free run, one-step and k-step predictions have the
    input's shape and are finite; y_init is returned as given; k-step uses only the past."""
    recs = _records()
    m = cls(**_params(cls, params)).fit(recs[:1], recs[1:])
    ctx["model"] = m
    u, y = recs[0].u, recs[0].y
    free = m.simulate(u, 40.0)
    _expect(free.shape == u.shape and bool(np.all(np.isfinite(free))), "fit_predict",
            f"free run has shape {free.shape} or non-finite values")
    ctx["free"] = free
    one = m.predict(u, 40.0, y=y, steps_ahead=1)
    _expect(one.shape == u.shape and bool(np.all(np.isfinite(one))), "fit_predict", "one-step prediction is not finite")
    k0 = m.n_init_ + 5
    init = m.simulate(u, 40.0, y_init=y[:k0])
    _expect(np.array_equal(init[:k0], y[:k0]), "fit_predict", "simulate(y_init=...) must return y_init unchanged")
    t0, k = 300, 4
    y_bad = y.copy()
    y_bad[t0:] += 5 * np.std(y)
    p, p_bad = m.predict(u, 40.0, y=y, steps_ahead=k), m.predict(u, 40.0, y=y_bad, steps_ahead=k)
    _expect(np.allclose(p[:t0 + k - 1], p_bad[:t0 + k - 1], rtol=0, atol=1e-12), "fit_predict",
            "a k-step prediction used measurements from its own future")


def check_inputs_refused(cls, params=None, ctx=None) -> None:
    """NaN inputs and an RH outside 0-100 % are refused with an InputError."""
    m, u = ctx["model"], _records()[0].u
    bad = u.copy()
    bad[10] = np.nan
    _raises(lambda: m.simulate(bad, 40.0), InputError, "inputs", "a NaN in the voltage")
    if m.uses_rh:
        _raises(lambda: m.simulate(u, 150.0), InputError, "inputs", "RH 150 %")


def check_bundle(cls, params=None, ctx=None) -> None:
    """A saved bundle loads (no pickled code) and predicts exactly what the model did."""
    from ..bundle import load, save
    from . import MODELS
    m, u = ctx["model"], _records()[0].u
    added = MODELS.get(cls.kind) is None
    if added:          # a bundle names its model by kind: an unregistered class is added for the check
        MODELS[cls.kind] = cls
    try:
        with tempfile.TemporaryDirectory() as tmp:
            b = load(save(m, Path(tmp) / m.kind))
            got = b.predict(u, rh=40.0, fs=FS)
    finally:
        if added:
            MODELS.pop(cls.kind)
    _expect(np.allclose(got, ctx["free"], rtol=1e-6, atol=1e-12), "bundle",
            f"the loaded bundle predicts differently (max difference {np.max(np.abs(got - ctx['free'])):.3g})")


def check_chunks(cls, params=None, ctx=None) -> None:
    """A free run in pieces (long records) equals the run in one piece."""
    from . import base
    m, u = ctx["model"], _records()[0].u
    old = base.SIM_CHUNK
    base.SIM_CHUNK = 37
    try:
        pieces = m.simulate(u, 40.0)
    finally:
        base.SIM_CHUNK = old
    whole = ctx["free"]
    _expect(np.max(np.abs(pieces - whole)) <= 1e-5 * np.max(np.abs(whole)) + 1e-15, "chunks",
            "simulating in pieces (advance) differs from one piece")


def check_seeded(cls, params=None, ctx=None) -> None:
    """The same seed gives the same model (identical free run)."""
    recs = _records()
    again = cls(**_params(cls, params)).fit(recs[:1], recs[1:])
    _expect(np.array_equal(again.simulate(recs[0].u, 40.0), ctx["free"]), "seeded",
            "two fits with the same seed give different models")


#: The checks in the order they run (each name is the prefix of its ContractError).
CHECKS = (check_class, check_params, check_fit_predict, check_inputs_refused, check_bundle, check_chunks, check_seeded)


#: checks that read the model fitted by :func:`check_fit_predict`
_NEEDS_FIT = ("check_inputs_refused", "check_bundle", "check_chunks", "check_seeded")


def model_checks(cls, params: dict | None = None) -> list[tuple[str, object]]:
    """``[(name, run), ...]``: every check of the network contract as its own callable, in
    order, sharing one fitted model — one test item per check, as scikit-learn's
    ``parametrize_with_checks`` gives.  ``run()`` raises :class:`ContractError` when its check
    fails; a check that needs the fitted model fits it first when no earlier check did."""
    ctx: dict = {}

    def runner(check):
        def run():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                if check.__name__ in _NEEDS_FIT and "free" not in ctx:
                    check_fit_predict(cls, params, ctx)
                check(cls, params, ctx)
        return run

    return [(check.__name__.removeprefix("check_"), runner(check)) for check in CHECKS]


def check_model(cls, params: dict | None = None) -> list[str]:
    """Run every check of the network contract on ``cls`` (with its ``CHECK_PARAMS``,
    updated by ``params``); returns the names of the checks passed, or raises
    :class:`ContractError` naming every check that failed (each message starts with its check)."""
    done, failed = [], []
    for name, run in model_checks(cls, params):
        try:
            run()
        except ContractError as err:
            failed.append(str(err))
        else:
            done.append(f"check_{name}")
    if failed:
        raise ContractError("; ".join(failed))
    return done
