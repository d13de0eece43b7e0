"""``eap predict``: run a saved model bundle on a voltage record (CSV) and write the prediction."""
from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np

from physics.pages.columns import quantity
from physics.errors import InputError, InputNotice, ModelError
from physics.limits import MAX_STEPS_AHEAD, check_count

from ._common import add_quiet_option, add_record_options, provenance, stage_log

NAME = "predict"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("model", "input")
HELP = "predict the output of a trained model bundle (tip deflection, or the quantity it was trained on) for a record"
DESCRIPTION = (HELP + ". The input CSV follows docs/reference/file-formats.md (time_s, voltage_V, optional rh_pct, optional "
               "measured output, e.g. deflection_m), or any file through --columns. The prediction is written as a "
               "time-series CSV whose output column is named after the model's output (deflection_m, level_V, ...); "
               "if the input carries the measured output, the fit is printed. A sampling rate other than the "
               "training rate is refused unless --resample is given; RH outside the trained range gives a warning.")


def add_arguments(p):
    p.add_argument("--model", required=True, help="model bundle folder (e.g. RUN/models/narx)")
    p.add_argument("--input", required=True, help="input time-series CSV (voltage, optional RH)")
    add_record_options(p, gain=False)
    p.add_argument("--out", required=True, help="output CSV for the prediction (never the input file)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing --out CSV (and its sidecar) written by eap (never other files)")
    add_quiet_option(p)
    p.add_argument("--rh", type=float, default=None,
                   help="relative humidity [%%] when the file has no rh_pct column (wins over it)")
    p.add_argument("--resample", action="store_true",
                   help="allow a sampling rate different from the model's: resample in and out")
    p.add_argument("--init-samples", type=int, default=None,
                   help="free run: start the model from the first N measured outputs of the input file, which "
                        "the printed fit then skips (default, when the file has the measured output: the start-up "
                        "window max(50, the model's n_init), as train-compare and compare do; 0: start from rest)")
    p.add_argument("--steps-ahead", type=int, default=None,
                   help="k-step-ahead prediction from the measured deflection in the input "
                        "(default: free-run simulation)")


#: Samples per piece of a record predicted in pieces.
STREAM_SAMPLES = 1 << 18
#: Input files larger than this (about 10⁶ rows) are predicted in pieces when the model can
#: (a free run at the training rate): memory then grows with a piece, not with the record.
STREAM_BYTES = 40 << 20


def _pieces(args, output, uses_rh: bool, need_y: bool, stream: bool):
    """(the input record's pieces — one, or consecutive pieces of a long CSV —, whether it
    carries a relative humidity)."""
    from physics.io.timeseries import parse_column_map, read_timeseries, read_timeseries_pieces

    columns = parse_column_map(args.columns, output) if args.columns else None
    kw = dict(columns=columns, fs=args.fs_Hz, require_deflection=need_y, output=output)

    def read(rh):
        if stream:
            gen = read_timeseries_pieces(args.input, rows=STREAM_SAMPLES, rh=rh, **kw)
            first = next(gen)
            return itertools.chain([first], gen)
        return iter([read_timeseries(args.input, rh=rh, **kw)])
    try:
        return read(args.rh), True
    except InputError as exc:
        # a model without humidity input does not need RH: read with a placeholder, drop it
        if uses_rh or args.rh is not None or "relative humidity" not in str(exc):
            raise
    return read(0.0), False


class _Fit:
    """RMSE and fit % of a prediction against a measured output, accumulated piece by piece
    (the values of :func:`physics.analysis.metrics.rmse` and :func:`~physics.analysis.metrics.fit_percent`)
    after the first ``skip`` samples (the measured outputs the model was started from)."""

    def __init__(self, skip: int = 0):
        self.n, self.sy, self.syy, self.see = 0, 0.0, 0.0, 0.0
        self.skip = int(skip)

    def add(self, y, yhat) -> None:
        cut = min(self.skip, y.size)
        self.skip -= cut
        y, yhat = y[cut:], yhat[cut:]
        e = y - yhat
        self.n += y.size
        self.sy += float(np.sum(y))
        self.syy += float(np.dot(y, y))
        self.see += float(np.dot(e, e))

    def result(self) -> dict:
        out = {"rmse": float(np.sqrt(self.see / self.n)), "samples": self.n}
        spread = self.syy - self.sy ** 2 / self.n
        if spread > 1e-24 * max(self.syy, 1e-300):   # a constant measured output: relative fit undefined
            out["fit_percent"] = 100.0 * (1.0 - float(np.sqrt(self.see / spread)))
        return out


def _streams(args, bundle, k, size: int) -> bool:
    """Whether the record is predicted in pieces: a long CSV, free run, a model that
    continues from its state (see :attr:`nnmodel.models.base.NeuralModel.streams`)."""
    return (k is None and not args.resample and Path(args.input).suffix.lower() == ".csv"
            and size > STREAM_BYTES and getattr(bundle.model, "streams", False))


def run(args) -> int:
    from physics.io.outputs import preflight_files
    from physics.io.record import OutputQuantity

    log = stage_log(args, [args.input])
    if Path(args.out).suffix.lower() != ".csv":
        raise InputError(f"--out {args.out}: the prediction is written as CSV; give a path ending in .csv")
    preflight_files([args.out], overwrite=args.overwrite, inputs=[args.input, args.model])
    from ...bundle import load
    bundle = load(args.model)
    output = OutputQuantity.from_dict(bundle.card.get("output"), f"{args.model}: card output")
    model, uses_rh = bundle.model, bundle.model.uses_rh
    k, n_init = _check_counts(args, model)
    stream = Path(args.input).is_file() and _streams(args, bundle, k, Path(args.input).stat().st_size)
    log(f"reading {args.input}" + (" in pieces" if stream else ""))
    pieces, rh_read = _pieces(args, output, uses_rh, need_y=k is not None or bool(n_init), stream=stream)
    first = next(pieces)
    if k is not None and k > first.n:
        raise InputError(f"--steps-ahead {k}: {args.input} has {first.n} samples; give at most {first.n} (or omit "
                         "the flag for a free run)")
    pieces = itertools.chain([first], pieces)
    init, used = _initial_outputs(args, first, k, n_init, model)
    predicted = _predictions(args, bundle, pieces, first, k, init, used, stream)
    log(f"predicting with {bundle.card['model']} and writing {args.out}")
    n, fit, notes = _write(args, bundle, output, predicted, first, k, used, stream, rh_read)
    for note in notes:
        print(f"eap predict: warning: {note}")
    line = (f"predicted {n} samples at {first.fs:g} Hz with {bundle.card['model']} "
            f"({'free run' if k is None else f'{k}-step-ahead'})")
    if fit.n:
        res = fit.result()
        line += (f"; against the measured {output.name}" + (f" after the first {used} samples" if used else "")
                 + f": RMSE {quantity(res['rmse'], output.unit)}")
        line += f", fit {res['fit_percent']:.1f} %" if "fit_percent" in res else ""
    print(f"{line}; wrote {args.out} ({output.column})")
    return 0


def _check_counts(args, model) -> tuple[int | None, int | None]:
    """``--steps-ahead`` and ``--init-samples``, checked against the model."""
    k = args.steps_ahead
    if k is not None:
        check_count(k, 1, MAX_STEPS_AHEAD, "--steps-ahead", "samples; beyond a few hundred a prediction is a free "
                    "run — omit the flag for one")
    n_init = args.init_samples
    if n_init is not None and n_init < 0:
        raise InputError(f"--init-samples {n_init}: must be 0 (start from rest) or a positive number of samples")
    if n_init and n_init < model.n_init_:
        raise InputError(f"--init-samples {n_init}: this model starts from its last {model.n_init_} "
                         "outputs; give at least that many, or 0 to start from rest")
    return k, n_init


def _initial_outputs(args, first, k, n_init, model):
    """(the measured outputs a free run starts from, or None; how many samples the fit skips).
    A free run starts from the first measured outputs when the file has them (nnmodel.startup)."""
    from ...startup import start_samples
    init = first.deflection if (k is None and n_init != 0) else None
    used = 0 if init is None else (n_init or start_samples(model.n_init_))
    if init is not None and used >= init.size:
        raise InputError(f"{args.input}: {init.size} samples; the model starts from the first {used} measured outputs "
                         "(--init-samples), so the record must be longer")
    if n_init and init is not None:
        init = init[:used]
    return init, used


def _predictions(args, bundle, pieces, first, k, init, used, stream):
    """(piece, prediction) pairs: a long record in pieces through the model's state, else whole."""
    from ...bundle import FS_RTOL
    model, uses_rh = bundle.model, bundle.model.uses_rh
    if stream:
        if abs(first.fs - bundle.fs) > FS_RTOL * bundle.fs:
            raise InputError(f"the input is sampled at {first.fs:g} Hz but the model was trained at {bundle.fs:g} Hz; "
                             "resample the input, or pass --resample")
        a, b = itertools.tee(pieces)
        y0 = None if init is None else init[:used]
        return zip(a, model.simulate_pieces(((ts.voltage, ts.rh if uses_rh else None) for ts in b), y0))
    return ((ts, bundle.predict(ts.voltage, rh=ts.rh if uses_rh else None, fs=ts.fs, steps_ahead=k,
                                resample=args.resample, deflection=ts.deflection if k else init))
            for ts in pieces)


def _write(args, bundle, output, predicted, first, k, used, stream, rh_read):
    """Write the prediction and its sidecar (atomically, piece by piece); re-issue the notes on
    the user's input.  Returns (samples written, the fit against the measured output, warnings)."""
    from physics.io.csvtable import append_rows, write_sidecar
    from physics.io.outputs import output_files
    from physics.io.timeseries import columns_of
    uses_rh = bundle.model.uses_rh
    fit, n, meta = _Fit(used if k is None else 0), 0, dict(first.meta)
    with warnings.catch_warnings(record=True) as caught, \
            output_files([args.out], overwrite=args.overwrite, inputs=[args.input, args.model]) as (tmp,):
        warnings.simplefilter("always")
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            for ts, pred in predicted:
                bad = np.flatnonzero(~np.isfinite(pred))
                if bad.size:
                    raise ModelError(f"{args.model}: the model's free run diverged on {args.input} (non-finite from "
                                     f"t = {ts.time[bad[0]]:g} s); nothing was written — the input may lie outside "
                                     "what it was trained on")
                if ts.deflection is not None:
                    fit.add(ts.deflection, pred)
                cols = columns_of(type(ts)(time=ts.time, voltage=ts.voltage, deflection=pred, output=output,
                                           rh=ts.rh if (rh_read or uses_rh) else None, source=str(args.out)))
                append_rows(fh, cols, header=n == 0)
                n += ts.n
        notes = list(dict.fromkeys(str(w.message) for w in caught
                                   if issubclass(w.category, (RuntimeWarning, UserWarning))
                                   and not issubclass(w.category, InputNotice)))
        meta["prediction"] = {
            "model": bundle.card["model"], "bundle": str(args.model), "input": str(args.input),
            "output_unit_of_model": output.unit, "fs_hz_model": bundle.fs, "fs_hz_input": first.fs,
            "resampled": bool(abs(first.fs - bundle.fs) > 1e-4 * bundle.fs),
            "mode": "free run" if k is None else f"{k}-step-ahead", "warnings": notes,
            "initialised_from_measured_samples": used if k is None else None,
            "rh_range_trained_pct": bundle.rh_range, "in_pieces": stream, "provenance": provenance()}
        if fit.n:
            meta["prediction"]["against_measured"] = fit.result()
        write_sidecar(meta, tmp.with_suffix(".yaml"))
    for w in caught:          # notes on the user's input and folders (e.g. a folder left in place): said as notes
        if issubclass(w.category, InputNotice):
            warnings.warn(w.message)
    return n, fit, notes
