"""Saved model bundles: a folder with the weights (no pickled code) and a JSON card.

::

    MODEL/
      card.json     model type, hyper-parameters, inputs and units, sampling rate, RH range
                    seen in training, dataset hash, metrics, parameter count, versions
      weights.pt    the torch ``state_dict`` (tensors only; read with ``weights_only=True``)

:func:`save` writes the folder atomically (a temporary folder renamed into place).
:func:`load` returns a :class:`Bundle` whose :meth:`Bundle.predict` takes physical units,
refuses a sampling rate other than the training rate unless asked to resample, warns
when the humidity is outside the range seen in training, and rejects NaNs and bad shapes.
Loading never unpickles arbitrary objects: the card is JSON, the weights are read with
``torch.load(..., weights_only=True)`` and must be a flat mapping of tensors.
"""
from __future__ import annotations

import datetime
import json
import math
import os
import re
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import torch

from physics._version import __version__
from physics.errors import InputError, arg
from physics.io.fileio import jsonable, load_json, sha256_file

from .data import check_fs, check_voltage
from .models import MODELS, load_plugins
from .models.base import NeuralModel
from .models.params import MAX_PARAMETERS

__all__ = ["save", "load", "Bundle", "resample", "FORMAT", "FORMAT_VERSION"]

FORMAT = "eap-model-bundle"
FORMAT_VERSION = 1
WEIGHTS = "weights.pt"
CARD = "card.json"
#: relative sampling-rate difference accepted as "the same rate" (timestamps in files are
#: rounded; 0.01 % changes no dynamics that matter)
FS_RTOL = 1e-4

_UNITS = {"voltage": "V", "rh": "%RH"}


def save(model: NeuralModel, path: str | os.PathLike, *, dataset_hash: str | None = None,
         metrics: dict | None = None, output: tuple[str, str] = ("deflection", "m"),
         notes: str = "", overwrite: bool = False, extra: dict | None = None) -> Path:
    """Save a trained model as the folder ``path`` (atomically).

    ``output`` names the output quantity and its unit (default tip deflection in m; the
    Silverbox benchmark saves ``("V2", "V")``).  An existing folder is replaced only with
    ``overwrite=True``.  ``extra``: further card entries (e.g. ``tuning``, the trials of
    ``train-compare --tune``), which may not replace a standard one.
    """
    model._check_fitted()
    target = Path(path)
    if target.exists() and not overwrite:
        raise InputError(f"{target} already exists; choose another folder or pass overwrite=True")
    if target.exists() and not (target / CARD).is_file():
        raise InputError(f"{target} exists and is not a model bundle; refusing to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    learned = model.learned_state()
    state = {k: v.detach().cpu().clone() for k, v in model.net_.state_dict().items()}
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent))
    try:
        torch.save(state, tmp / WEIGHTS)
        stats = {n: dict(zip(("mean", "std"), model.net_.stat(n))) for n in ("u", "y", "rh")}
        card = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "model": model.kind,
            "class": f"{type(model).__module__}.{type(model).__name__}",
            "hyper_parameters": model.get_params(),
            "inputs": [{"name": n, "unit": _UNITS[n]} for n in learned["inputs"]],
            "output": {"name": output[0], "unit": output[1]},
            "fs_hz": learned["fs"],
            "rh_range_pct": learned["rh_range"],
            "n_init": learned["n_init"],
            "n_parameters": model.n_parameters,
            "normalisation": {"voltage": stats["u"], "output": stats["y"],
                              **({"rh": stats["rh"]} if "rh" in learned["inputs"] else {})},
            "training": _training_card(model, learned),
            "dataset_hash": dataset_hash,
            "metrics": jsonable(metrics) if metrics else {},
            "notes": notes,
            "package_version": __version__,
            "torch_version": torch.__version__,
            "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "weights": {"file": WEIGHTS, "sha256": sha256_file(tmp / WEIGHTS), "format": "torch state_dict"},
        }
        for key, value in {**(learned.get("card_extra") or {}), **(extra or {})}.items():  # e.g. the hybrid's physics
            if key in card:
                raise InputError(f"model {model.kind!r}: card entry {key!r} would overwrite a standard field")
            card[key] = value
        (tmp / CARD).write_text(json.dumps(jsonable(card), indent=2, allow_nan=False) + "\n",
                                encoding="utf-8")
        if target.exists():
            old = target.with_name(f".{target.name}.old-{os.getpid()}")
            os.replace(target, old)
            os.replace(tmp, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, target)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return target


def _read_card(folder: Path) -> dict:
    cp = folder / CARD
    if not cp.is_file():
        raise InputError(f"{folder} is not a model bundle (no {CARD})")
    if cp.is_symlink():
        raise InputError(f"{cp} is a symbolic link; a bundle holds its own files (a link could lead outside it)")
    card = load_json(cp, "bundle card")
    if not isinstance(card, dict) or card.get("format") != FORMAT:
        raise InputError(f"{cp}: not an {FORMAT} card")
    if card.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{cp}: bundle format version {card.get('format_version')} is not "
                         f"supported (this package reads version {FORMAT_VERSION})")
    if card.get("model") not in MODELS:
        load_plugins()
    if card.get("model") not in MODELS:
        raise InputError(f"{cp}: unknown model type {card.get('model')!r}; known: {', '.join(MODELS)}")
    inputs = card.get("inputs")
    if not isinstance(inputs, list) or not all(isinstance(i, dict) and isinstance(i.get("name"), str)
                                               for i in inputs):
        raise InputError(f"{cp}: 'inputs' must be a list of {{name, unit}} entries, got {inputs!r}")
    fs = card.get("fs_hz")
    if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not math.isfinite(fs) or fs <= 0:
        raise InputError(f"{cp}: 'fs_hz' must be a positive sampling rate in Hz, got {fs!r}")
    for key in ("weights", "training", "output", "normalisation"):
        if card.get(key) is not None and not isinstance(card[key], dict):
            raise InputError(f"{cp}: {key!r} must be a mapping, got {card[key]!r}")
    for name, st in (card.get("normalisation") or {}).items():
        std = st.get("std") if isinstance(st, dict) else None
        if isinstance(std, bool) or not isinstance(std, (int, float)) or not (math.isfinite(std) and std > 0):
            raise InputError(f"{cp}: normalisation.{name}.std {std!r} must be a positive number (a scale of "
                             f"{name}); the card is damaged — re-save the model")
    return card


def _training_card(model, learned: dict) -> dict:
    """Budget actually used: epochs run, and whether the wall-clock guard ended training."""
    hist = list(getattr(model, "history_", []) or [])
    summary = getattr(model, "training_summary_", None) or {}
    return {"fit_time_s": learned["fit_time_s"],
            "epochs": summary.get("epochs_run", len([r for r in hist if r.get("epoch", 0) >= 0])),
            "max_epochs": summary.get("max_epochs"), "max_time_s": summary.get("max_time_s"),
            "time_guard_fired": bool(summary.get("time_guard_fired", False)),
            "batch_size": summary.get("batch_size"), "training_windows": summary.get("training_windows"),
            "device": summary.get("device")}


def load(path: str | os.PathLike) -> "Bundle":
    """Load a bundle saved by :func:`save` (never unpickles arbitrary code)."""
    folder = Path(path)
    if not folder.is_dir():
        raise InputError(f"model bundle {folder} not found (expected a folder with {CARD} and {WEIGHTS})")
    card = _read_card(folder)
    weights = card.get("weights") or {}
    if not isinstance(weights.get("file", WEIGHTS), str):
        raise InputError(f"{folder / CARD}: weights.file must be a file name, got {weights.get('file')!r}")
    wfile = folder / weights.get("file", WEIGHTS)
    if wfile.is_symlink() or wfile.parent.resolve() != folder.resolve() or not wfile.is_file():
        raise InputError(f"{folder}: weights file {wfile.name} missing, a symbolic link or outside the bundle; a "
                         "bundle holds its own files")
    expected = weights.get("sha256")
    if not (isinstance(expected, str) and re.fullmatch(r"[0-9a-f]{64}", expected)):
        raise InputError(f"{folder / CARD}: weights.sha256 {expected!r} is not a SHA-256; without it the weights "
                         "cannot be checked — re-save the model with eap")
    cls = MODELS[card["model"]]
    hp = _card_hyper_parameters(card, cls, folder / CARD)
    learned = {"inputs": [i["name"] for i in card["inputs"]], "fs": card["fs_hz"],
               "rh_range": card.get("rh_range_pct"), "n_init": card.get("n_init"),
               "fit_time_s": (card.get("training") or {}).get("fit_time_s"),
               "card_extra": {k: card[k] for k in cls.card_keys() if k in card}}
    _check_size(cls, hp, learned, wfile, folder)
    if sha256_file(wfile) != expected:
        raise InputError(f"{wfile}: content does not match the SHA-256 in {CARD} (corrupt or altered)")
    try:
        state = torch.load(wfile, map_location="cpu", weights_only=True)
    except Exception:  # UnpicklingError for anything but plain tensors and containers
        raise InputError(f"{wfile}: refused to load — the file holds more than plain tensors (it may have "
                         "been altered); only weights saved by eap are accepted, retrain or re-save the "
                         "model") from None
    if not isinstance(state, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                              for k, v in state.items()):
        raise InputError(f"{wfile}: expected a flat mapping of parameter names to tensors")
    bad = [k for k, v in state.items() if v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if bad:
        raise InputError(f"{wfile}: weights {bad[:3]} contain NaN or infinite values; the bundle is corrupt")
    bad = [k for k, v in state.items() if k.endswith("_std") and v.is_floating_point() and not bool((v > 0).all())]
    if bad:
        raise InputError(f"{wfile}: normalisation {bad[:3]} holds a standard deviation ≤ 0; the bundle is corrupt")
    try:
        with torch.device("meta"), warnings.catch_warnings():  # shapes only: nothing is allocated
            warnings.simplefilter("ignore", UserWarning)  # "copying ... to a meta parameter is a no-op"
            cls(**hp).restore(learned, state)
        model = cls(**hp).restore(learned, state)
    except InputError as exc:
        raise InputError(f"{folder}: {exc}") from None
    except (RuntimeError, KeyError, ValueError, TypeError, IndexError) as exc:
        sizes = ", ".join(f"{k}={v}" for k, v in hp.items() if (k in cls._model_params() or k == "memory_filters")
                          and isinstance(v, int) and not isinstance(v, bool))
        raise InputError(f"{folder}: the weights do not match a {card['model']!r} model with the card's sizes "
                         f"{sizes} ({' '.join(str(exc).split())[:300]})") from None
    return Bundle(model, card, folder)


def _check_size(cls, hp: dict, learned: dict, wfile: Path, folder: Path) -> None:
    """Refuse a card describing a network too large to hold, before anything is allocated:
    every size parameter within its cap (the model's value checks), the network built on
    torch's meta device (shapes only) within :data:`MAX_PARAMETERS`, and a weights file no
    larger than such a network needs."""
    try:
        model = cls(**hp)
        with torch.device("meta"), warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            n = model.restore(learned, None).n_parameters
    except InputError as exc:
        raise InputError(f"{folder}: {exc}") from None
    except (RuntimeError, KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(f"{folder}: the card does not describe a {cls.kind!r} model "
                         f"({' '.join(str(exc).split())[:300]})") from None
    if n > MAX_PARAMETERS:
        raise InputError(f"{folder}: the card describes a {cls.kind!r} network of {n:,} parameters, more than "
                         f"the {MAX_PARAMETERS:,} a bundle may hold; refused before loading")
    limit = 16 * n + (16 << 20)     # float32 weights, float64 buffers, and the container
    if wfile.stat().st_size > limit:
        raise InputError(f"{wfile}: {wfile.stat().st_size:,} bytes, more than a network of {n:,} parameters "
                         "needs; refused before loading")


def _card_hyper_parameters(card: dict, cls, where: Path) -> dict:
    """The card's hyper-parameters, checked against the model's defaults (names, types)."""
    hp = card.get("hyper_parameters") or {}
    if not isinstance(hp, dict):
        raise InputError(f"{where}: hyper_parameters must be a mapping, got {type(hp).__name__}")
    defaults = cls.default_params()
    unknown = sorted(set(hp) - set(defaults))
    if unknown:
        raise InputError(f"{where}: unknown hyper-parameter(s) {unknown} for model {card['model']!r}")
    for key, value in hp.items():
        d = defaults[key]
        if isinstance(d, bool) or d is None or isinstance(d, str):
            continue
        if isinstance(d, (int, float)) and value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
                or (isinstance(d, int) and value != int(value))):
            raise InputError(f"{where}: hyper-parameter {key}={value!r} must be a finite "
                             f"{'whole number' if isinstance(d, int) else 'number'} like the default {d!r}")
    return dict(hp)


# ---------------------------------------------------------------------- resampling
def resample(x: np.ndarray, fs_from: float, fs_to: float, n_out: int | None = None) -> np.ndarray:
    """Resample a uniformly sampled signal (starting at t = 0) from ``fs_from`` to ``fs_to``:
    zero-phase anti-alias low-pass when the rate drops, then linear interpolation."""
    from scipy import signal

    x = np.asarray(x, float)
    n = x.size
    if n_out is None:
        n_out = int(np.floor((n - 1) * fs_to / fs_from + 1e-9)) + 1
    if fs_to < fs_from and n > 30:
        sos = signal.butter(8, 0.45 * fs_to, fs=fs_from, output="sos")
        x = signal.sosfiltfilt(sos, x)
    t_from = np.arange(n) / fs_from
    t_to = np.arange(n_out) / fs_to
    return np.interp(t_to, t_from, x)


_resample_signal = resample  # the name ``resample`` is also an argument of Bundle.predict


class Bundle:
    """A trained network loaded by :func:`nnmodel.load`.

    Attributes
    ----------
    model : NeuralModel
        The network.
    card : dict
        The bundle's card (``card.json``): model kind, hyper-parameters, inputs and units,
        sampling rate, RH range seen in training, dataset hash, metrics, versions.
    path : path or None
        The folder it was loaded from.

    Examples
    --------
    >>> import nnmodel
    >>> model = nnmodel.load("runs/train/models/ff")
    >>> model.card["model"], model.card["output"]["name"], model.n_parameters > 0
    ('ff', 'deflection', True)
    """

    def __init__(self, model: NeuralModel, card: dict, path: Path | None = None):
        self.model, self.card, self.path = model, card, path

    def __repr__(self) -> str:
        return (f"Bundle({self.card['model']!r}, fs={self.fs:g} Hz, inputs="
                f"{[i['name'] for i in self.card['inputs']]}, rh_range={self.rh_range})")

    @property
    def fs(self) -> float:
        """The sampling rate the network was trained at [Hz]."""
        return float(self.card["fs_hz"])

    @property
    def rh_range(self):
        """(lowest, highest) relative humidity seen in training [%], or None without humidity."""
        r = self.card.get("rh_range_pct")
        return None if r is None else tuple(r)

    @property
    def n_parameters(self) -> int:
        """Number of trained parameters."""
        return self.model.n_parameters

    def predict(self, voltage, rh=None, fs: float | None = None, steps_ahead: int | None = None,
                resample: bool = False, deflection=None) -> np.ndarray:
        """Predict the output for a voltage record.

        Parameters
        ----------
        voltage : array_like or time series
            Voltage [V], one value per sample; or a record with ``voltage``, ``fs``, ``rh``
            and ``deflection`` attributes.
        rh : float or array_like, optional
            Relative humidity [%], a constant or one value per sample; required when the
            network takes humidity.  Outside the range seen in training a warning is given.
        fs : float
            Sampling rate of ``voltage`` [Hz].
        steps_ahead : int, optional
            None (default): a free run.  k: k-step-ahead prediction from the measured
            ``deflection``.
        resample : bool
            Accept a sampling rate other than the training rate: the inputs are resampled to
            it and the prediction back to ``fs``.  Without it such a rate is refused.
        deflection : array_like, optional
            The measured output in the card's unit: a free run starts from its first samples
            (else from rest; at the training rate, only those first samples may be given);
            needed, whole, for ``steps_ahead``.

        Returns
        -------
        ndarray
            The predicted output, one value per sample, in the unit of the card's output
            (the tip deflection in m unless the dataset named another, e.g. ``level`` in cm).

        Raises
        ------
        InputError
            A NaN, a wrong shape, a missing ``fs`` or ``rh``, another sampling rate without
            ``resample``.
        """
        if hasattr(voltage, "voltage"):
            ts = voltage
            voltage = ts.voltage
            fs = fs if fs is not None else getattr(ts, "fs", None)
            if rh is None:
                rh = getattr(ts, "rh", None)
            if deflection is None and steps_ahead is not None:
                deflection = getattr(ts, "deflection", None)
        if fs is None:
            raise InputError(f"give the sampling rate fs= in Hz (this model was trained at {self.fs:g} Hz)")
        fs = check_fs(fs)
        u = check_voltage(voltage)
        y = None if deflection is None else np.asarray(deflection, dtype=float)
        same = abs(fs - self.fs) <= FS_RTOL * self.fs
        first_outputs = steps_ahead is None and same and y is not None and y.ndim == 1 and y.size < u.size
        if y is not None and y.shape != u.shape and not first_outputs:   # a free run may start from a few
            raise InputError(f"deflection must have the same shape as the voltage {u.shape}, got {y.shape}"
                             + ("" if steps_ahead is not None or same else
                                " (a free run from the first measured outputs needs the training rate)"))
        if same:
            return self.model.predict(u, rh=rh, y=y, steps_ahead=steps_ahead)
        if not resample:
            raise InputError(f"the input is sampled at {fs:g} Hz but the model was trained at "
                             f"{self.fs:g} Hz; resample the input, or give {arg('resample')} to resample in "
                             "and out automatically")
        m = self.model
        u_m = self._resample(u, fs, self.fs)
        rh_m = rh
        if rh is not None and np.ndim(rh) == 1:
            rh_arr = np.asarray(rh, dtype=float)
            if rh_arr.shape != u.shape:
                raise InputError(f"rh must be a constant or have one value per voltage sample "
                                 f"({u.size}), got shape {rh_arr.shape}")
            if not np.all(np.isfinite(rh_arr)):
                raise InputError("rh contains NaN or infinite values")
            rh_m = self._resample(rh_arr, fs, self.fs, u_m.size)
        y_m = None if y is None else self._resample(y, fs, self.fs, u_m.size)
        out_m = m.predict(u_m, rh=rh_m, y=y_m, steps_ahead=steps_ahead)
        return _resample_signal(out_m, self.fs, fs, u.size)

    @staticmethod
    def _resample(x, fs_from, fs_to, n_out=None):
        if not np.all(np.isfinite(x)):
            raise InputError("input contains NaN or infinite values")
        out = _resample_signal(x, fs_from, fs_to, n_out)
        if out.size < 2:
            raise InputError("the record is too short to resample")
        return out
