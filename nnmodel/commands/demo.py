"""``eap demo``: ``hidden-effect`` (a catalog effect hidden in synthetic measurements, then the
diagnosis) and ``missing-physics`` (creep, outside the catalog: the diagnosis says so and
describes it; the shipped example effect is added; the error falls)."""
from __future__ import annotations

import sys
from pathlib import Path

from physics.diagnose.demo import hidden_effects, run_hidden_effect
from physics.errors import InputError

from ._common import add_output_options, check_out, provenance, writing
from .diagnose import print_summary

NAME = "demo"
HELP = ("demonstrations: `eap demo hidden-effect` hides a physical effect in synthetic measurements and diagnoses "
        "it; `eap demo missing-physics` shows the loop with an effect outside the catalog")
SCENARIOS = ("hidden-effect", "missing-physics")
#: The example effect file the missing-physics demo adds (the recipe for users).
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "effects" / "creep.py"


def add_arguments(p):
    p.add_argument("scenario", choices=SCENARIOS, help="hidden-effect: measurements with an effect the model lacks; "
                   "missing-physics: creep, outside the catalog, then the example effect added")
    p.add_argument("--template", default=str(EXAMPLE), help="missing-physics: the effect file added in the second step")
    p.add_argument("--effect", default="random", help=f"the hidden effect: {', '.join(hidden_effects())}, none, or random")
    p.add_argument("--seed", type=int, default=0, help="seed of the random parameters, noise and choice")
    p.add_argument("--device", default="ipmc_pt_eg", help="device the measurements are simulated from")
    p.add_argument("--design", choices=["auto", "rich"], default="auto",
                   help="auto: the excitation that exposes the hidden effect; rich: sweeps at 3 RH levels and "
                        "2 amplitudes plus a square pulse, so every candidate is evaluated")
    p.add_argument("--duration-s", type=float, default=60.0, help="length of each record [s]")
    p.add_argument("--fs-Hz", type=float, default=500.0, help="sampling rate of the records [Hz]")
    add_output_options(p, "runs/demo_hidden_effect", "folder for the diagnosis report")


def run(args) -> int:
    if args.scenario == "missing-physics":
        return _missing_physics(args)
    eff = None if args.effect == "none" else args.effect
    if eff not in (None, "random") and eff not in hidden_effects():
        raise InputError(f"--effect {args.effect!r}: choose one of {', '.join(hidden_effects())}, none or random")
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
    print(f"report: {args.out}/index.html")
    return 0


def _missing_physics(args) -> int:
    """Creep records → diagnosis (not explained, described) → + the example effect → diagnosis."""
    from physics.diagnose.demo import outside_catalog_case
    from physics.diagnose.diagnosis import diagnose
    from physics.diagnose.report import write_diagnosis
    from physics.effects import effect_classes_in_file, register, unregister
    check_out(args)
    ms, tp = outside_catalog_case("creep", args.seed, device=args.device, fs=args.fs_Hz, duration=args.duration_s)
    print(f"truth (outside the catalog): tip load × (1 + r/(1+sτ)), r = {tp['creep_r']:.3g}, "
          f"τ = {tp['creep_tau_s']:.3g} s; user's model: {args.device} with effects 'none' (the bare double layer)")
    before = diagnose(ms, args.device, "none")
    print("\n1. the catalog alone:")
    print_summary(before)
    classes = effect_classes_in_file(args.template)
    ids = [register(c).id for c in classes]
    try:
        after = diagnose(ms, args.device, "none")
    finally:
        for i in ids:
            unregister(i)
    print(f"\n2. with {args.template} added (--effects-path):")
    print_summary(after)
    with writing(args) as tmp:
        write_diagnosis(before, tmp / "before", provenance={**provenance(), "truth": tp})
        write_diagnosis(after, tmp / "after", provenance={**provenance(), "truth": tp})
    w = after.winner
    print(f"\nloop: before {before.verdict.status} (RMS {1e6 * before.base.rmse:.3g} µm); after adding "
          f"{', '.join(ids)}: {after.verdict.status}" + (f", RMS {1e6 * w.fit.rmse:.3g} µm "
                                                          f"({w.fit.rmse / after.noise_floor:.2f}× the noise floor)"
                                                          if w else ""))
    print(f"reports: {args.out}/before/index.html, {args.out}/after/index.html")
    return 0
