"""``eap demo hidden-effect``: synthetic measurements with an effect the model lacks, then the diagnosis."""
from __future__ import annotations

import sys

from physics.diagnose.demo import HIDDEN, run_hidden_effect
from physics.errors import InputError

from ._common import add_output_options, check_out, provenance, writing
from .diagnose import print_summary

NAME = "demo"
HELP = "demonstrations: `eap demo hidden-effect` hides a physical effect in synthetic measurements and diagnoses it"
SCENARIOS = ("hidden-effect",)


def add_arguments(p):
    p.add_argument("scenario", choices=SCENARIOS, help="hidden-effect: measurements with an effect the model lacks")
    p.add_argument("--effect", default="random", help=f"the hidden effect: {', '.join(HIDDEN)}, none, or random")
    p.add_argument("--seed", type=int, default=0, help="seed of the random parameters, noise and choice")
    p.add_argument("--device", default="ipmc_pt_eg", help="device the measurements are simulated from")
    p.add_argument("--design", choices=["auto", "rich"], default="auto",
                   help="auto: the excitation that exposes the hidden effect; rich: sweeps at 3 RH levels and "
                        "2 amplitudes plus a square pulse, so every candidate is evaluated")
    p.add_argument("--duration-s", type=float, default=60.0, help="length of each record [s]")
    p.add_argument("--fs-Hz", type=float, default=500.0, help="sampling rate of the records [Hz]")
    add_output_options(p, "runs/demo_hidden_effect", "folder for the diagnosis report")


def run(args) -> int:
    eff = None if args.effect == "none" else args.effect
    if eff not in (None, "random") and eff not in HIDDEN:
        raise InputError(f"--effect {args.effect!r}: choose one of {', '.join(HIDDEN)}, none or random")
    log = lambda m: print(f"[diagnose] {m}", file=sys.stderr, flush=True)  # noqa: E731
    check_out(args)
    with writing(args) as tmp:
        case, res = run_hidden_effect(eff, args.seed, out=tmp, device=args.device, design=args.design,
                                      fs=args.fs_Hz, duration=args.duration_s, progress=log)
    hidden = case.hidden
    tp = ", ".join(f"{k}={v:.4g}" for k, v in case.truth_params.items())
    print(f"hidden effect: {hidden or 'none'} (seed {args.seed}); truth parameters: {tp}")
    print(f"user's model: {case.device} [{', '.join(case.base_effects)}]; records: "
          f"{', '.join(m.source for m in case.measurements)} ({args.duration_s:g} s at {args.fs_Hz:g} Hz, "
          f"sensor noise floor {1e6 * case.noise_floor:.3g} µm)")
    print_summary(res)
    found = res.verdict.missing_effect
    top = res.best.effect if res.best else None
    ok = (found == hidden) if hidden else (found is None)
    print(f"result: hidden {hidden or 'none'}, ranked first {top}, verdict {found} -> "
          f"{'correct' if ok else 'NOT correct'}")
    print(f"report: {args.out}/report.html")
    _ = provenance
    return 0
