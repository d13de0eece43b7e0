"""``eap compare``: a model (physics device or trained neural bundle) against measurements."""
from __future__ import annotations

import time
from pathlib import Path

from physics.compare import (CallablePredictor, FRFOptions, PhysicsPredictor, Predictor, compare,
                             load_measurements, parse_bands, write_comparison_report)
from physics.errors import InputError
from physics.io.record import DEFLECTION, OutputQuantity
from physics.io.timeseries import parse_column_map

from ._common import add_output_options, add_quiet_option, add_record_options, provenance, reserving, stage_log

NAME = "compare"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("model", "measurements")
#: takes --param (device parameters) although it has no --device option
TAKES_PARAMS = True
HELP = "compare a model (device or neural bundle) with measurements: metrics, Bode, overlays, HTML report"
DESCRIPTION = (HELP + ". MEASUREMENT files are time-series CSV/.mat files (docs/reference/file-formats.md) or frequency-"
               "response CSVs (freq_Hz, mag_m_per_V, phase_deg). Writes report.json, metrics.csv, bands.csv, "
               "by_rh.csv, PNGs and the page index.html into --out.")


# ------------------------------------------------------------------ shared with `eap identify`
def add_measurement_arguments(p) -> None:
    p.add_argument("measurements", nargs="+", metavar="MEASUREMENT",
                   help="time-series files (.csv/.mat) and/or frequency-response CSVs")
    p.add_argument("--rh", type=float, default=None,
                   help="relative humidity [%%] of the records: needed for files without an rh_pct column or "
                        "sidecar key, and overrides them when given")
    add_record_options(p)
    p.add_argument("--resample", action="store_true", help="resample non-uniform time onto the median step")


def add_frf_arguments(p) -> None:
    g = p.add_argument_group("frequency-response estimation")
    g.add_argument("--frf-method", choices=["auto", "welch", "periodic", "whole"], default="auto",
                   help="auto: from the record's excitation metadata (multisine periods, sweep), else Welch")
    g.add_argument("--nperseg", type=int, default=None, help="samples per segment (overrides the choice)")
    g.add_argument("--window", default=None, help="window (hann, boxcar, ...; overrides the choice)")
    g.add_argument("--band", default=None, help="frequency band f_lo,f_hi [Hz] (default: the excitation's)")
    g.add_argument("--points", type=int, default=400,
                   help="thin each estimate to about this many log-spaced frequencies (0: keep all)")
    g.add_argument("--min-coherence", type=float, default=0.0, help="ignore frequencies with lower coherence γ²")
    g.add_argument("--sensor-bandwidth-Hz", default="auto",
                   help="first-order sensor low-pass applied to the model: auto (from record metadata), none, "
                        "or a cut-off in Hz")
    g.add_argument("--rh-tolerance", type=float, default=1.0,
                   help="the hygrometer's tolerance [%%]: records whose RH differ by less than this form one RH "
                        "level, labelled by its nominal value (default 1)")


def frf_options(args) -> FRFOptions:
    band = None
    if args.band:
        try:
            lo, hi = (float(x) for x in args.band.split(","))
        except ValueError:
            raise InputError(f"--band {args.band!r}: expected f_lo,f_hi in Hz, e.g. 0.1,50") from None
        if not 0 <= lo < hi:
            raise InputError(f"--band {args.band!r}: need 0 <= f_lo < f_hi")
        band = (lo, hi)
    if args.points < 0:
        raise InputError("--points must be >= 0")
    if args.window is not None:
        from scipy.signal import get_window
        try:
            get_window(args.window, 16)
        except ValueError:
            raise InputError(f"--window {args.window!r}: not a window scipy knows; use e.g. hann, hamming, "
                             "blackman, boxcar, flattop") from None
    return FRFOptions(method=args.frf_method, nperseg=args.nperseg, window=args.window, band=band,
                      max_points=args.points)


def fit_options(args, **fit):
    """The measurement options of ``args`` (and the fit options ``fit``) as the one options
    object of identify and diagnose."""
    from physics.identify.options import FitOptions
    if not (args.rh_tolerance >= 0):
        raise InputError(f"--rh-tolerance {args.rh_tolerance!r}: must be a non-negative number of % RH")
    return FitOptions(rh=args.rh, rh_tolerance=args.rh_tolerance, frf=frf_options(args),
                      sensor_bandwidth=sensor_setting(args.sensor_bandwidth_Hz),
                      min_coherence=args.min_coherence, **fit)


def sensor_setting(text: str):
    t = str(text).strip().lower()
    if t in ("auto", "none"):
        return t
    try:
        return float(t)
    except ValueError:
        raise InputError(f"--sensor-bandwidth-Hz {text!r}: expected auto, none or a frequency in Hz") from None


def read_measurements(args, output: OutputQuantity | None = None) -> list:
    """The measurements of ``args`` (:func:`physics.compare.load_measurements`, which checks
    them); ``output``: what the model predicts (default: the tip deflection in m)."""
    want = output or DEFLECTION
    columns = parse_column_map(args.columns, want) if args.columns else None
    return load_measurements(args.measurements, rh=args.rh, columns=columns, fs=args.fs_Hz,
                             resample=args.resample, output=want, gain=getattr(args, "sensor_gain", None))


# ------------------------------------------------------------------ model resolution
def bundle_predictor(path: Path) -> Predictor:
    """Wrap a trained neural-model bundle folder into the common predictor interface."""
    try:
        import nnmodel
        loader = getattr(nnmodel, "load")
    except (ImportError, AttributeError):
        raise InputError(f"--model {path}: is a folder (a neural-model bundle?) but this installation has no "
                         "nnmodel.load to read bundles; give a device name or device YAML") from None
    bundle = loader(path)
    from nnmodel.startup import start_samples
    model = getattr(bundle, "model", None)      # a bundle of this package (others: only .predict)

    def run(voltage, rh, fs):
        return bundle.predict(voltage, rh=rh, fs=fs, resample=True)

    def run_record(ts, _rh):
        """The start-up rule (nnmodel.startup), as train-compare and predict run it: the
        record's own RH, the measured outputs of the start-up window."""
        return bundle.predict(ts.voltage, rh=ts.rh if model.uses_rh else None, fs=ts.fs, resample=True,
                              deflection=ts.deflection)

    card = getattr(bundle, "card", {}) or {}
    info = {"kind": "neural bundle", "path": str(path),
            **{k: card[k] for k in ("model", "fs_hz", "rh_range_pct", "inputs", "output") if k in card}}
    if model is None:
        return CallablePredictor(run, name=f"{card.get('model', 'bundle')} ({path.name})", info=info)
    return CallablePredictor(run, name=f"{card.get('model', 'bundle')} ({path.name})", info=info,
                             record_fn=run_record, start_samples=start_samples(model.n_init_), measured_output=True)


def resolve_predictor(spec: str, effects: str, n_modes: int = 4, hold: str = "cubic") -> Predictor:
    """A physics device (name or YAML) or a bundle folder → predictor."""
    p = Path(spec)
    if p.is_dir():
        return bundle_predictor(p)
    return PhysicsPredictor.from_device(spec, effects, n_modes=n_modes, hold=hold)


# ------------------------------------------------------------------ command
def add_arguments(p):
    add_measurement_arguments(p)
    p.add_argument("--model", required=True,
                   help="device name (configs/devices), device YAML, or a trained neural-model bundle folder")
    p.add_argument("--effects", default="default",
                   help="effects of a physics model: comma-separated ids or default/linear/all/none")
    p.add_argument("--n-modes", type=int, default=4, help="retained bending modes (physics model)")
    p.add_argument("--hold", choices=["cubic", "linear"], default="cubic",
                   help="input interpolation of the physics time solver (linear for square waves/steps)")
    p.add_argument("--offset", choices=["auto", "start", "mean", "none"], default="auto",
                   help="before the time metrics: start = a trained bundle's start-up rule (it starts from the "
                        "measured outputs of the record's first samples, which are not scored), mean = remove the "
                        "best constant offset, none = keep it; auto: start for a bundle, mean for a physics model")
    p.add_argument("--skip-s", type=float, default=0.0, help="exclude this start-up interval from time metrics [s]")
    p.add_argument("--bands", default=None, help="band edges [Hz] for errors by band, e.g. 0.1,1,10,50 "
                                                 "(default: decades)")
    add_frf_arguments(p)
    add_output_options(p, "runs/compare")
    add_quiet_option(p)


def _inputs(args) -> list:
    """Files a command reads (never to be replaced by its output folder)."""
    model = Path(args.model)
    return list(args.measurements) + ([model] if model.exists() else [])


def run(args) -> int:
    t0 = time.perf_counter()
    log = stage_log(args, args.measurements)
    with reserving(args, _inputs(args)):
        log(f"reading {len(args.measurements)} measurement file(s)")
        predictor = resolve_predictor(args.model, args.effects, args.n_modes, args.hold)
        output = OutputQuantity.from_dict(predictor.info.get("output"), f"{args.model}: output") \
            if isinstance(getattr(predictor, "info", None), dict) else DEFLECTION
        ms = read_measurements(args, output)
        offset = args.offset if args.offset != "auto" else ("start" if predictor.start_samples else "mean")
        res = compare(ms, predictor, frf_options=frf_options(args), offset=offset, skip_s=args.skip_s,
                      min_coherence=args.min_coherence, bands=parse_bands(args.bands) if args.bands else None,
                      rh_tolerance=args.rh_tolerance, sensor_bandwidth=sensor_setting(args.sensor_bandwidth_Hz),
                      log=log)
        log("writing the report")
        write_comparison_report(res, args.out, provenance=provenance(inputs=args.measurements),
                                title=f"eap compare: {predictor.name}", output=output, overwrite=args.overwrite,
                                inputs=_inputs(args))
    from physics.pages.columns import quantity
    d = Path(args.out)
    print(f"model: {predictor.name}")
    for r in res.records:
        tm, fe = r.summary.get("time_metrics"), r.summary["frf_metrics"]
        parts = [f"{Path(r.source).name} (RH {r.rh:.3g} %):"]
        if tm:
            rt = tm["residual_tests"]
            parts.append(f"fit {tm['fit_percent']:.1f} %, NRMSE {100 * tm['nrmse']:.3g} %, corr "
                         f"{100 * tm['correlation']:.1f} %, RMSE {quantity(tm['rmse'], output.unit)}; residual "
                         f"{'white' if rt['white'] else 'correlated'} ({rt['autocorrelation_outside']}/"
                         f"{rt['autocorrelation_lags']} lags outside 99 %), "
                         f"{'independent of' if rt['independent_of_input'] else 'correlated with'} the input "
                         f"({rt['cross_correlation_outside']}/{rt['cross_correlation_lags']});")
        if fe.get("j_err_m_per_V") is not None:
            parts.append(f"J_err {quantity(fe['j_err_m_per_V'], output.unit + '/V')}, |H| error {fe['log_mag_rms_dB']:.3g} dB rms, "
                         f"phase {fe['phase_rms_deg']:.3g} deg rms ({fe['n_points']} freq.)")
        print("  " + " ".join(parts))
    if len(res.by_rh) >= 2:
        print("  by RH: " + "; ".join(
            f"{row['rh_pct']:g} %: " + (f"fit {row['fit_percent']:.1f} %, " if row["fit_percent"] is not None else "")
            + (f"J_err {quantity(row['j_err_m_per_V'], output.unit + '/V')}" if row["j_err_m_per_V"] is not None
               else "")
            for row in res.by_rh))
    for w in res.warnings:
        print(f"  warning: {w}")
    print(f"wrote {d}/index.html, report.json, metrics.csv and plots in {time.perf_counter() - t0:.1f} s")
    return 0
