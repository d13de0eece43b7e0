"""``eap dataset``: build a training dataset folder from measurement files (or check one)."""
from __future__ import annotations

from physics.errors import InputError
from physics.timeseries import parse_column_map

from ._common import add_output_options

NAME = "dataset"
HELP = "build a dataset folder (dataset.json + standard CSVs) from your measurement files, or --check one"
DESCRIPTION = (HELP + ". Files are read with the same rules as every command (DATA_FORMAT.md, --columns for "
               "other files); FILE[START:STOP] takes a sample range (e.g. the standard split of one long "
               "record). Without --validation files, train-compare holds out --val-fraction of each training "
               "record. The schema of dataset.json is in the README.")


def add_arguments(p):
    p.add_argument("--train", nargs="+", default=[], metavar="FILE", help="training records")
    p.add_argument("--validation", nargs="+", default=[], metavar="FILE", help="validation records (optional)")
    p.add_argument("--test", nargs="+", default=[], metavar="FILE", help="test records (optional)")
    p.add_argument("--val-fraction", type=float, default=0.2,
                   help="with no --validation: fraction at the end of each training record used for validation")
    p.add_argument("--holdout-rh", default="", help="RH levels [%%] held out of training, e.g. 50,70")
    p.add_argument("--columns", default=None, help="column map, e.g. voltage=V1,deflection=V2 (stored units)")
    p.add_argument("--fs-Hz", type=float, default=None, help="sampling rate of files without a time column")
    p.add_argument("--rh", type=float, default=None, help="relative humidity [%%] of files without one")
    p.add_argument("--resample", action="store_true", help="resample non-uniform time onto the median step")
    p.add_argument("--check", default=None, metavar="DS", help="re-verify the dataset folder DS and its sources")
    add_output_options(p, "runs/dataset", "dataset folder to create")


def run(args) -> int:
    from nnmodel.measured import build_dataset, check_dataset
    if args.check:
        notes = check_dataset(args.check)
        for n in notes:
            print(f"note: {n}")
        print(f"{args.check}: every file matches its SHA-256 in dataset.json")
        return 0
    if args.fs_Hz is not None and not args.fs_Hz > 0:
        raise InputError(f"--fs-Hz {args.fs_Hz!r}: must be a positive sampling rate")
    try:
        held = [float(x) for x in args.holdout_rh.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--holdout-rh {args.holdout_rh!r}: expected RH levels in %, e.g. 50,70") from None
    out = build_dataset(args.out, train=args.train, validation=args.validation, test=args.test,
                        val_fraction=args.val_fraction, holdout_rh=held,
                        columns=parse_column_map(args.columns) if args.columns else None, fs=args.fs_Hz,
                        rh=args.rh, resample=args.resample, overwrite=args.overwrite,
                        command="eap " + " ".join(__import__("sys").argv[1:]))
    from nnmodel.dataset import load_dataset
    ds = load_dataset(out)
    counts = {s: len(ds.entries(s)) for s in ("train", "validation", "test")}
    print(f"dataset {out}: {counts['train']} train / {counts['validation']} validation / {counts['test']} test "
          f"records at {ds.fs:g} Hz, {sum(e['samples'] for e in ds.meta['files'])} samples"
          + ("" if ds.has_rh else ", no relative humidity"))
    return 0
