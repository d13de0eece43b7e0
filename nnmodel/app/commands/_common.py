"""Options shared by several commands."""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

from physics.io.outputs import OUT_DIR, output_folder, preflight, reserve


def add_model_options(p: argparse.ArgumentParser, rh_required: bool = False) -> None:
    p.add_argument("--device", default="ipmc_pt_eg",
                   help="device name in configs/devices (ipmc_pt_eg, ip2c_pedot_water) or a YAML path")
    p.add_argument("--effects", default="default",
                   help="comma-separated effect ids, or default / linear / all / none (see `eap effects`)")
    p.add_argument("--rh", type=float, default=None, required=rh_required,
                   help="relative humidity [%%] (needed when the humidity effect is on)")
    p.add_argument("--n-modes", type=int, default=4, help="retained bending modes (the rest is quasi-static)")


def add_output_options(p: argparse.ArgumentParser, default: str | None, what: str = "output folder") -> None:
    """``--out`` (a folder written atomically, see :mod:`physics.io.outputs`) and ``--overwrite``."""
    if default is None:
        p.add_argument("--out", required=True, help=what)
    else:
        p.add_argument("--out", default=default, help=what)
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out folder written by eap (never one holding other files)")


def add_record_options(p: argparse.ArgumentParser, *, gain: bool = True, fs: bool = True) -> None:
    """``--columns`` (a column map with units, for files in another layout) and, with ``fs``,
    ``--fs-Hz``, with ``gain``, ``--sensor-gain``: how every command that reads records reads
    other files."""
    p.add_argument("--columns", default=None,
                   help="column map for files in another layout, e.g. time=t,voltage=V1,deflection=V2 (values in s, "
                        "V, m), with units where they differ: deflection=Tip (mm):mm, time=t:ms (a unit in a header, "
                        "Tip [mm], is used too)")
    if fs:
        p.add_argument("--fs-Hz", type=float, default=None, help="sampling rate of files without a time column")
    if gain:
        p.add_argument("--sensor-gain", default=None, metavar="GAIN",
                       help="convert an output column read in another unit to tip deflection in metres, e.g. 2.5mm/V "
                            "for a laser sensor giving volts (with --columns deflection=COLUMN:V)")


def add_quiet_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr (the summary is still printed)")


#: Input size [bytes] from which a command reports its stages (~250,000 CSV rows, a few seconds).
LONG_INPUT_BYTES = 10_000_000


def stage_log(args, inputs=()):
    """``log(message)``: one line per stage on stderr, with the elapsed time (``[compare
    12.3 s] simulating …``), when the ``inputs`` (paths) add up to at least
    :data:`LONG_INPUT_BYTES`; silent for short work and with ``--quiet``."""
    size = sum(Path(p).stat().st_size for p in inputs if Path(p).is_file())
    if getattr(args, "quiet", False) or size < LONG_INPUT_BYTES:
        return lambda message: None
    t0 = time.perf_counter()

    def log(message: str) -> None:
        print(f"[{args.command} {time.perf_counter() - t0:.1f} s] {message}", file=sys.stderr, flush=True)
    return log


def add_parallel_options(p: argparse.ArgumentParser) -> None:
    """``--workers`` and ``--scheduler`` of :mod:`physics.execution.parallel`."""
    p.add_argument("--workers", type=int, default=1,
                   help="local worker processes (1: in this process; results are identical for any count)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing Dask scheduler, e.g. tcp://host:8786 (default: $EAP_SCHEDULER if set)")


def parallel_settings(args):
    from physics.execution.parallel import ParallelSettings
    return ParallelSettings.resolve(args.workers, args.scheduler)


def check_out(args, inputs=()) -> None:
    """Refuse a bad ``--out`` before any work (see :func:`physics.io.outputs.preflight`)."""
    preflight(args.out, inputs=inputs, overwrite=getattr(args, "overwrite", False))


def reserving(args, inputs=()):
    """``with reserving(args, inputs):`` around a command whose ``--out`` is written by a library
    writer (``write_identification(res, args.out, overwrite=args.overwrite, inputs=inputs)``):
    a bad ``--out`` is refused before any work, with the writer's own checks and words, and a
    second run into it fails at once (:func:`physics.io.outputs.reserve`)."""
    return reserve(args.out, inputs=inputs, overwrite=getattr(args, "overwrite", False), flag=OUT_DIR)


def writing(args, inputs=()):
    """The output-folder context of a command that assembles its ``--out`` itself (no library
    writer owns that folder): ``with writing(args, inputs) as d:`` writes into a temporary
    folder ``d`` that replaces ``args.out`` when the block succeeds."""
    return output_folder(args.out, inputs=inputs, overwrite=getattr(args, "overwrite", False))


def check_result(deflection, model) -> None:
    """Refuse a simulated tip deflection [m] that is not finite or beyond the strip's length
    (an unstable user effect or a parameter out of its range), naming the effects."""
    import numpy as np

    from physics.errors import ModelError
    d = np.asarray(deflection)
    bad = np.flatnonzero(~np.isfinite(d))
    where = f"{model.device.name} [{', '.join(model.effect_ids)}]"
    if bad.size:
        raise ModelError(f"the simulation of {where} is not finite from sample {bad[0]} on (an unstable effect or "
                         "a parameter out of its range); nothing was written")
    length = float(model.free_length)
    peak = float(np.max(np.abs(d))) if d.size else 0.0
    if peak > length:
        raise ModelError(f"the simulation of {where} reaches a tip deflection of {peak:.3g} m, beyond the strip's "
                         f"free length ({length:.3g} m): not physics (an unstable effect or a parameter out of its "
                         "range); nothing was written")


def provenance(argv=None, inputs=()) -> dict:
    from physics._version import __version__
    out = {"package": "eap-model", "version": __version__, "python": platform.python_version(),
           "command": " ".join(["eap"] + (sys.argv[1:] if argv is None else list(argv)))}
    files = [p for p in map(Path, inputs) if p.is_file()]
    if files:
        from physics.io.fileio import sha256_file
        out["data_sha256"] = {p.name: sha256_file(p) for p in files}
    return out


def dumps(obj) -> str:
    return json.dumps(obj, indent=2)
