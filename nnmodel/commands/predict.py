"""``eap predict``: run a saved model bundle on a voltage record (CSV) and write the prediction."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from physics.columns import quantity
from physics.errors import InputError

from ._common import add_quiet_option, provenance, stage_log

NAME = "predict"
HELP = "predict tip deflection with a trained model bundle for a voltage (+RH) record"
DESCRIPTION = (HELP + ". The input CSV follows DATA_FORMAT.md (time_s, voltage_V, optional rh_pct, "
               "optional deflection_m). The prediction is written as a time-series CSV whose "
               "deflection column is the model output; if the input carries a measured deflection, "
               "the fit is printed. A sampling rate other than the training rate is refused unless "
               "--resample is given; RH outside the trained range gives a warning.")


def add_arguments(p):
    p.add_argument("--model", required=True, help="model bundle folder (e.g. RUN/models/narx)")
    p.add_argument("--input", required=True, help="input time-series CSV (voltage, optional RH)")
    p.add_argument("--out", required=True, help="output CSV for the prediction (never the input file)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out CSV (and its sidecar)")
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


def _read(path, rh, uses_rh: bool, need_y: bool):
    from physics.timeseries import read_timeseries

    try:
        return read_timeseries(path, rh=rh, require_deflection=need_y), True
    except InputError as exc:
        # a model without humidity input does not need RH: read with a placeholder, drop it
        if uses_rh or rh is not None or "relative humidity" not in str(exc):
            raise
    return read_timeseries(path, rh=0.0, require_deflection=need_y), False


def _check_out(args) -> None:
    """Refuse a bad ``--out`` before any work."""
    out, inp = Path(args.out), Path(args.input)
    if out.suffix.lower() != ".csv":
        raise InputError(f"--out {out}: the prediction is written as CSV; give a path ending in .csv")
    for p in (out, out.with_suffix(".yaml")):
        if p.resolve() in (inp.resolve(), inp.with_suffix(".yaml").resolve()):
            raise InputError(f"--out {out} would overwrite the input {p}; choose another --out")
        if p.exists() and not args.overwrite:
            raise InputError(f"--out: {p} already exists; choose another --out or pass --overwrite")


def run(args) -> int:
    from physics.timeseries import TimeSeries, write_timeseries
    from physics.metrics import fit_percent, rmse

    from ..bundle import load

    log = stage_log(args, [args.input])
    _check_out(args)
    bundle = load(args.model)
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
    ts, rh_read = _read(args.input, args.rh, uses_rh, need_y=k is not None or bool(n_init))
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
    out_unit = bundle.card.get("output", {}).get("unit", "m")
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
        raise InputError("the model produced non-finite values for this input (diverged)")
    if ts.deflection is not None:
        fit = {"rmse": rmse(ts.deflection, pred)}
        line += f"; against the measured deflection: RMSE {quantity(fit['rmse'], out_unit)}"
        try:
            fit["fit_percent"] = fit_percent(ts.deflection, pred)
            line += f", fit {fit['fit_percent']:.1f} %"
        except InputError:  # constant measured deflection: relative fit undefined
            pass
        meta["prediction"]["against_measured"] = fit
    out = TimeSeries(time=ts.time, voltage=ts.voltage, deflection=pred,
                     rh=ts.rh if (rh_read or uses_rh) else None, meta=meta, source=str(args.out))
    log(f"writing {args.out}")
    path = write_timeseries(out, args.out, overwrite=args.overwrite, protect=(args.input,))
    print(f"{line}; wrote {path}")
    return 0
