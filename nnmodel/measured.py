"""Datasets from a lab's own measurement files (``eap dataset``).

Each named file (optionally a sample range ``FILE[START:STOP]``, e.g. the standard split
of one long benchmark record) is read with the same rules, column maps and errors as every
other command (:func:`physics.io.timeseries.read_timeseries`), written into the dataset folder
as a standard time-series CSV (``time_s, voltage_V, deflection_m[, rh_pct]``, or the output
named with ``output``, e.g. ``level_V``) with its sidecar (the source's metadata) and listed
in ``dataset.json`` (schema ``eap-dataset/1``, the same as :func:`nnmodel.dataset.generate`)
with its split, RH, length, the SHA-256 of the record and of its sidecar, and its source
(path, SHA-256 of the whole source file, sample range, column map).

What the output is (``output``: name and unit, default the tip deflection in m) is decided
here, once: every record is checked against that quantity's plausibility rule at import,
and training, prediction and reports read it from ``dataset.json``.  The sensor of the
sources' sidecars reaches the dataset (``sensor``, ``noise_floor_m``).

Records that share samples leak test data into training: two parts of the same content (the
same file, a copy of it, or overlapping ranges of one record) are refused unless
``allow_overlap``, and then marked (``overlap`` in the entries and in ``dataset.json``).
A record whose output or voltage is constant is refused (nothing to learn).
:func:`check_dataset` re-verifies everything and names what changed.
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from physics.compare import cluster_rh
from physics.errors import InputError
from physics.io.fileio import sha256_file, write_json
from physics.io.outputs import component, output_folder, preflight
from physics.io.record import OutputQuantity
from physics.io.timeseries import TimeSeries, read_timeseries, write_timeseries

from .dataset import SCHEMA, load_dataset

_RANGE = re.compile(r"^(?P<path>.+)\[(?P<a>-?\d*):(?P<b>-?\d*)\]$")


def parse_part(text: str) -> tuple[Path, slice]:
    """``FILE`` or ``FILE[START:STOP]`` (sample indices, Python slice rules)."""
    m = _RANGE.match(text)
    if not m:
        return Path(text), slice(None)
    a, b = m["a"], m["b"]
    return Path(m["path"]), slice(int(a) if a else None, int(b) if b else None)


def _read(path: Path, opts: dict) -> tuple[TimeSeries, bool]:
    """The record, and whether it carries a relative humidity."""
    try:
        return read_timeseries(path, **opts), True
    except InputError as exc:
        if opts.get("rh") is not None or "no relative humidity" not in str(exc):
            raise
    return read_timeseries(path, **dict(opts, rh=0.0)), False


def _check_varies(ts: TimeSeries, text: str, split: str) -> None:
    for name, arr in (("voltage", ts.voltage), (ts.output.name, ts.deflection)):
        if np.ptp(arr) == 0:
            raise InputError(f"--{split} {text}: the {name} is constant ({float(arr[0]):g}) over the samples used; "
                             "a record with a constant input or output teaches a model nothing — check the column "
                             "(--columns) or the sample range")


def _overlaps(records) -> list[tuple[int, int, int, int]]:
    """(i, j, first, last) of record pairs that share samples of the same content."""
    out = []
    for i in range(len(records)):
        for j in range(i + 1, len(records)):
            a, b = records[i], records[j]
            if a["source_sha"] == b["source_sha"]:
                lo, hi = max(a["range"][0], b["range"][0]), min(a["range"][1], b["range"][1])
                if lo < hi:
                    out.append((i, j, lo, hi))
    return out


def _sensor_summary(records) -> tuple[dict | None, float | None]:
    """The sensor common to every record's sidecar (or None) and the noise floor [m] they
    give (the largest; None unless every record states one)."""
    sensors = [r["ts"].meta.get("sensor") for r in records]
    common = sensors[0] if sensors and all(s == sensors[0] for s in sensors) else None
    floors = [s.get("noise_floor_m") if isinstance(s, dict) else None for s in sensors]
    floor = max(floors) if floors and all(isinstance(f, (int, float)) for f in floors) else None
    return common, floor


@dataclass(frozen=True)
class ReadOptions:
    """How :func:`build_dataset` reads every source file (as
    :func:`physics.io.timeseries.read_timeseries` does): the ``columns`` map, the sampling
    rate ``fs`` [Hz] of files without a time column, the ``rh`` [%] of files without one,
    ``resample`` non-uniform time onto the median step, and the sensor ``gain``."""

    columns: dict | None = None
    fs: float | None = None
    rh: float | None = None
    resample: bool = False
    gain: str | None = None


def build_dataset(out, *, train: Sequence[str], validation: Sequence[str] = (), test: Sequence[str] = (),
                  val_fraction: float = 0.2, holdout_rh: Sequence[float] = (), read: ReadOptions | None = None,
                  output: OutputQuantity | str | None = None, allow_overlap: bool = False, overwrite: bool = False,
                  command: str = "eap dataset", rh_tolerance: float = 1.0) -> Path:
    """Write the dataset folder ``out`` (see the module doc); returns its path.  ``read``: how
    the files are read (:class:`ReadOptions`; default: as they are).  ``rh_tolerance``
    [%]: training records whose RH differ by less form one RH level (``rh_levels``)."""
    if not train:
        raise InputError("--train: give at least one training file")
    if not (isinstance(val_fraction, (int, float)) and 0.0 <= val_fraction < 0.9):
        raise InputError(f"--val-fraction {val_fraction!r}: must lie in [0, 0.9)")
    if isinstance(output, str):
        output = OutputQuantity.parse(output)
    read = read if read is not None else ReadOptions()
    parts = [(s, t) for s, items in (("train", train), ("validation", validation), ("test", test)) for t in items]
    inputs = [parse_part(t)[0] for _, t in parts]
    preflight(out, inputs=inputs, overwrite=overwrite)
    records = _read_records(parts, dict(columns=read.columns, fs=read.fs, rh=read.rh, resample=read.resample,
                                        output=output, gain=read.gain))
    shared, has_rh, held = _check_records(records, allow_overlap, holdout_rh)
    sensor, floor = _sensor_summary(records)
    t0 = time.perf_counter()
    with output_folder(out, inputs=inputs, overwrite=overwrite) as tmp:
        entries = [_write_record(tmp, r, held, read.columns) for r in records]
        marks = [{"records": [entries[i]["path"], entries[j]["path"]], "samples": [int(lo), int(hi)]}
                 for i, j, lo, hi in shared]
        for m in marks:
            for rel in m["records"]:
                next(e for e in entries if e["path"] == rel)["overlap"] = True
        trained = [e["rh_pct"] for e in entries if e["rh_pct"] is not None and e["split"] == "train"]
        levels = sorted(set(cluster_rh(trained, rh_tolerance))) if trained else []   # hygrometer jitter: one level
        quantity = records[0]["ts"].output
        meta = {"schema": SCHEMA, "name": Path(out).name, "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "generator": {"tool": "eap dataset", "command": command, "device": None, "effects": None},
                "seed": None, "fs_Hz": records[0]["ts"].fs, "val_fraction": val_fraction,
                "rh_levels": {"train": levels, "held_out": held} if has_rh else None,
                "output": quantity.to_dict(), "sensor": sensor,
                "noise_floor_m": floor if quantity.is_deflection else None,
                "generation_time_s": time.perf_counter() - t0, "files": entries}
        if marks:
            meta["overlap"] = marks
        write_json(tmp / "dataset.json", meta)
    return Path(out)


def _read_records(parts, opts: dict) -> list[dict]:
    """Read every (split, ``FILE[START:STOP]``) of ``parts`` with the reader options ``opts``:
    one dict per record (its sample range, a unique name within its split, the source's SHA-256)."""
    records, names, source_hash = [], set(), {}
    for split, text in parts:
        path, rng = parse_part(text)
        if not path.is_file():
            raise InputError(f"--{split} {text}: file not found")
        ts, has_rh = _read(path, opts)
        n0 = ts.n
        beyond = [i for i in (rng.start, rng.stop) if i is not None and not -n0 <= i <= n0]
        if beyond:
            raise InputError(f"--{split} {text}: sample {beyond[0]} lies beyond the {n0} samples of {path}; give "
                             f"indices within -{n0}…{n0} (a range is never clipped)")
        a, b, _ = rng.indices(n0)
        if b - a < 16:
            raise InputError(f"--{split} {text}: samples {a}:{b} of {n0} leave {max(b - a, 0)} samples; a record "
                             "needs at least 16")
        ts = ts.slice(a, b)
        _check_varies(ts, text, split)
        stem = path.stem.lstrip(".").encode("utf-8", "surrogateescape")[:120].decode("utf-8", "ignore") or "record"
        name = component(stem + ("" if (a, b) == (0, n0) else f"_{a}-{b}"), f"--{split} {text}", "a record file")
        base, k = name, 1
        while f"{split}/{name}" in names:
            k += 1
            name = f"{base}_{k}"
        names.add(f"{split}/{name}")
        if path not in source_hash:
            source_hash[path] = sha256_file(path)
        records.append({"split": split, "text": text, "path": path, "range": (a, b), "ts": ts, "has_rh": has_rh,
                        "name": name, "source_sha": source_hash[path]})
    return records


def _check_records(records, allow_overlap: bool, holdout_rh) -> tuple[list, bool, list[float]]:
    """Refuse records that do not form one dataset (another output, sampling rate or RH
    presence; shared samples unless ``allow_overlap``): (the shared samples, whether the
    records carry an RH, the held-out RH levels sorted)."""
    first = records[0]
    for r in records[1:]:
        if r["ts"].output != first["ts"].output:
            raise InputError(f"--{r['split']} {r['text']}: its output is {r['ts'].output.label()} but "
                             f"{first['text']} gives {first['ts'].output.label()}; a dataset has one output")
    shared = _overlaps(records)
    if shared and not allow_overlap:
        i, j, lo, hi = shared[0]
        a, b = records[i], records[j]
        same = "the same file" if a["path"].resolve() == b["path"].resolve() else "files with identical content"
        raise InputError(f"--{a['split']} {a['text']} and --{b['split']} {b['text']} share samples {lo}:{hi} of "
                         f"{same}; overlapping records leak one split into another (or count samples twice) — "
                         "give disjoint ranges, or pass --allow-overlap to keep them (they are then marked)")
    fs_all = {round(r["ts"].fs, 6) for r in records}
    if len(fs_all) > 1:
        worst = max(records, key=lambda r: abs(r["ts"].fs - first["ts"].fs))
        raise InputError(f"{worst['path']}: sampled at {worst['ts'].fs:g} Hz but {first['path']} at "
                         f"{first['ts'].fs:g} Hz; a dataset has one sampling rate — resample the files first")
    with_rh = {r["has_rh"] for r in records}
    if len(with_rh) > 1:
        raise InputError("some files carry a relative humidity and others do not; give --rh for all, or add an "
                         "rh_pct column to every file")
    has_rh = with_rh.pop()
    held = sorted(float(x) for x in holdout_rh)
    if held and not has_rh:
        raise InputError("--holdout-rh needs records with a relative humidity (rh_pct column, sidecar or --rh)")
    return shared, has_rh, held


def _write_record(tmp: Path, r: dict, held: list[float], columns) -> dict:
    """Write record ``r`` into the dataset folder ``tmp`` (time from 0, the source in its
    sidecar): its ``dataset.json`` entry.  A training record at a held-out RH is refused."""
    ts = r["ts"]
    level = float(np.mean(ts.rh)) if r["has_rh"] else None
    is_held = bool(level is not None and any(abs(level - h) <= 2.5 for h in held))
    if is_held and r["split"] == "train":
        raise InputError(f"--train {r['text']}: its RH {level:.3g} % is listed in --holdout-rh {held}; "
                         "held-out RH levels must not be trained on")
    meta = {k: v for k, v in ts.meta.items() if k not in ("split",)}
    meta["source"] = str(r["path"].resolve())
    keep = TimeSeries(time=ts.time - ts.time[0], voltage=ts.voltage, deflection=ts.deflection,
                      rh=ts.rh if r["has_rh"] else None, meta=meta, output=ts.output)
    rel = f"{r['split']}/{r['name']}.csv"
    write_timeseries(keep, tmp / rel)
    a, b = r["range"]
    return {"path": rel, "split": r["split"], "heldout_rh": is_held, "extra_effects": [],
            "rh_pct": level, "samples": int(keep.n), "sha256": sha256_file(tmp / rel),
            "sidecar_sha256": sha256_file((tmp / rel).with_suffix(".yaml")),
            "source": {"path": str(r["path"].resolve()), "sha256": r["source_sha"],
                       "samples": [int(a), int(b)], "columns": columns}}


def check_dataset(path) -> list[str]:
    """Re-verify a dataset: every file against its SHA-256 (raises naming a changed file),
    every record read as training reads it (sampling rate, output, plausibility), and every
    source file still present; returns notes on sources that moved or changed."""
    ds = load_dataset(path, verify=True)
    for e in ds.meta["files"]:
        ds.record(e)
    notes = []
    for e in ds.meta["files"]:
        src = e.get("source")
        if not isinstance(src, dict) or not isinstance(src.get("path"), str):
            continue
        p = Path(src["path"])
        if not p.is_file():
            notes.append(f"source {p} of {e['path']} is no longer there (the dataset's own copy is intact)")
        elif sha256_file(p) != src.get("sha256"):
            notes.append(f"source {p} of {e['path']} changed since the dataset was built (rebuild it to use the "
                         "new content)")
    if ds.meta.get("overlap"):
        notes.append(f"{len(ds.meta['overlap'])} pair(s) of records share samples (built with --allow-overlap)")
    return sorted(set(notes))
