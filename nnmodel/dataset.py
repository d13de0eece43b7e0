"""Synthetic datasets for the neural models: generation (``eap generate``) and loading.

A dataset (``docs/reference/file-formats.md``) is a folder of time-series CSV files plus ``dataset.json``
with the generator and its configuration, the random seed, the split of every file
(train / validation / test), which RH levels are held out, and a SHA-256 of each file.
Records span RH 40–100 %: training RH levels, held-out RH levels (test only), records
whose RH drifts slowly, and "measurement-like" records simulated with physics the
generator's model lacks (e.g. ``nonlinear_charge``), scored separately.  Excitations
cover the operating range: log sweeps 0.1–50 Hz, random-phase multisines, band-limited
noise and square pulses, amplitudes up to 2 V, each ramped in from 0 V over the first
``fade_in_s`` (1 s) so that every record starts at rest, as a lab record does.  The sensor model adds laser noise,
quantisation and drift so that records look like lab records.  Everything follows
from one seed.
"""
from __future__ import annotations

import hashlib
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from physics.io.yamlio import load_yaml
from physics import signals
from physics.device import config_dir, load_device
from physics.errors import InputError
from physics.io.fileio import load_json, sha256_file, write_json
from physics.limits import FS_RANGE_HZ
from physics.model import ActuatorModel, resolve_effects
from physics.execution.parallel import ParallelSettings, map_tasks, warm_up
from physics.io.outputs import output_folder, preflight
from physics.io.sensor import SensorModel
from physics.solvers.timedomain import simulate
from physics.io.record import OutputQuantity
from physics.io.timeseries import read_timeseries, write_timeseries

from .data import Experiment

SCHEMA = "eap-dataset/1"
SPLITS = ("train", "validation", "test")

_DEFAULTS: dict[str, Any] = {
    "device": "ip2c_pedot_water", "effects": "default", "fs_Hz": 250.0, "duration_s": 40.0, "seed": 0,
    "train_rh_pct": [40, 60, 80, 100], "heldout_rh_pct": [50, 70, 90],
    "excitations": ["sweep", "multisine", "noise", "square"], "amplitude_V": [0.5, 2.0], "f_max_Hz": 50.0,
    "validation_per_rh": 1, "test_per_train_rh": 1, "test_per_heldout_rh": 2,
    "varying_rh": {"train": 2, "test": 2, "range_pct": [40, 100]},
    "measurement_like": {"effects": ["nonlinear_charge"], "count": 2, "rh_pct": [55, 85]},
    "sensor": "default", "fade_in_s": 1.0,
}


def load_config(name_or_path: str = "default", overrides: dict | None = None) -> dict:
    """A dataset configuration: ``configs/datasets/NAME.yaml`` or a YAML path, with overrides.
    Unknown keys are rejected."""
    p = Path(name_or_path)
    if p.suffix not in (".yaml", ".yml"):
        p = config_dir() / "datasets" / f"{name_or_path}.yaml"
    if not p.is_file():
        raise InputError(f"dataset configuration {name_or_path!r} not found ({p})")
    raw = load_yaml(p, "dataset configuration") or {}
    if not isinstance(raw, dict):
        raise InputError(f"{p}: a dataset configuration must be a mapping")
    cfg = dict(_DEFAULTS)
    for src, where in ((raw, str(p)), (overrides or {}, "overrides")):
        unknown = set(src) - set(_DEFAULTS)
        if unknown:
            raise InputError(f"{where}: unknown dataset option(s) {sorted(unknown)}; known: {sorted(_DEFAULTS)}")
        cfg.update({k: v for k, v in src.items() if v is not None})
    if not (cfg["fs_Hz"] > 2 * cfg["f_max_Hz"] and cfg["duration_s"] > 0):
        raise InputError(f"dataset: need fs_Hz > 2 f_max_Hz and a positive duration_s "
                         f"(got fs_Hz={cfg['fs_Hz']}, f_max_Hz={cfg['f_max_Hz']}, duration_s={cfg['duration_s']})")
    if not (isinstance(cfg["fade_in_s"], (int, float)) and 0 <= cfg["fade_in_s"] < cfg["duration_s"]):
        raise InputError(f"dataset: fade_in_s must be a number of seconds in [0, duration_s), "
                         f"got {cfg['fade_in_s']!r}")
    bad = set(cfg["excitations"]) - {"sweep", "multisine", "noise", "square"}
    if bad:
        raise InputError(f"dataset: unknown excitation(s) {sorted(bad)}")
    return cfg


def _sensor(spec) -> SensorModel:
    if spec in (None, "default"):
        return SensorModel(deflection_range=0.02)   # ±20 mm: the laser's range, no clipping
    if spec == "ideal":
        return SensorModel.ideal()
    if isinstance(spec, dict):
        try:
            return SensorModel(**spec)
        except TypeError as exc:
            raise InputError(f"dataset sensor: {exc}") from None
    raise InputError("dataset sensor must be 'default', 'ideal' or a mapping of SensorModel settings")


@dataclass
class _Spec:
    name: str
    split: str
    kind: str
    rh: float | tuple[float, float]   # constant, or (low, high) range for a drifting RH
    heldout: bool = False
    extra_effects: tuple[str, ...] = ()
    seed: int = 0
    excitation: dict = field(default_factory=dict)


def _plan(cfg: dict, rng: np.random.Generator) -> list[_Spec]:
    specs: list[_Spec] = []
    exc = list(cfg["excitations"])

    def add(split, kind, rh, **kw):
        i = len(specs)
        label = f"rh{rh:g}" if np.ndim(rh) == 0 else "rhvar"
        specs.append(_Spec(f"{split}/r{i:03d}_{kind}_{label}", split, kind, rh, seed=int(rng.integers(2**31)), **kw))

    for rh in cfg["train_rh_pct"]:
        for kind in exc:
            add("train", kind, float(rh))
        for _ in range(cfg["validation_per_rh"]):
            add("validation", str(rng.choice(exc)), float(rh))
        for _ in range(cfg["test_per_train_rh"]):
            add("test", str(rng.choice(exc)), float(rh))
    for rh in cfg["heldout_rh_pct"]:
        for _ in range(cfg["test_per_heldout_rh"]):
            add("test", str(rng.choice(exc)), float(rh), heldout=True)
    var = cfg["varying_rh"]
    for split in ("train", "test"):
        for _ in range(int(var.get(split, 0))):
            add(split, str(rng.choice(exc)), tuple(var["range_pct"]))
    ml = cfg["measurement_like"] or {}
    rhs = ml.get("rh_pct", [])
    for k in range(int(ml.get("count", 0))):
        add("test", str(rng.choice(exc)), float(rhs[k % len(rhs)]), extra_effects=tuple(ml.get("effects", [])))
    return specs


def _excitation(spec: _Spec, cfg: dict) -> signals.Signal:
    """The excitation of one record, ramped in from 0 V over ``fade_in_s`` (records start
    at rest)."""
    return signals.fade_in(_raw_excitation(spec, cfg), cfg["fade_in_s"])


def _raw_excitation(spec: _Spec, cfg: dict) -> signals.Signal:
    rng = np.random.default_rng(spec.seed)
    fs, T, fmax = cfg["fs_Hz"], cfg["duration_s"], cfg["f_max_Hz"]
    amp = float(rng.uniform(*cfg["amplitude_V"]))
    if spec.kind == "sweep":
        return signals.sweep(amp, 0.1, fmax, T, fs)
    if spec.kind == "multisine":
        return signals.multisine(amp / 2.5, max(0.1, 1.0 / T), float(rng.uniform(0.5, 1.0)) * fmax, T, 1, fs,
                                 seed=spec.seed)
    if spec.kind == "noise":
        return signals.noise(amp / 2.5, 0.1, float(rng.uniform(0.3, 1.0)) * fmax, T, fs, seed=spec.seed)
    t_on = float(rng.uniform(0.5, 3.0))
    t_off = float(rng.uniform(1.0, 5.0))
    cycles = max(1, int(T // (t_on + t_off)))
    sig = signals.square(amp, t_on, t_off, cycles, fs, rise_time=2.0 / fs, bipolar=bool(rng.integers(2)))
    n = int(round(T * fs))   # pad with rest, or cut, to the record length
    v = np.concatenate([sig.v, np.zeros(max(0, n - sig.v.size))])[:n]
    return signals.Signal(np.arange(n) / fs, v, sig.kind, sig.params)


def _rh_series(spec: _Spec, t: np.ndarray) -> np.ndarray | float:
    if np.ndim(spec.rh) == 0:
        return float(spec.rh)
    lo, hi = spec.rh
    rng = np.random.default_rng(spec.seed + 1)
    ph = rng.uniform(0, 2 * np.pi)
    frac = 0.5 + 0.5 * np.sin(2 * np.pi * t / (t[-1] + t[1]) * rng.uniform(0.5, 1.0) + ph)
    return lo + (hi - lo) * frac



def _generate_record(task: dict) -> dict:
    """Simulate, measure and write one record of the plan (a task of :func:`generate`; runs in
    any worker: plain data in, the file's dataset entry out)."""
    spec, cfg = task["spec"], task["cfg"]
    model = ActuatorModel(cfg["device"], list(resolve_effects(cfg["effects"], load_device(cfg["device"])))
                          + list(spec.extra_effects))
    sig = _excitation(spec, cfg)
    rh = _rh_series(spec, sig.t)
    hold = "linear" if spec.kind == "square" else "cubic"
    res = simulate(model, None, sig.t, sig.v, rh=rh, hold=hold)
    ts = _sensor(cfg["sensor"]).apply(res.to_timeseries(), seed=spec.seed)
    ts.meta.update({"excitation": sig.describe(), "split": spec.split})
    path = Path(task["folder"]) / f"{spec.name}.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_timeseries(ts, path)
    return {"path": f"{spec.name}.csv", "split": spec.split, "excitation": sig.describe(),
            "rh_pct": spec.rh if np.ndim(spec.rh) == 0 else {"varying": list(spec.rh)},
            "heldout_rh": spec.heldout, "extra_effects": list(spec.extra_effects),
            "effects": list(model.effect_ids), "seed": spec.seed, "samples": int(sig.t.size),
            "sha256": sha256_file(path), "sidecar_sha256": sha256_file(path.with_suffix(".yaml"))}


def _record_cost(task: dict) -> float:
    """Relative cost of a record, to simulate the dearest first: a drifting RH is solved
    sample by sample (about 10× a constant RH), extra effects are mostly nonlinear (≈ ×4)."""
    spec = task["spec"]
    return (10.0 if np.ndim(spec.rh) else 1.0) * (4.0 if spec.extra_effects else 1.0)


def generate(out: str | Path, config: str | dict = "default", *, overwrite: bool = False,
             progress: bool = True, settings: ParallelSettings | None = None, **overrides) -> Path:
    """Generate a dataset folder (written to a temporary folder, then renamed into place; the
    output-folder policy of :mod:`physics.io.outputs`: ``overwrite`` replaces only a folder eap wrote).
    ``settings``: where the records are simulated (:mod:`physics.execution.parallel`; identical files for
    any worker count, every record has its own seed)."""
    cfg = load_config(config, overrides) if isinstance(config, str) else load_config("default", config)
    out = Path(out)
    preflight(out, overwrite=overwrite)
    warm_up(settings)   # the workers start while the plan and the base model are made
    rng = np.random.default_rng(cfg["seed"])
    specs = _plan(cfg, rng)
    sensor = _sensor(cfg["sensor"])
    base = ActuatorModel(cfg["device"], cfg["effects"])
    t0 = time.perf_counter()
    with output_folder(out, overwrite=overwrite) as tmp:
        tasks = [{"spec": spec, "cfg": cfg, "folder": str(tmp)} for spec in specs]
        entries = map_tasks(_generate_record, tasks, settings, desc="generating dataset", progress=progress,
                            cost=_record_cost)
        meta = {"schema": SCHEMA, "name": out.name, "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "generator": {"tool": "eap generate", "device": cfg["device"], "effects": list(base.effect_ids),
                              "config": cfg}, "seed": cfg["seed"], "fs_Hz": cfg["fs_Hz"],
                "rh_levels": {"train": cfg["train_rh_pct"], "held_out": cfg["heldout_rh_pct"]},
                "noise_floor_m": sensor.noise_floor(), "generation_time_s": time.perf_counter() - t0,
                "files": entries}
        write_json(tmp / "dataset.json", meta)
    return out


@dataclass
class Dataset:
    """A loaded dataset: ``meta`` (dataset.json, validated) and ``path``; files are checked
    against their hashes (:func:`load_dataset`)."""

    path: Path
    meta: dict
    _read: dict = field(default_factory=dict, repr=False, compare=False)   # entry path -> TimeSeries read

    @property
    def fs(self) -> float:
        return float(self.meta["fs_Hz"])

    @property
    def output(self) -> OutputQuantity:
        """What the records' output is (default: the tip deflection in m)."""
        return OutputQuantity.from_dict(self.meta.get("output"))

    @property
    def hash(self) -> str:
        """Content hash of the whole dataset (hash of the per-file hashes)."""
        return hashlib.sha256("".join(e["sha256"] for e in self.meta["files"]).encode()).hexdigest()

    def entries(self, split: str | None = None, *, heldout: bool | None = None,
                measurement_like: bool | None = None) -> list[dict]:
        out = []
        for e in self.meta["files"]:
            if split is not None and e["split"] != split:
                continue
            if heldout is not None and bool(e.get("heldout_rh")) != heldout:
                continue
            if measurement_like is not None and bool(e.get("extra_effects")) != measurement_like:
                continue
            out.append(e)
        return out

    def records(self, split: str | None = None, **filters) -> list[Experiment]:
        return [self.record(e) for e in self.entries(split, **filters)]

    @property
    def has_rh(self) -> bool:
        """False for a dataset of measurements without relative humidity (``rh_levels`` null)."""
        return self.meta.get("rh_levels") is not None

    def record(self, entry: dict) -> Experiment:
        """The record of ``entry`` as the networks' view of it; each file is read once (the
        dataset keeps what it has read, its arrays read-only)."""
        ts = self._read.get(entry["path"])
        if ts is None:        # kept as the networks see it: without the RH channel when the dataset has none
            ts = self._read_record(entry)
            ts = self._read[entry["path"]] = ts if self.has_rh else _without_rh(ts)
        return Experiment.from_timeseries(ts, name=entry["path"])

    def _read_record(self, entry: dict):
        ts = read_timeseries(self.path / entry["path"], rh=None if self.has_rh else 0.0, output=self.output)
        if abs(ts.fs - self.fs) > 1e-6 * self.fs:
            raise InputError(f"{self.path / entry['path']}: sampled at {ts.fs:g} Hz but dataset.json says fs_Hz "
                             f"{self.fs:g}; the dataset was changed — rebuild it")
        if entry.get("samples") is not None and ts.n != entry["samples"]:
            raise InputError(f"{self.path / entry['path']}: {ts.n} samples but dataset.json says {entry['samples']}; "
                             "the dataset was changed — rebuild it")
        for name in ("time", "voltage", "deflection", "rh"):
            a = getattr(ts, name)
            if isinstance(a, np.ndarray):
                a.setflags(write=False)
        return ts


def _without_rh(ts):
    """``ts`` without its humidity channel (a dataset without RH), sharing the other arrays."""
    import dataclasses
    return dataclasses.replace(ts, rh=None)


# --------------------------------------------------------------------------- a closed world

_SHA = re.compile(r"^[0-9a-f]{64}$")


def _fault(mf: Path, what: str) -> InputError:
    return InputError(f"{mf}: {what}; the dataset description is damaged — rebuild it with eap dataset or eap "
                      "generate")


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _check_meta(meta, mf: Path) -> None:
    """The schema of dataset.json, one clear error per fault (the first found)."""
    if not isinstance(meta, dict):
        raise _fault(mf, f"expected a JSON object, got {type(meta).__name__}")
    if meta.get("schema") != SCHEMA:
        raise _fault(mf, f"schema {meta.get('schema')!r} is not {SCHEMA!r}")
    lo, hi = FS_RANGE_HZ
    fs = meta.get("fs_Hz")
    if not (_number(fs) and lo <= fs <= hi):
        raise _fault(mf, f"fs_Hz {fs!r} is not a sampling rate within {lo:g}–{hi:g} Hz")
    vf = meta.get("val_fraction", 0.0)
    if vf is not None and not (_number(vf) and 0.0 <= vf < 0.9):
        raise _fault(mf, f"val_fraction {vf!r} must lie in [0, 0.9)")
    levels = meta.get("rh_levels")
    if levels is not None and not (isinstance(levels, dict) and all(
            isinstance(levels.get(k, []), list) and all(_number(x) for x in levels.get(k, []))
            for k in ("train", "held_out"))):
        raise _fault(mf, f"rh_levels {levels!r} must be null or a mapping of RH lists (train, held_out) in %")
    try:
        OutputQuantity.from_dict(meta.get("output"), f"{mf}: output")
    except InputError as exc:
        raise _fault(mf, str(exc).removeprefix(f"{mf}: ")) from None
    floor = meta.get("noise_floor_m")
    if floor is not None and not (_number(floor) and floor >= 0):
        raise _fault(mf, f"noise_floor_m {floor!r} must be null or a non-negative number of metres")
    files = meta.get("files")
    if not isinstance(files, list) or not files:
        raise _fault(mf, f"files must be a non-empty list of records, got {type(files).__name__}")
    seen: set[str] = set()
    for k, e in enumerate(files):
        where = f"files[{k}]"
        if not isinstance(e, dict):
            raise _fault(mf, f"{where} must be an object (path, split, sha256, ...), got {type(e).__name__}")
        path = e.get("path")
        if not isinstance(path, str) or not path:
            raise _fault(mf, f"{where}.path {path!r} must be a relative file path")
        where = f"{where} ({path})"
        parts = PurePosixPath(path).parts
        if PurePosixPath(path).is_absolute() or "\\" in path or ".." in parts or not path.lower().endswith(".csv"):
            raise _fault(mf, f"{where}: a record must be a .csv path inside the dataset folder (relative, no '..')")
        if len(parts) > 8 or any(len(q.encode("utf-8", "surrogateescape")) > 255 for q in parts):
            raise _fault(mf, f"files[{k}].path: a path of {len(parts)} parts, {len(path)} characters; a record's "
                             "path is a split folder and a file name of at most 255 bytes")
        if path in seen:
            raise _fault(mf, f"{where} is listed twice")
        seen.add(path)
        if e.get("split") not in SPLITS:
            raise _fault(mf, f"{where}: split {e.get('split')!r}; expected one of {', '.join(SPLITS)}")
        if not (isinstance(e.get("sha256"), str) and _SHA.match(e["sha256"])):
            raise _fault(mf, f"{where}: sha256 {e.get('sha256')!r} is not a SHA-256 (64 hex digits)")
        side = e.get("sidecar_sha256")
        if side is not None and not (isinstance(side, str) and _SHA.match(side)):
            raise _fault(mf, f"{where}: sidecar_sha256 {side!r} is not null or a SHA-256")
        n = e.get("samples")
        if n is not None and not (isinstance(n, int) and not isinstance(n, bool) and n >= 2):
            raise _fault(mf, f"{where}: samples {n!r} must be a whole number ≥ 2")
        if not isinstance(e.get("heldout_rh", False), bool):
            raise _fault(mf, f"{where}: heldout_rh {e.get('heldout_rh')!r} must be true or false")
        extra = e.get("extra_effects", [])
        if not (isinstance(extra, list) and all(isinstance(x, str) for x in extra)):
            raise _fault(mf, f"{where}: extra_effects {extra!r} must be a list of effect ids")
        rh = e.get("rh_pct")
        if rh is not None and not (_number(rh) and 0 <= rh <= 100) and not (
                isinstance(rh, dict) and isinstance(rh.get("varying"), list)):
            raise _fault(mf, f"{where}: rh_pct {rh!r} must be null, a number within 0–100 % or "
                             "{\"varying\": [low, high]}")


def _inside(root: Path, rel: str, mf: Path) -> Path:
    """``root/rel`` after checking it is a regular file inside ``root`` reached without links."""
    p = root
    for part in PurePosixPath(rel).parts:
        p = p / part
        if p.is_symlink():
            raise InputError(f"{mf}: {rel}: {p} is a symbolic link; a dataset holds its own files (a link could "
                             "lead outside the folder) — copy the file in and rebuild the dataset")
    if not p.is_file():
        raise InputError(f"{mf}: listed file {rel} is missing")
    if root not in p.resolve().parents:
        raise InputError(f"{mf}: {rel} resolves outside the dataset folder; a dataset holds its own files")
    return p


def load_dataset(path: str | Path, verify: bool = True) -> Dataset:
    """Load and validate ``dataset.json`` of a dataset folder (schema, every path a regular
    file inside the folder, no entry twice); with ``verify`` every file's and sidecar's
    SHA-256 is checked too.  A dataset is a closed world: nothing outside its folder is read."""
    path = Path(path)
    mf = path / "dataset.json"
    if not (mf.exists() or mf.is_symlink()):
        raise InputError(f"{path} is not a dataset folder (no dataset.json)")
    root = path.resolve()
    if mf.is_symlink() or mf.resolve().parent != root:
        raise InputError(f"{mf} is a symbolic link; a dataset holds its own description (a link could lead outside "
                         "the folder) — copy the file in")
    meta = load_json(mf, "dataset description")
    _check_meta(meta, mf)
    for e in meta["files"]:
        f = _inside(root, e["path"], mf)
        side = f.with_suffix(".yaml")
        if "sidecar_sha256" in e and e["sidecar_sha256"] is None and (side.exists() or side.is_symlink()):
            raise InputError(f"{side}: a sidecar the dataset does not list (dataset.json says {e['path']} has none); "
                             "remove it or rebuild the dataset")
        if not verify:
            continue
        if sha256_file(f) != e["sha256"]:
            raise InputError(f"{f}: content differs from the SHA-256 recorded in dataset.json "
                             f"(modified after generation)")
        if e.get("sidecar_sha256") is not None:
            if not side.is_file() or side.is_symlink():
                raise InputError(f"{mf}: the sidecar {side.name} of {e['path']} is missing")
            if sha256_file(side) != e["sidecar_sha256"]:
                raise InputError(f"{side}: content differs from the SHA-256 recorded in dataset.json (the record's "
                                 "metadata was modified after the dataset was written)")
        elif "sidecar_sha256" not in e and side.exists():
            raise InputError(f"{side}: dataset.json records no hash for this sidecar (an older eap wrote the "
                             "dataset); rebuild the dataset")
    return Dataset(path, meta)
