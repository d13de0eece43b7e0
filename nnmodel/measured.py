"""Datasets from a lab's own measurement files (``eap dataset``).

Each named file (optionally a sample range ``FILE[START:STOP]``, e.g. the standard split
of one long benchmark record) is read with the same rules, column maps and errors as every
other command (:func:`physics.timeseries.read_timeseries`), written into the dataset folder
as a standard time-series CSV (``time_s, voltage_V, deflection_m[, rh_pct]``) and listed in
``dataset.json`` (schema ``eap-dataset/1``, the same as :func:`nnmodel.dataset.generate`)
with its split, RH, length, SHA-256 and its source (path, SHA-256 of the whole source file,
sample range, column map).  :func:`check_dataset` re-verifies both and names what changed.
"""
from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from physics.errors import InputError
from physics.fileio import sha256_file, write_json
from physics.outputs import output_folder, preflight
from physics.timeseries import TimeSeries, read_timeseries, write_timeseries

from .dataset import SCHEMA, load_dataset

_RANGE = re.compile(r"^(?P<path>.+)\[(?P<a>-?\d*):(?P<b>-?\d*)\]$")


def parse_part(text: str) -> tuple[Path, slice]:
    """``FILE`` or ``FILE[START:STOP]`` (sample indices, Python slice rules)."""
    m = _RANGE.match(text)
    if not m:
        return Path(text), slice(None)
    a, b = m["a"], m["b"]
    return Path(m["path"]), slice(int(a) if a else None, int(b) if b else None)


def _read(path: Path, columns, fs, rh, resample) -> tuple[TimeSeries, bool]:
    """The record, and whether it carries a relative humidity."""
    try:
        return read_timeseries(path, columns=columns, fs=fs, rh=rh, resample=resample), True
    except InputError as exc:
        if rh is not None or "no relative humidity" not in str(exc):
            raise
    return read_timeseries(path, columns=columns, fs=fs, rh=0.0, resample=resample), False


def build_dataset(out, *, train: Sequence[str], validation: Sequence[str] = (), test: Sequence[str] = (),
                  val_fraction: float = 0.2, holdout_rh: Sequence[float] = (), columns: dict | None = None,
                  fs: float | None = None, rh: float | None = None, resample: bool = False,
                  overwrite: bool = False, command: str = "eap dataset") -> Path:
    """Write the dataset folder ``out`` (see the module doc); returns its path."""
    if not train:
        raise InputError("--train: give at least one training file")
    if not 0.0 <= val_fraction < 0.9:
        raise InputError(f"--val-fraction {val_fraction!r}: must lie in [0, 0.9)")
    parts = [(s, t) for s, items in (("train", train), ("validation", validation), ("test", test)) for t in items]
    inputs = [parse_part(t)[0] for _, t in parts]
    preflight(out, inputs=inputs, overwrite=overwrite)
    records, names = [], set()
    for split, text in parts:
        path, rng = parse_part(text)
        if not path.is_file():
            raise InputError(f"--{split} {text}: file not found")
        ts, has_rh = _read(path, columns, fs, rh, resample)
        n0 = ts.n
        a, b, _ = rng.indices(n0)
        if b - a < 16:
            raise InputError(f"--{split} {text}: samples {a}:{b} of {n0} leave {max(b - a, 0)} samples; a record "
                             "needs at least 16")
        ts = ts.slice(a, b)
        name = f"{path.stem}" + ("" if (a, b) == (0, n0) else f"_{a}-{b}")
        base, k = name, 1
        while f"{split}/{name}" in names:
            k += 1
            name = f"{base}_{k}"
        names.add(f"{split}/{name}")
        records.append((split, text, path, (a, b), ts, has_rh, name))
    fs_all = {round(r[4].fs, 6) for r in records}
    if len(fs_all) > 1:
        worst = max(records, key=lambda r: abs(r[4].fs - records[0][4].fs))
        raise InputError(f"{worst[2]}: sampled at {worst[4].fs:g} Hz but {records[0][2]} at {records[0][4].fs:g} Hz; "
                         "a dataset has one sampling rate — resample the files first")
    with_rh = {r[5] for r in records}
    if len(with_rh) > 1:
        raise InputError("some files carry a relative humidity and others do not; give --rh for all, or add an "
                         "rh_pct column to every file")
    has_rh = with_rh.pop()
    held = sorted(float(x) for x in holdout_rh)
    if held and not has_rh:
        raise InputError("--holdout-rh needs records with a relative humidity (rh_pct column, sidecar or --rh)")
    entries = []
    t0 = time.perf_counter()
    with output_folder(out, inputs=inputs, overwrite=overwrite) as tmp:
        source_hash: dict[Path, str] = {}
        for split, text, path, (a, b), ts, rec_rh, name in records:
            level = float(np.mean(ts.rh)) if rec_rh else None
            is_held = bool(level is not None and any(abs(level - h) <= 2.5 for h in held))
            if is_held and split == "train":
                raise InputError(f"--train {text}: its RH {level:.3g} % is listed in --holdout-rh {held}; "
                                 "held-out RH levels must not be trained on")
            keep = TimeSeries(time=ts.time - ts.time[0], voltage=ts.voltage, deflection=ts.deflection,
                              rh=ts.rh if rec_rh else None, meta={"source": str(path.resolve())})
            rel = f"{split}/{name}.csv"
            write_timeseries(keep, tmp / rel)
            if path not in source_hash:
                source_hash[path] = sha256_file(path)
            entries.append({"path": rel, "split": split, "heldout_rh": is_held, "extra_effects": [],
                            "rh_pct": level, "samples": int(keep.n), "sha256": sha256_file(tmp / rel),
                            "source": {"path": str(path.resolve()), "sha256": source_hash[path],
                                       "samples": [int(a), int(b)], "columns": columns}})
        levels = sorted({e["rh_pct"] for e in entries if e["rh_pct"] is not None and e["split"] == "train"})
        meta = {"schema": SCHEMA, "name": Path(out).name, "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "generator": {"tool": "eap dataset", "command": command, "device": None, "effects": None},
                "seed": None, "fs_Hz": records[0][4].fs, "val_fraction": val_fraction,
                "rh_levels": {"train": levels, "held_out": held} if has_rh else None,
                "output": {"name": (columns or {}).get("deflection", "deflection"),
                           "unit": "m" if columns is None else "file units"},
                "noise_floor_m": None, "generation_time_s": time.perf_counter() - t0, "files": entries}
        write_json(tmp / "dataset.json", meta)
    return Path(out)


def check_dataset(path) -> list[str]:
    """Re-verify a dataset: every file against its SHA-256 (raises naming a changed file)
    and every source file still present; returns notes on sources that moved or changed."""
    ds = load_dataset(path, verify=True)
    notes = []
    for e in ds.meta["files"]:
        src = e.get("source")
        if not src:
            continue
        p = Path(src["path"])
        if not p.is_file():
            notes.append(f"source {p} of {e['path']} is no longer there (the dataset's own copy is intact)")
        elif sha256_file(p) != src["sha256"]:
            notes.append(f"source {p} of {e['path']} changed since the dataset was built (rebuild it to use the "
                         "new content)")
    return sorted(set(notes))
