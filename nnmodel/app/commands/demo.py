"""``eap demo``: ``hidden-effect`` (a catalog effect hidden in synthetic measurements, then the
diagnosis) and ``missing-physics`` (physics outside the catalog: the diagnosis says so and
describes what remains; it is drafted as an effect file; diagnosed again, the error falls)."""
from __future__ import annotations

import sys

from physics.testbeds.demo import OUTSIDE, hidden_effects, run_hidden_effect
from physics.errors import InputError

from ._common import add_output_options, check_out, provenance, reserving, writing
from .diagnose import print_summary

NAME = "demo"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device",)
HELP = ("demonstrations: `eap demo hidden-effect` hides a physical effect in synthetic measurements and diagnoses "
        "it; `eap demo missing-physics` shows the loop with an effect outside the catalog")
SCENARIOS = ("hidden-effect", "missing-physics")


def add_arguments(p):
    p.add_argument("scenario", choices=SCENARIOS, help="hidden-effect: measurements with an effect the model lacks; "
                   "missing-physics: physics outside the catalog, described, drafted as an effect, diagnosed again")
    p.add_argument("--kind", default="creep", choices=OUTSIDE,
                   help="missing-physics: the physics outside the catalog in the records")
    p.add_argument("--effect", default="random", help=f"the hidden effect: {', '.join(hidden_effects())}, none, or random")
    p.add_argument("--seed", type=int, default=0, help="seed of the random parameters, noise and choice")
    p.add_argument("--device", default="ipmc_pt_eg", help="device the measurements are simulated from")
    p.add_argument("--design", choices=["auto", "rich"], default="auto",
                   help="auto: the excitation that exposes the hidden effect; rich: sweeps at 3 RH levels and "
                        "2 amplitudes plus a square pulse, so every candidate is evaluated")
    p.add_argument("--records", choices=["lab", "simulator"], default="lab",
                   help="missing-physics: the records as a lab exports them (tip in mm with 3 µm noise, an offset "
                        "and a drift, no excitation or sensor metadata) or as the simulator writes them")
    p.add_argument("--duration-s", type=float, default=60.0, help="length of each record [s]")
    p.add_argument("--fs-Hz", type=float, default=None,
                   help="sampling rate of the records [Hz] (default: 500; missing-physics 200)")
    add_output_options(p, "runs/demo_hidden_effect", "folder for the diagnosis report")


def run(args) -> int:
    if args.scenario == "missing-physics":
        return _missing_physics(args)
    eff = None if args.effect == "none" else args.effect
    if eff not in (None, "random") and eff not in hidden_effects():
        raise InputError(f"--effect {args.effect!r}: choose one of {', '.join(hidden_effects())}, none or random")
    log = lambda m: print(f"[diagnose] {m}", file=sys.stderr, flush=True)  # noqa: E731
    with reserving(args):
        case, res = run_hidden_effect(eff, args.seed, out=args.out, overwrite=args.overwrite, device=args.device,
                                      design=args.design, fs=args.fs_Hz or 500.0, duration=args.duration_s,
                                      progress=log)
    hidden = case.hidden
    tp = ", ".join(f"{k}={v:.4g}" for k, v in case.truth_params.items())
    print(f"hidden effect: {hidden or 'none'} (seed {args.seed}); truth parameters: {tp}")
    print(f"user's model: {case.device} [{', '.join(case.base_effects)}]; records: "
          f"{', '.join(m.source for m in case.measurements)} ({args.duration_s:g} s at {args.fs_Hz or 500.0:g} Hz, "
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
    """Records with physics outside the catalog → diagnosis (not explained; what remains) →
    drafted effect files → diagnosis with the drafts → the error before and after
    (:func:`physics.testbeds.demo.outside_loop`)."""
    from physics.testbeds.demo import outside_loop, outside_truth_text
    from physics.diagnose.report import write_diagnosis
    check_out(args)
    lab = args.records == "lab"
    with writing(args) as tmp:
        lp = outside_loop(args.kind, args.seed, tmp, device=args.device, fs=args.fs_Hz or 200.0,
                          duration=args.duration_s, lab=lab)
        print(f"truth (outside the catalog): {outside_truth_text(args.kind, lp.truth)}; records: "
              f"{', '.join(f'{args.out}/records/{f.name}' for f in lp.files)}"
              + (" (as a lab exports them: tip in mm, no excitation or sensor metadata)" if lab else "")
              + f"; user's model: {args.device} with effects 'none' (the bare double layer)")
        print("\n1. the catalog alone:")
        _final_summary(lp.before)
        print("\n2. what remains, drafted as effect files:")
        for line in lp.outcome.lines():
            print(f"draft: {line}")
        for name, problems in lp.checks.items():
            print(f"draft: {args.out}/drafts/{name}: contract check " + ("; ".join(problems) or "passed"))
        write_diagnosis(lp.before, tmp / "before", provenance={**provenance(), "truth": lp.truth})
        if lp.after is not None:
            print(f"\n3. the diagnosis again, with {', '.join(d.file_name for d in lp.outcome.kept)} (--effects-path):")
            _final_summary(lp.after)
            write_diagnosis(lp.after, tmp / "after", provenance={**provenance(), "truth": lp.truth})
    before, after = lp.before, lp.after or lp.before
    final = after.final.rmse
    kept = ", ".join(d.effect_id for d in lp.outcome.kept)
    print(f"\nloop: before {before.verdict.status} (RMS {1e6 * before.base.rmse:.3g} µm); "
          + (f"after adding {kept}: {after.verdict.status}, " if kept else "no draft kept: ")
          + f"RMS {1e6 * final:.3g} µm (the true model: {1e6 * lp.true_error:.3g} µm)")
    print(f"records: {args.out}/records/; drafts: {args.out}/drafts/; reports: {args.out}/before/index.html"
          + (f", {args.out}/after/index.html" if lp.after is not None else ""))
    return 0


def _final_summary(res) -> None:
    """:func:`print_summary` with the paths of records inside the output being written shown
    as their final paths."""
    import io
    from physics.io.outputs import final_text
    buf = io.StringIO()
    print_summary(res, file=buf)
    print(final_text(buf.getvalue()), end="")
