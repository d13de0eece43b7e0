"""``eap sweep``: the model over a grid of parameters / RH / amplitudes, as one tidy table."""
from __future__ import annotations

import time
from pathlib import Path

from physics.errors import InputError
from physics.io.outputs import output_files, preflight_files

from ._common import add_model_options, add_parallel_options, parallel_settings

NAME = "sweep"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device",)
HELP = "frequency response or simulation over a grid of device parameters, RH and amplitudes (CSV table)"
DESCRIPTION = (HELP + ". --grid NAME=VALUES (repeatable) with VALUES a,b,c or lin:a:b:n / log:a:b:n in the "
               "parameter's SI unit (see `eap effects`), rh in %, amplitude in V. Runs on --workers local "
               "processes or an existing Dask cluster (--scheduler / EAP_SCHEDULER).")


def add_arguments(p):
    add_model_options(p)
    p.add_argument("--grid", action="append", default=[], metavar="NAME=VALUES", help="a grid axis (repeatable)")
    p.add_argument("--kind", choices=["frf", "simulate"], default="frf",
                   help="frf: resonance and gains at --freqs-Hz; simulate: peak-to-peak of a sine response")
    p.add_argument("--freqs-Hz", default="0.1,1,10", help="frf: frequencies where gain and phase are tabulated")
    p.add_argument("--frequency-Hz", type=float, default=1.0, help="simulate: sine frequency")
    p.add_argument("--amplitude-V", type=float, default=1.0, help="simulate: sine amplitude (unless in the grid)")
    p.add_argument("--out", required=True, help="output table (.csv)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out table written by eap")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_parallel_options(p)


def run(args) -> int:
    from physics.solvers.sweep import SweepTone, parse_grid, run_sweep
    from physics.device import load_device
    out = Path(args.out)
    if out.suffix.lower() != ".csv":
        raise InputError(f"--out {out}: the sweep is written as a CSV table; give a path ending in .csv")
    preflight_files([out], overwrite=args.overwrite)
    try:
        freqs = [float(x) for x in args.freqs_Hz.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"--freqs-Hz {args.freqs_Hz!r}: expected frequencies in Hz, e.g. 0.1,1,10") from None
    if not freqs or min(freqs) <= 0:
        raise InputError(f"--freqs-Hz {args.freqs_Hz!r}: frequencies must be positive")
    grid = parse_grid(args.grid, load_device(args.device))
    t0 = time.perf_counter()
    table = run_sweep(args.device, args.effects, grid, kind=args.kind, rh=args.rh, freqs=freqs,
                      tone=SweepTone(frequency=args.frequency_Hz, amplitude=args.amplitude_V), n_modes=args.n_modes,
                      settings=parallel_settings(args), progress=not args.quiet)
    with output_files([out], overwrite=args.overwrite) as (tmp,):
        table.to_csv(tmp, index=False, lineterminator="\n")
    print(f"sweep of {len(table)} points ({' × '.join(f'{k} {len(v)}' for k, v in grid.items())}) in "
          f"{time.perf_counter() - t0:.1f} s; wrote {out}")
    return 0
