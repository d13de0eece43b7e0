"""``eap simulate``: time-domain simulation of a device for a generated or given voltage record."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from physics import signals
from physics.errors import InputError
from physics.io.fileio import atomic_path, write_json
from physics.model import ActuatorModel
from physics.pages.plotting import plot_timeseries
from physics.solvers.timedomain import FIELDS, simulate
from physics.limits import FREQ_RANGE_HZ, FS_RANGE_HZ, MAX_DRIVE_V, MAX_SAMPLES, MAX_SAMPLES_X_RATE, check_range
from physics.io.timeseries import parse_column_map, read_timeseries, write_timeseries

from ._common import (add_model_options, add_output_options, add_record_options, check_out, check_result,
                      provenance, writing)

NAME = "simulate"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device", "input")
#: API argument → flag, where the flag's destination differs (InputError.render).
FLAGS = {"frequency": "--frequency-Hz", "f_start": "--f-start-Hz", "f_stop": "--f-stop-Hz", "fs": "--fs-Hz",
         "duration": "--duration-s", "amplitude": "--amplitude-V"}
HELP = "simulate tip deflection and current for a voltage signal; writes CSV + plots"


def add_arguments(p):
    add_model_options(p)
    p.add_argument("--signal", choices=sorted(signals.GENERATORS), default="sweep", help="excitation")
    p.add_argument("--input", default=None, help="read the voltage (and RH) from a time-series CSV instead")
    add_record_options(p, gain=False, fs=False)
    p.add_argument("--duration-s", type=float, default=100.0, help="record length [s]")
    p.add_argument("--fs-Hz", type=float, default=1000.0, help="sampling rate [Hz]")
    p.add_argument("--amplitude-V", type=float, default=2.0, help="amplitude (sweep, tone, square) [V]")
    p.add_argument("--rms-V", type=float, default=0.5, help="RMS (multisine, noise) [V]")
    p.add_argument("--f-start-Hz", type=float, default=0.1, help="lowest frequency (sweep, multisine, noise)")
    p.add_argument("--f-stop-Hz", type=float, default=50.0, help="highest frequency (sweep, multisine, noise)")
    p.add_argument("--frequency-Hz", type=float, default=1.0, help="tone frequency [Hz]")
    p.add_argument("--t-on-s", type=float, default=20.0, help="square: on time [s]")
    p.add_argument("--t-off-s", type=float, default=80.0, help="square: off time [s]")
    p.add_argument("--phases", choices=["random", "schroeder"], default="random", help="multisine phases")
    p.add_argument("--seed", type=int, default=0, help="seed of random signals")
    p.add_argument("--fields", default="", help=f"internal fields to save: {', '.join(FIELDS)}")
    p.add_argument("--hold", choices=["cubic", "linear"], default=None,
                   help="input interpolation between samples (default: linear for square/steps, else cubic)")
    add_output_options(p, "runs/simulate")


def make_signal(args) -> signals.Signal:
    for flag in ("duration_s", "fs_Hz", "amplitude_V", "rms_V", "f_start_Hz", "f_stop_Hz", "frequency_Hz",
                 "t_on_s", "t_off_s"):
        value = getattr(args, flag)
        if not np.isfinite(value) or value <= 0:
            raise InputError(f"--{flag.replace('_', '-')} {value!r}: must be a positive number")
    lo, hi = FS_RANGE_HZ
    check_range(args.fs_Hz, lo, hi, "--fs-Hz", "Hz")
    for flag in ("f_start_Hz", "f_stop_Hz", "frequency_Hz"):
        check_range(getattr(args, flag), *FREQ_RANGE_HZ, f"--{flag.replace('_', '-')}", "Hz")
    for flag in ("amplitude_V", "rms_V"):
        check_range(getattr(args, flag), 0.0, MAX_DRIVE_V, f"--{flag.replace('_', '-')}",
                    "V; the drive of a strip is a few volts")
    n = args.duration_s * args.fs_Hz
    if not 16 <= n <= MAX_SAMPLES:
        raise InputError(f"--duration-s {args.duration_s:g} × --fs-Hz {args.fs_Hz:g} = {n:.3g} samples; a record "
                         f"needs 16 to {MAX_SAMPLES:.3g} (split a longer run)")
    if n * args.fs_Hz > MAX_SAMPLES_X_RATE:
        raise InputError(f"--duration-s {args.duration_s:g} at --fs-Hz {args.fs_Hz:g}: {n:.3g} samples × "
                         f"{args.fs_Hz:g} Hz = {n * args.fs_Hz:.3g} exceeds {MAX_SAMPLES_X_RATE:.3g} (the simulator's "
                         "work per sample grows with the rate: its realisation resolves up to half the rate); "
                         f"simulate at most {MAX_SAMPLES_X_RATE / args.fs_Hz:.3g} samples at this rate, or lower "
                         "--fs-Hz")
    if args.f_start_Hz >= args.f_stop_Hz:
        raise InputError(f"--f-start-Hz {args.f_start_Hz:g} must be below --f-stop-Hz {args.f_stop_Hz:g}")
    k = args.signal
    if k == "sweep":
        return signals.sweep(args.amplitude_V, args.f_start_Hz, args.f_stop_Hz, args.duration_s, args.fs_Hz)
    if k == "tone":
        return signals.tone(args.amplitude_V, args.frequency_Hz, args.duration_s, args.fs_Hz)
    if k == "square":
        cycles = max(1, int(round(args.duration_s / (args.t_on_s + args.t_off_s))))
        return signals.square(args.amplitude_V, args.t_on_s, args.t_off_s, cycles, args.fs_Hz)
    if k == "steps":
        return signals.steps([args.duration_s / 10], [args.amplitude_V], args.duration_s, args.fs_Hz)
    if k == "multisine":
        return signals.multisine(args.rms_V, args.f_start_Hz, args.f_stop_Hz, args.duration_s, 1, args.fs_Hz,
                                 phases=args.phases, seed=args.seed)
    return signals.noise(args.rms_V, args.f_start_Hz, args.f_stop_Hz, args.duration_s, args.fs_Hz, args.seed)


def run(args) -> int:
    check_out(args, [args.input] if args.input else [])
    model = ActuatorModel(args.device, args.effects, n_modes=args.n_modes)
    fields = tuple(f.strip() for f in args.fields.split(",") if f.strip())
    if args.input:
        columns = parse_column_map(args.columns) if args.columns else None
        ts = read_timeseries(args.input, rh=args.rh, require_deflection=False, columns=columns)
        t, v, rh = ts.time - ts.time[0], ts.voltage, ts.rh
        if ts.n * ts.fs > MAX_SAMPLES_X_RATE:
            raise InputError(f"--input {args.input}: {ts.n} samples × {ts.fs:g} Hz = {ts.n * ts.fs:.3g} exceeds "
                             f"{MAX_SAMPLES_X_RATE:.3g} (the simulator's work per sample grows with the rate); "
                             f"split the record into parts of at most {MAX_SAMPLES_X_RATE / ts.fs:.3g} samples")
        sig_meta = {"kind": "file", "path": str(args.input)}
        hold = args.hold or "cubic"
    else:
        sig = make_signal(args)
        t, v, rh = sig.t, sig.v, args.rh
        sig_meta = sig.describe()
        hold = args.hold or ("linear" if args.signal in ("square", "steps") else "cubic")
    t0 = time.perf_counter()
    res = simulate(model, None, t, v, rh=rh, fields=fields, hold=hold, progress=True)
    elapsed = time.perf_counter() - t0
    check_result(res.deflection, model)
    ts = res.to_timeseries()
    ts.meta.update({"signal": sig_meta, "provenance": provenance()})
    with writing(args, inputs=[args.input] if args.input else []) as d:
        csv = write_timeseries(ts, d / "simulation.csv")   # into the new folder d: nothing there to protect
        plot_timeseries(res.time, {"voltage": (res.voltage, "V"), "deflection": (res.deflection * 1e3, "mm"),
                                   "current": (res.current * 1e3, "mA")}, d / "simulation.png",
                        title=f"{model.device.name}: {', '.join(model.effect_ids)}")
        if res.fields:
            with atomic_path(d / "fields.npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez_compressed(fh, z_m=res.z, time_s=res.time, **res.fields)
        summary = {"device": model.device.name, "effects": list(model.effect_ids), "signal": sig_meta,
                   "rh_pct_mean": float(np.mean(res.rh)), "samples": int(t.size), "fs_Hz": res.fs,
                   "deflection_peak_to_peak_m": float(np.ptp(res.deflection)),
                   "deflection_rms_m": float(np.std(res.deflection)),
                   "current_rms_A": float(np.std(res.current)), "runtime_s": elapsed,
                   "files": [csv.name, "simulation.png"] + (["fields.npz"] if res.fields else []),
                   "provenance": provenance()}
        write_json(d / "summary.json", summary)
    d = Path(args.out)
    print(f"simulated {t[-1] - t[0]:.3g} s at {res.fs:g} Hz in {elapsed:.2f} s; "
          f"deflection {1e3 * np.ptp(res.deflection):.3g} mm peak-to-peak; wrote {d}/")
    return 0
