"""The diagnosis on the two test beds of issue 24 (physics.testbeds.cases): lab-like records
of our simulator and records of a perturbed simulator, over several seeds.  Prints, per case
and seed: the truth, the verdict chain with its confidence, the error before → after each
step, the true model's error (scored the same way) and the status; then a summary.

    python bench/diagnose_testbeds.py [--suites lab,perturbed] [--truths all] [--seeds 3]
        [--effects-path examples/effects/creep.py]

"in catalog" cases pass when the hidden effect is the first pick with confidence "high" and
the final error is within 1.5× the true model's; "none" passes with "nothing to explain".
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="lab,perturbed")
    ap.add_argument("--truths", default="all", help="comma-separated truths, or all, catalog, outside")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--effects-path", default=None, help="a user effect file registered before the diagnosis")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    from physics.diagnose import diagnose
    from physics.testbeds.cases import OUTSIDE, make_case, truths
    if args.effects_path:
        from physics.effects import load_effects_file
        load_effects_file(args.effects_path)
    ok = total = 0
    for suite in args.suites.split(","):
        all_t = truths(suite)
        sel = {"all": all_t, "catalog": tuple(t for t in all_t if t not in OUTSIDE and t != "none"),
               "outside": OUTSIDE}.get(args.truths, tuple(args.truths.split(",")))
        for truth in sel:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                case = make_case(suite, truth, seed)
                t0 = time.perf_counter()
                res = diagnose(case.measurements, case.device, case.effects, seed=seed)
                wall = time.perf_counter() - t0
                v = res.verdict
                steps = " ".join(f"+{p.effect}[{p.label}] {1e6 * p.rmse_before:.3g}→{1e6 * p.rmse_after:.3g}"
                                 for p in v.picks) or ("ambiguous " + "/".join(v.ambiguous) if v.ambiguous else "-")
                true_e = case.true_error()
                if truth == "none":
                    good = v.status == "nothing to explain"
                elif case.hidden:
                    good = bool(v.picks) and v.picks[0].effect == truth and v.picks[0].label == "high" \
                        and v.final_rmse <= 1.5 * true_e
                else:
                    good = None
                if good is not None:
                    ok += good
                    total += 1
                mark = {True: "ok", False: "MISS", None: "  "}[good]
                print(f"{mark:4s} {suite:9s} {truth:21s} s{seed}  {v.status:28s} {steps:55s} base "
                      f"{1e6 * v.base_rmse:.3g} final {1e6 * v.final_rmse:.3g} true {1e6 * true_e:.3g} µm "
                      f"(noise {1e6 * res.noise_floor:.3g}; {wall:.0f} s)", flush=True)
                if v.remaining_kind == "described":
                    print(f"       remains: {v.remaining[0]['text'][:110]}", flush=True)
    print(f"passed {ok}/{total} cases with a definite expectation")
    return 0


if __name__ == "__main__":
    sys.exit(main())
