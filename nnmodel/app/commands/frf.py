"""``eap frf``: closed-form small-signal frequency response of a device."""
from __future__ import annotations

import numpy as np

from physics.errors import InputError, ModelError
from physics.io.fileio import write_json
from physics.solvers.frequency import frequency_response
from physics.io.frfdata import FRFData, write_frf
from physics.limits import FREQ_RANGE_HZ, MAX_FREQUENCIES, MAX_GAIN_M_PER_V, check_count, check_range
from physics.io.outputs import output_files
from physics.pages.plotting import plot_bode

from ._common import add_model_options, provenance

NAME = "frf"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device",)
HELP = "frequency response (deflection/voltage, impedance, Cs_up) as JSON, CSV and a Bode plot"


def add_arguments(p):
    add_model_options(p)
    p.add_argument("--f-min-Hz", type=float, default=0.1, help="lowest frequency [Hz]")
    p.add_argument("--f-max-Hz", type=float, default=50.0, help="highest frequency [Hz]")
    p.add_argument("--points", type=int, default=500, help="log-spaced frequencies")
    p.add_argument("--json", default="frf.json", help="output JSON (frequency, magnitude, phase, ...)")
    p.add_argument("--csv", default=None, help="also write the FRF CSV of docs/reference/file-formats.md")
    p.add_argument("--plot", default=None, help="also write a Bode plot (PNG)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace existing --json/--csv/--plot files written by eap (never other files)")


def run(args) -> int:
    lo, hi = FREQ_RANGE_HZ
    for flag, value in (("--f-min-Hz", args.f_min_Hz), ("--f-max-Hz", args.f_max_Hz)):
        check_range(value, lo, hi, flag, "Hz; the response of a strip and its sensor")
    if not args.f_min_Hz < args.f_max_Hz or args.points < 2:
        raise InputError(f"--f-min-Hz {args.f_min_Hz:g} and --f-max-Hz {args.f_max_Hz:g} must be positive and "
                         f"increasing, with --points ≥ 2 (got {args.points})")
    check_count(args.points, 2, MAX_FREQUENCIES, "--points")
    if args.csv is not None and not args.csv.lower().endswith(".csv"):
        raise InputError(f"--csv {args.csv}: the FRF table is written as CSV; give a path ending in .csv")
    targets, flags = [args.json, args.csv, args.plot], ["--json", "--csv", "--plot"]
    with output_files(targets, overwrite=args.overwrite, flags=flags) as (json_tmp, csv_tmp, plot_tmp):
        f = np.logspace(np.log10(args.f_min_Hz), np.log10(args.f_max_Hz), args.points)
        fr = frequency_response(args.device, args.effects, f, rh=args.rh, n_modes=args.n_modes)
        where = f"the response of {fr.device} [{', '.join(fr.effects)}]"
        if not (np.all(np.isfinite(fr.deflection)) and np.all(np.isfinite(fr.impedance))):
            raise ModelError(f"{where} is not finite at some frequencies (an effect or a parameter out of its "
                             "range); nothing was written")
        peak = float(np.max(np.abs(fr.deflection)))
        if peak > MAX_GAIN_M_PER_V:
            raise ModelError(f"{where} reaches {peak:.3g} m/V, beyond {MAX_GAIN_M_PER_V:g} m/V: not a strip's "
                             "response (an effect or a parameter out of its range); nothing was written")
        out = fr.to_dict()
        out["provenance"] = provenance()
        write_json(json_tmp, out)
        if csv_tmp:
            write_frf(FRFData(freq=fr.freq, response=fr.deflection, rh=fr.rh,
                              meta={"device": fr.device, "effects": list(fr.effects)}), csv_tmp)
        if plot_tmp:
            plot_bode(fr.freq, {f"{fr.device} RH {fr.rh:g} %": fr.deflection}, plot_tmp,
                      title=", ".join(fr.effects))
    res = fr.resonance()
    peak = f", resonance {1e3 * res[1]:.3g} mm/V at {res[0]:.3g} Hz" if res else ", no resonance in range"
    print(f"{fr.device} [{', '.join(fr.effects)}] RH {fr.rh:g} %: {1e3 * fr.magnitude[0]:.3g} mm/V "
          f"at {fr.freq[0]:g} Hz{peak}; wrote {args.json}")
    return 0
