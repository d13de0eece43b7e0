"""``eap validate``: the reduced model against the reference PNP + solvent solver."""
from __future__ import annotations

from pathlib import Path

from physics.io.fileio import write_json
from physics.reference.validate import AMPLITUDES, DEVICES, run_validation

from ._common import add_output_options, check_out, provenance, writing

NAME = "validate"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device",)
HELP = "validation report: reduced model vs the full nonlinear PNP + solvent reference (plots, JSON, HTML)"
DESCRIPTION = (HELP + ". Small-signal FRF (criterion 1 % / 1° over 0.1–50 Hz), amplitude sweep 0.05–2 V with "
               "the amplitudes where the linear model's error passes 5 % and 20 % and the effect of the large-signal "
               "charge law, "
               "harmonic distortion, cation/solvent profiles at the thesis's snapshots (Fig. 13/15/17/30). "
               "A full run takes a few minutes.")


def add_arguments(p):
    p.add_argument("--device", action="append", default=None,
                   help=f"device name or YAML path (repeatable; default: {', '.join(DEVICES)})")
    p.add_argument("--amplitudes-V", type=float, nargs="+", default=list(AMPLITUDES),
                   help="sine amplitudes of the sweep [V]")
    p.add_argument("--quick", action="store_true", help="three amplitudes and no square pulse (smoke run)")
    add_output_options(p, "runs/validate", "report folder (PNG plots, figures.json, index.html)")


def run(args) -> int:
    check_out(args)
    with writing(args) as tmp:
        figs = run_validation(tmp, devices=tuple(args.device or DEVICES), amps=tuple(sorted(args.amplitudes_V)),
                              quick=args.quick)
        write_json(tmp / "provenance.json", provenance())
    d = Path(args.out)
    ok = all(figs[dev]["small_signal"]["max_mag_err_pct"] <= 1.0 and figs[dev]["small_signal"]["max_phase_err_deg"] <= 1.0
             for dev in figs["devices"])
    print(f"small-signal criterion (1 % / 1° over 0.1–50 Hz): {'met' if ok else 'NOT met'}; "
          f"wrote {d / 'index.html'}, {d / 'figures.json'} and the PNG plots")
    return 0 if ok else 1
