"""``eap dataset``: build a training dataset folder from measurement files (or check one)."""
from __future__ import annotations

import math

from physics.errors import InputError
from physics.io.record import OutputQuantity
from physics.io.timeseries import parse_column_map

from ._common import add_output_options, add_record_options

NAME = "dataset"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("train", "validation", "test", "check")
HELP = "build a dataset folder (dataset.json + standard CSVs) from your measurement files, or --check one"
DESCRIPTION = (HELP + ". Files are read with the same rules as every command (docs/reference/file-formats.md, --columns for "
               "other files); FILE[START:STOP] takes a sample range (e.g. the standard split of one long "
               "record); records that share samples are refused unless --allow-overlap. The output is the tip "
               "deflection in m unless --output NAME:UNIT (or a unit in --columns) says otherwise; it is checked "
               "against that quantity's plausible range here, once. Without --validation files, train-compare "
               "holds out --val-fraction of each training record. The schema of dataset.json is in the README.")


def add_arguments(p):
    p.add_argument("--train", nargs="+", default=[], metavar="FILE", help="training records")
    p.add_argument("--validation", nargs="+", default=[], metavar="FILE", help="validation records (optional)")
    p.add_argument("--test", nargs="+", default=[], metavar="FILE", help="test records (optional)")
    p.add_argument("--val-fraction", type=float, default=0.2,
                   help="with no --validation: fraction at the end of each training record used for validation")
    p.add_argument("--holdout-rh", default="", help="RH levels [%%] held out of training, e.g. 50,70")
    add_record_options(p)
    p.add_argument("--output", default=None, metavar="NAME:UNIT",
                   help="what the measured output is when it is not the tip deflection, e.g. level:V (its column "
                        "is NAME_UNIT in standard files, or mapped with --columns NAME=COLUMN)")
    p.add_argument("--allow-overlap", action="store_true",
                   help="keep records that share samples (the same file or overlapping ranges; marked in "
                        "dataset.json) instead of refusing them")
    p.add_argument("--rh", type=float, default=None, help="relative humidity [%%] of files without one")
    p.add_argument("--rh-tolerance", type=float, default=1.0,
                   help="the hygrometer's tolerance [%%]: training records whose RH differ by less form one RH level "
                        "(default 1, as eap diagnose and train-compare)")
    p.add_argument("--resample", action="store_true", help="resample non-uniform time onto the median step")
    p.add_argument("--check", default=None, metavar="DS", help="re-verify the dataset folder DS and its sources")
    add_output_options(p, "runs/dataset", "dataset folder to create")


def run(args) -> int:
    from nnmodel.measured import ReadOptions, build_dataset, check_dataset
    if args.check:
        notes = check_dataset(args.check)
        for n in notes:
            print(f"note: {n}")
        print(f"{args.check}: every file matches its SHA-256 in dataset.json")
        return 0
    if args.fs_Hz is not None and not args.fs_Hz > 0:
        raise InputError(f"--fs-Hz {args.fs_Hz!r}: must be a positive sampling rate")
    if not (math.isfinite(args.val_fraction) and 0.0 <= args.val_fraction < 0.9):
        raise InputError(f"--val-fraction {args.val_fraction!r}: must lie in [0, 0.9)")
    try:
        held = [float(x) for x in args.holdout_rh.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--holdout-rh {args.holdout_rh!r}: expected RH levels in %, e.g. 50,70") from None
    if not all(math.isfinite(h) and 0 <= h <= 100 for h in held):
        raise InputError(f"--holdout-rh {args.holdout_rh!r}: RH levels must lie within 0–100 %")
    if not (math.isfinite(args.rh_tolerance) and args.rh_tolerance >= 0):
        raise InputError(f"--rh-tolerance {args.rh_tolerance!r}: must be a non-negative number of % RH")
    output = OutputQuantity.parse(args.output) if args.output else None
    if output is not None and args.sensor_gain is not None and output.name != "deflection":
        raise InputError(f"--output {args.output} and --sensor-gain {args.sensor_gain} contradict each other: the "
                         f"gain turns the output into the tip deflection in m, --output keeps it as {output.name} "
                         f"in {output.unit}; give one of them")
    read = ReadOptions(columns=parse_column_map(args.columns, output) if args.columns else None, fs=args.fs_Hz,
                       rh=args.rh, resample=args.resample, gain=args.sensor_gain)
    out = build_dataset(args.out, train=args.train, validation=args.validation, test=args.test,
                        val_fraction=args.val_fraction, holdout_rh=held, read=read, output=output,
                        allow_overlap=args.allow_overlap, overwrite=args.overwrite, rh_tolerance=args.rh_tolerance,
                        command="eap " + " ".join(__import__("sys").argv[1:]))
    from nnmodel.dataset import load_dataset
    ds = load_dataset(out)
    counts = {s: len(ds.entries(s)) for s in ("train", "validation", "test")}
    floor = ds.meta.get("noise_floor_m")
    print(f"dataset {out}: {counts['train']} train / {counts['validation']} validation / {counts['test']} test "
          f"records at {ds.fs:g} Hz, {sum(e['samples'] for e in ds.meta['files'])} samples, output "
          f"{ds.output.label()}" + ("" if ds.has_rh else ", no relative humidity")
          + (f", sensor noise floor {1e6 * floor:.3g} µm" if floor else "")
          + (f"; {len(ds.meta['overlap'])} pair(s) of records share samples (--allow-overlap)"
             if ds.meta.get("overlap") else ""))
    return 0
