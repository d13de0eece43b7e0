"""``eap identify``: identify device parameters from measurements; writes the fitted device file."""
from __future__ import annotations

import warnings
from pathlib import Path

from physics.errors import InputError
from physics.identify import IdentifiabilityWarning, LsqOptions, identify, write_identification
from physics.limits import MAX_STARTS, check_count
from physics.io.outputs import component

from ._common import add_output_options, add_parallel_options, parallel_settings, provenance, reserving
from .compare import add_frf_arguments, add_measurement_arguments, fit_options, read_measurements

NAME = "identify"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device", "measurements")
#: API argument → flag, where the flag's destination differs (InputError.render).
FLAGS = {"n_starts": "--starts"}
HELP = "identify device parameters from measurements (least squares or the thesis Nelder-Mead); writes a device YAML"
DESCRIPTION = (HELP + ". Writes NAME.yaml (a device file with the identified values, their units and sources), "
               "report.json, parameters.csv, Bode/correlation PNGs and the page index.html into --out.")


def add_arguments(p):
    add_measurement_arguments(p)
    p.add_argument("--device", default="ipmc_pt_eg", help="start device: name in configs/devices or a YAML path")
    p.add_argument("--effects", default="default",
                   help="comma-separated effect ids, or default / linear / all / none (see `eap effects`)")
    p.add_argument("--n-modes", type=int, default=4, help="retained bending modes")
    p.add_argument("--free", default="", help="parameters shared by all records, e.g. kf,beta_f")
    p.add_argument("--per-rh", default="",
                   help="parameters fitted once per RH level (Table V style humidity map), e.g. Y,kf")
    p.add_argument("--method", choices=["lsq", "nelder-mead", "both"], default="lsq",
                   help="lsq: bounded least squares on the complex FRF (default); nelder-mead: the thesis "
                        "procedure on J_err (eq. 13, tol 1e-6, 100 iterations); both: report both")
    p.add_argument("--residual", choices=["frf", "time", "both"], default="frf",
                   help="least-squares residual: complex log FRF, time record, or both")
    p.add_argument("--starts", type=int, default=None, help="multi-start count (None: 5 for FRF residuals, 1 with time residuals)")
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start points")
    p.add_argument("--start", default=None, help="start values, e.g. kf=0.004,Y=0.2 GPa (SI if no unit)")
    p.add_argument("--bounds", default=None, help="search ranges, e.g. kf=1e-4:1e-1,Y=0.05:2 GPa")
    p.add_argument("--start-spread", type=float, default=1.0,
                   help="multi-start points within this many decades of the start (log parameters)")
    p.add_argument("--no-phase", action="store_true", help="fit log-magnitudes only (least squares)")
    p.add_argument("--weighting", choices=["coherence", "uniform"], default="coherence",
                   help="weights of the FRF residuals: 1/random error from the coherence, or uniform")
    p.add_argument("--skip-s", type=float, default=0.0, help="time residuals: skip this start-up interval [s]")
    add_frf_arguments(p)
    add_parallel_options(p)
    p.add_argument("--name", default=None, help="name of the fitted device and its file NAME.yaml (default: DEVICE_identified)")
    add_output_options(p, "runs/identify")


def run(args) -> int:
    if not args.free.strip() and not args.per_rh.strip():
        raise InputError("name the parameters to identify with --free (and/or --per-rh), e.g. --free kf,beta_f")
    if args.name is not None:
        component(args.name, "--name", "the device file NAME.yaml")
    if args.starts is not None:
        check_count(args.starts, 1, MAX_STARTS, "--starts", "multi-start fits")
    protect = list(args.measurements) + ([args.device] if Path(args.device).suffix in (".yaml", ".yml") else [])
    with reserving(args, protect):
        ms = read_measurements(args)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentifiabilityWarning)  # printed below from the result
            opts = fit_options(args, free=args.free, per_rh=args.per_rh, start=args.start, bounds=args.bounds,
                               n_starts=args.starts, seed=args.seed, n_modes=args.n_modes, weighting=args.weighting,
                               settings=parallel_settings(args))
            res = identify(ms, args.device, args.effects, options=opts, method=args.method, residual=args.residual,
                           fit_phase=not args.no_phase, skip_s=args.skip_s,
                           lsq=LsqOptions(start_spread=args.start_spread))
        out = write_identification(res, args.out, name=args.name, provenance=provenance(inputs=protect),
                                   overwrite=args.overwrite, inputs=protect)
    d = Path(args.out)
    prob = res.problem
    print(f"{prob.device.name} [{', '.join(prob.effects)}] from {len(res.sources)} measurement(s), "
          f"{sum(t.freq.size for t in prob.targets)} frequencies, RH levels {', '.join(f'{x:g}' for x in prob.levels)} %")
    chk = res.check
    for name, f in res.fits.items():
        mark = (" (start values kept)" if res.kept_start else " (written)") if name == res.primary else ""
        crit = (f"criterion ({f.residual_kind}) {chk['cost_start']:.4g} -> {f.cost:.4g}; "
                if name == res.primary and chk.get("cost_start") is not None else "")
        print(f"method {name}{mark}: {crit}J_err (eq. 13) {1e3 * res.j_err_initial:.4g} -> {1e3 * f.j_err:.4g} mm/V, "
              f"{f.nfev} model evaluations" + (f", {f.nit} iterations" if f.nit is not None else "")
              + f", {f.wall_s:.2f} s; {f.message}")
    if chk.get("time_rmse_start_m") is not None:
        print(f"time records: RMS error {1e6 * chk['time_rmse_start_m']:.4g} µm at the start -> "
              f"{1e6 * chk['time_rmse_fitted_m']:.4g} µm fitted (offset and linear drift of each record removed)")
        for r in res.param_rows(f):
            print(f"  {r['parameter']:16s} = {r['value']:.6g} ± {r['std_error']:.3g} {r['unit']} "
                  f"({100 * r['rel_std_error']:.3g} %), 95 % [{r['ci95_lo']:.4g}, {r['ci95_hi']:.4g}]"
                  f"  (start {r['initial']:.4g})")
    for w in res.warnings:
        print(f"  warning: {w}")
    for n in res.settings.get("notes", []):
        print(f"  note: {n}")
    print(f"total {res.wall_s:.2f} s, {res.n_evaluations} model evaluations "
          f"(thesis loop for these data: {res.thesis_equivalent_s() / 86400:.3g} days)")
    print(f"wrote {d / out['device_written']}, {d}/index.html, report.json, parameters.csv")
    return 0
