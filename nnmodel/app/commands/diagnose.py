"""``eap diagnose``: where a model fails, which physical effect is missing, add it, watch the error fall."""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from physics.diagnose import AnalysisOptions, SelectionOptions, diagnose, write_diagnosis
from physics.diagnose.draft import write_drafts
from physics.diagnose.verdict import nuisance_summary
from physics.errors import InputError
from physics.limits import FS_RANGE_HZ, MAX_STARTS, check_count, check_range
from physics.io.outputs import component, preflight, separate

from ._common import add_output_options, add_parallel_options, parallel_settings, provenance, reserving
from .compare import add_frf_arguments, add_measurement_arguments, fit_options, read_measurements

NAME = "diagnose"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ("device", "measurements")
#: API argument → flag, where the flag's destination differs (InputError.render).
FLAGS = {"n_starts": "--starts", "noise_floor": "--noise-floor-um", "fs_max": "--fs-max-Hz"}
HELP = "diagnose a model against measurements: where it fails, which effect is missing (ranked, with statistics)"
DESCRIPTION = (HELP + ". MEASUREMENT files are time-series records (docs/reference/file-formats.md): several records may differ "
               "in signal, amplitude and RH. Writes diagnosis.json, PNGs and the page index.html into --out; --apply also "
               "writes the extended device file (fitted values, the missing effect added to its effect list).")


def add_arguments(p):
    add_measurement_arguments(p)
    p.add_argument("--device", default="ipmc_pt_eg", help="device: name in configs/devices or a YAML path")
    p.add_argument("--effects", default="default",
                   help="the model's effects: comma-separated ids, or default / linear / all / none (see `eap effects`)")
    p.add_argument("--free", default="",
                   help="the model's free parameters (default: the coupling gain and the stiffness, each as the model's "
                        "effects name it, and beta_f)")
    p.add_argument("--per-rh", default="auto",
                   help="model parameters fitted once per RH level (as eap identify --per-rh, e.g. Y,kf); auto "
                        "(default): with records at two or more RH levels, those the model's humidity law declares; "
                        "none: no per-RH parameter")
    p.add_argument("--candidates", default="default",
                   help="effects to try: comma-separated ids (default: every effect with a diagnosis spec that the "
                        "model lacks, catalog and --effects-path, except those tried only on request)")
    p.add_argument("--force", action="store_true", help="also try effects the data cannot reveal (flagged as such)")
    p.add_argument("--max-effects", type=int, default=2,
                   help="longest chain of missing effects: after a pick the remaining candidates are tried again on "
                        "top of it while one passes (default 2)")
    p.add_argument("--forward-only", action="store_true",
                   help="do not try removing effects of the model the data do not support (by default the selection "
                        "runs both ways: a removed effect is tried again with its own parameters free)")
    p.add_argument("--no-support", action="store_true", help="skip checking that the data support the model's own effects")
    p.add_argument("--start", default=None, help="start values of the free parameters, e.g. kf=0.004,Y=0.2 GPa")
    p.add_argument("--bounds", default=None, help="search ranges, e.g. kf=1e-4:1e-1")
    p.add_argument("--starts", type=int, default=4, help="multi-start count of each fit")
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start points")
    p.add_argument("--n-modes", type=int, default=4, help="retained bending modes")
    p.add_argument("--noise-floor-um", type=float, default=None,
                   help="deflection noise floor [µm] (default: from the records' sensor metadata, else estimated)")
    p.add_argument("--fs-max-Hz", type=float, default=None,
                   help="cap on the analysis sampling rate (default: ≥ 5× the highest excited frequency)")
    add_frf_arguments(p)
    add_output_options(p, "runs/diagnose")
    add_parallel_options(p)
    p.add_argument("--apply", action="store_true",
                   help="(the default) write the best model's device file NAME.yaml into --out")
    p.add_argument("--no-apply", action="store_true", help="do not write the best model's device file")
    p.add_argument("--name", default=None, help="name of the best model's device (default: DEVICE_EFFECTS)")
    p.add_argument("--draft-effects", default=None, metavar="DIR",
                   help="where drafted effects go (default: OUT/drafts): when the model is not adequate, what remains "
                        "is drafted as effect files, fitted with the model and kept when they lower the error")
    p.add_argument("--no-draft", action="store_true", help="do not draft effects for what the catalog leaves")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def print_summary(res, file=None) -> None:
    """The diagnosis on the terminal: the base, where it fails, the ranking of each step and
    the verdict (the same text as the page and diagnosis.json)."""
    file = file or sys.stdout
    b = res.base
    nf = f"{1e6 * res.noise_floor:.3g} µm" if math.isfinite(res.noise_floor) else "unknown"
    print(f"base {res.device.name} [{', '.join(b.effects)}], free {', '.join(b.spec.free + b.spec.per_rh)}: "
          f"RMS error {1e6 * b.rmse:.4g} µm, fit {b.fit_pct:.2f} % (noise floor {nf})", file=file)
    print("where it fails:", file=file)
    for f in res.analysis_base.findings:
        print(f"  - {f}", file=file)
    prev = None
    for s in res.steps:
        if s.kind != "add":         # a backward or refit step: what it did, in one line
            print(f"step {s.index}: " + (s.decision.reason if s.kind == "refit" else
                                         f"{s.removal.effect} {'withdrawn' if s.withdrawn else 'removed'} "
                                         f"({s.removal.explanation})"), file=file)
            prev = s
            continue
        on = "" if prev is None else (" on top of the model with its own effects refitted" if prev.kind == "refit"
                                      else f" without {prev.removal.effect}" if prev.removal is not None
                                      else f" on top of {s.base.effects[-1]}")
        prev = s
        print(f"step {s.index}: candidates{on}, most to least supported:", file=file)
        print(f"  {'effect':22s} {'weight':>7s} {'RMS after [µm]':>15s} {'ΔBIC':>11s} {'p-value':>9s} {'flags':>5s}  "
              "evidence", file=file)
        for c in s.ranking:
            cmp = c.comparison
            tag = "  <- picked" if c is s.decision.pick else ""
            apart = f"  (cannot be told apart from {', '.join(c.indistinguishable_from)})" if c.indistinguishable_from \
                else ""
            print(f"  {c.effect:22s} {s.decision.weights.get(c.effect, 0):7.3g} {1e6 * c.fit.rmse:15.4g} "
                  f"{cmp.delta_bic:11.4g} {cmp.p_value:9.2g} {len(c.quality):5d}  {c.evidence(s.base)}{tag}{apart}",
                  file=file)
        for c in s.candidates:
            if not c.evaluated and s.index == 1:
                print(f"  {c.effect:22s} not evaluated: {c.reason}", file=file)
    for sp in res.support:
        print(f"  model effect {sp.effect}: {sp.explanation}", file=file)
    for line in res.verdict.lines():
        print(line, file=file)


def run(args) -> int:
    t_start = time.perf_counter()
    if args.noise_floor_um is not None and not (args.noise_floor_um > 0):
        raise InputError(f"--noise-floor-um {args.noise_floor_um!r}: must be a positive number of µm")
    if args.fs_max_Hz is not None and not (args.fs_max_Hz > 0):
        raise InputError(f"--fs-max-Hz {args.fs_max_Hz!r}: must be a positive frequency")
    if args.max_effects < 1:
        raise InputError(f"--max-effects {args.max_effects}: must be at least 1")
    check_count(args.starts, 1, MAX_STARTS, "--starts", "multi-start fits")
    if args.fs_max_Hz is not None:
        check_range(args.fs_max_Hz, *FS_RANGE_HZ, "--fs-max-Hz", "Hz")
    if args.name is not None:
        component(args.name, "--name", "the device file NAME.yaml")
    separate({"--out": args.out, "--draft-effects": args.draft_effects})
    if args.apply and args.no_apply:
        raise InputError("--apply and --no-apply contradict each other; give one")
    protect = list(args.measurements) + ([args.device] if Path(args.device).suffix in (".yaml", ".yml") else [])
    drafts_dir = Path(args.draft_effects) if args.draft_effects is not None else Path(args.out) / "drafts"
    inside = args.draft_effects is None
    apply = not args.no_apply
    with reserving(args, protect):
        if not inside:
            preflight(args.draft_effects, inputs=protect, overwrite=args.overwrite, flag="--draft-effects")
        res, outcome = _diagnose(args)
        kept = outcome.kept if outcome is not None else []
        if kept and apply:
            _register(kept)       # the best model's device file names their sections
        best = _best(res, outcome, drafts_dir, [str(Path(f).resolve()) for f in getattr(args, 'effects_path', [])])
        if best is not None and best["fit"] is not res.final:     # the offsets and drifts of the model written
            res.verdict.nuisance = nuisance_summary(best["fit"], res.records)
        out = write_diagnosis(res, args.out, apply=apply, name=args.name, provenance=provenance(inputs=protect),
                              best=best, measurements=[str(m) for m in args.measurements],
                              drafts=kept if inside else (), overwrite=args.overwrite, inputs=protect)
    checks = out["drafts"]
    if kept and not inside:
        checks = write_drafts(kept, drafts_dir, overwrite=args.overwrite, inputs=protect)
    d = Path(args.out)
    print_summary(res)
    if outcome is not None:
        _print_drafts(outcome, drafts_dir, checks)
    if best is not None:
        print(f"best model: {best['text']}")
    if apply:
        ap = out["applied"]
        print(f"applied: {ap['path']}\n  use it: {ap['usage']}" if ap.get("written") else f"applied: {ap['reason']}")
    phases = f"the diagnosis {res.timings['total']:.1f} s" + (
        f", its draft rounds {res.timings['draft rounds']:.1f} s" if "draft rounds" in res.timings else "")
    print(f"wrote {d}/diagnosis.json, {d}/index.html and {len([f for f in out['files'] if f.endswith('.png')])} PNGs "
          f"in {time.perf_counter() - t_start:.1f} s ({phases})")
    return 0


def _diagnose(args):
    """The diagnosis of ``args`` and, unless ``--no-draft``, its drafted effects (a
    :class:`~physics.diagnose.draft.DraftOutcome`, else None)."""
    ms = read_measurements(args)
    log = None if args.quiet else (lambda m: print(f"[diagnose] {m}", file=sys.stderr, flush=True))
    opts = fit_options(args, free=args.free or None, per_rh=args.per_rh, start=args.start, bounds=args.bounds,
                       n_starts=args.starts, seed=args.seed, n_modes=args.n_modes, settings=parallel_settings(args))
    res = diagnose(ms, args.device, args.effects, options=opts, candidates=args.candidates, force=args.force,
                   check_support=not args.no_support,
                   selection=SelectionOptions(max_effects=args.max_effects, backward=not args.forward_only),
                   analysis=AnalysisOptions(noise_floor=None if args.noise_floor_um is None
                                            else 1e-6 * args.noise_floor_um, fs_max=args.fs_max_Hz),
                   progress=log)
    if args.no_draft:
        return res, None
    from physics.diagnose.draft import draft_effects, rediagnosis
    t0 = time.perf_counter()
    outcome = draft_effects(res, rediagnosis(ms, res, opts, fs_max=args.fs_max_Hz, progress=log), progress=log)
    res.timings["draft rounds"] = time.perf_counter() - t0
    return res, outcome


def _best(res, outcome, drafts_dir: Path, user_files=()) -> dict | None:
    """The best model of the run as the report writes it: the diagnosis's final model, or the
    draft rounds' best (:attr:`~physics.diagnose.draft.DraftOutcome.final`: with the kept drafts,
    or the diagnosis's picks refined further on the time records) when it fits better.  Its fit,
    its effects, the effect files it needs, a one-line summary and what the draft rounds did (as
    printed).  A test strip with rough electrodes and solvent diffusion: the rounds refined the
    picks to 33.4 µm, kept no draft, and 35.2 µm was written while only the kept drafts' model was
    taken from them."""
    fit, files = res.final, []
    if outcome is not None and outcome.final is not None and outcome.final.rmse < fit.rmse:
        fit, files = outcome.final, [str(drafts_dir / d.file_name) for d in outcome.kept]
    if fit is res.base and not files:
        return None
    files = list(user_files) + files
    nf = res.noise_floor
    ratio = f" = {fit.rmse / nf:.2f}× the noise floor of {1e6 * nf:.3g} µm" if nf and nf > 0 else ""
    how = (f" (with the drafts {', '.join(d.effect_id for d in outcome.kept)})" if fit is not res.final and outcome.kept
           else " (refined further on the time records by the draft rounds)" if fit is not res.final
           else f" (its own effects refitted: {', '.join(res.settings['own_refined'])})" if res.settings["own_refined"]
           else "")
    return {"fit": fit, "effect_files": files, "draft_rounds": outcome.lines() if outcome is not None else [],
            "text": f"[{', '.join(fit.effects)}] RMS error {1e6 * res.base.rmse:.4g} → {1e6 * fit.rmse:.4g} µm{ratio}{how}"}


def _register(kept) -> None:
    """Register the kept drafts (their fitted values as defaults) for this process."""
    import tempfile

    from physics.effects import EFFECTS, load_effects_file
    with tempfile.TemporaryDirectory(prefix="eap-drafts-") as t:
        for d in kept:
            if d.effect_id not in EFFECTS:
                path = Path(t) / d.file_name
                path.write_text(d.source(), encoding="utf-8")
                load_effects_file(path)


def _print_drafts(outcome, out: Path, checks: dict) -> None:
    for line in outcome.lines():
        print(f"draft: {line}")
    if not outcome.kept:
        print(f"draft: nothing written to {out} (" + ("the model is adequate" if not outcome.rejected
                                                       else "no draft lowers the error") + ")")
        return
    for name, problems in checks.items():
        print(f"draft: {out / name}: contract check " + ("passed" if not problems else "FAILED: " + "; ".join(problems)))
