"""``eap predict``: run a saved model bundle on a voltage record (CSV) and write the prediction."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from physics.columns import quantity
from physics.errors import InputError, ModelError

from ._common import add_quiet_option, provenance, stage_log

NAME = "predict"
HELP = "predict the output of a trained model bundle (tip deflection, or the quantity it was trained on) for a record"
DESCRIPTION = (HELP + ". The input CSV follows DATA_FORMAT.md (time_s, voltage_V, optional rh_pct, optional "
               "measured output, e.g. deflection_m), or any file through --columns. The prediction is written as a "
               "time-series CSV whose output column is named after the model's output (deflection_m, level_V, ...); "
               "if the input carries the measured output, the fit is printed. A sampling rate other than the "
               "training rate is refused unless --resample is given; RH outside the trained range gives a warning.")


def add_arguments(p):
    p.add_argument("--model", required=True, help="model bundle folder (e.g. RUN/models/narx)")
    p.add_argument("--input", required=True, help="input time-series CSV (voltage, optional RH)")
    p.add_argument("--columns", default=None,
                   help="column map for other files, e.g. time=t,voltage=u (units as time=t:ms; the measured output "
                        "as output=y)")
    p.add_argument("--fs-Hz", type=float, default=None, help="sampling rate of a file without a time column")
    p.add_argument("--out", required=True, help="output CSV for the prediction (never the input file)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out CSV (and its sidecar) written by eap (never other files)")
    add_quiet_option(p)
    p.add_argument("--rh", type=float, default=None,
                   help="relative humidity [%%] when the file has no rh_pct column (wins over it)")
    p.add_argument("--resample", action="store_true",
                   help="allow a sampling rate different from the model's: resample in and out")
    p.add_argument("--init-samples", type=int, default=None,
                   help="free run: initialise the model from the first N measured outputs of the input file "
                        "(default: as many as the model uses when the file has a deflection column; 0: start "
                        "from rest)")
    p.add_argument("--steps-ahead", type=int, default=None,
                   help="k-step-ahead prediction from the measured deflection in the input "
                        "(default: free-run simulation)")


def _read(args, output, uses_rh: bool, need_y: bool):
    """The input record, and whether it carries a relative humidity."""
    from physics.timeseries import parse_column_map, read_timeseries

    columns = parse_column_map(args.columns, output) if args.columns else None
    kw = dict(columns=columns, fs=args.fs_Hz, require_deflection=need_y, output=output)
    try:
        return read_timeseries(args.input, rh=args.rh, **kw), True
    except InputError as exc:
        # a model without humidity input does not need RH: read with a placeholder, drop it
        if uses_rh or args.rh is not None or "relative humidity" not in str(exc):
            raise
    return read_timeseries(args.input, rh=0.0, **kw), False


def run(args) -> int:
    from physics.metrics import fit_percent, rmse
    from physics.outputs import output_files, preflight_files
    from physics.record import OutputQuantity
    from physics.timeseries import TimeSeries, write_timeseries

    log = stage_log(args, [args.input])
    if Path(args.out).suffix.lower() != ".csv":
        raise InputError(f"--out {args.out}: the prediction is written as CSV; give a path ending in .csv")
    preflight_files([args.out], overwrite=args.overwrite, inputs=[args.input, args.model])
    from ..bundle import load
    bundle = load(args.model)
    output = OutputQuantity.from_dict(bundle.card.get("output"), f"{args.model}: card output")
    uses_rh = bundle.model.uses_rh
    k = args.steps_ahead
    if k is not None and k < 1:
        raise InputError(f"--steps-ahead must be a positive integer, got {k}")
    n_init = args.init_samples
    if n_init is not None and n_init < 0:
        raise InputError(f"--init-samples {n_init}: must be 0 (start from rest) or a positive number of samples")
    if n_init and n_init < bundle.model.n_init_:
        raise InputError(f"--init-samples {n_init}: this model starts from its last {bundle.model.n_init_} "
                         "outputs; give at least that many, or 0 to start from rest")
    log(f"reading {args.input}")
    ts, rh_read = _read(args, output, uses_rh, need_y=k is not None or bool(n_init))
    log(f"predicting {ts.n:,} samples with {bundle.card['model']}")
    # free run: initialised from the first measured outputs when the file has them (honest start)
    init = ts.deflection if (k is None and n_init != 0) else None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pred = bundle.predict(ts.voltage, rh=ts.rh if uses_rh else None, fs=ts.fs, steps_ahead=k,
                              resample=args.resample, deflection=ts.deflection if k else init)
    notes = [str(w.message) for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
    for n in notes:
        print(f"eap predict: warning: {n}")
    out_unit = output.unit
    meta = dict(ts.meta)
    meta["prediction"] = {
        "model": bundle.card["model"], "bundle": str(args.model), "input": str(args.input),
        "output_unit_of_model": out_unit, "fs_hz_model": bundle.fs, "fs_hz_input": ts.fs,
        "resampled": bool(abs(ts.fs - bundle.fs) > 1e-4 * bundle.fs),
        "mode": "free run" if k is None else f"{k}-step-ahead", "warnings": notes,
        "initialised_from_measured_samples": (bundle.model.n_init_ if init is not None else 0) if k is None else None,
        "rh_range_trained_pct": bundle.rh_range, "provenance": provenance(),
    }
    line = (f"predicted {ts.n} samples at {ts.fs:g} Hz with {bundle.card['model']} "
            f"({'free run' if k is None else f'{k}-step-ahead'})")
    if not np.all(np.isfinite(pred)):
        i = int(np.flatnonzero(~np.isfinite(pred))[0])
        raise ModelError(f"{args.model}: the model's free run diverged on {args.input} (non-finite from sample {i}, "
                         f"t = {ts.time[i]:g} s); nothing was written — the input may lie outside what it was "
                         "trained on")
    if ts.deflection is not None:
        fit = {"rmse": rmse(ts.deflection, pred)}
        line += f"; against the measured {output.name}: RMSE {quantity(fit['rmse'], out_unit)}"
        try:
            fit["fit_percent"] = fit_percent(ts.deflection, pred)
            line += f", fit {fit['fit_percent']:.1f} %"
        except InputError:  # constant measured deflection: relative fit undefined
            pass
        meta["prediction"]["against_measured"] = fit
    out = TimeSeries(time=ts.time, voltage=ts.voltage, deflection=pred,
                     rh=ts.rh if (rh_read or uses_rh) else None, meta=meta, source=str(args.out), output=output)
    log(f"writing {args.out}")
    with output_files([args.out], overwrite=args.overwrite, inputs=[args.input, args.model]) as (tmp,):
        write_timeseries(out, tmp)
    print(f"{line}; wrote {args.out} ({output.column})")
    return 0
