"""Diagnosis of truths outside the catalog: how often a catalog effect is named with high
confidence (the target is never), what the verdict says instead, and what the adequacy
check describes.  In-catalog identification rates are printed by
``bench/diagnose_speed.py --rate-seeds N``.

    python bench/diagnose_hidden.py [--seeds 3]

Truths (physics.testbeds.demo.outside_catalog_case): creep of the polymer, a play
(backlash) on the output, and a viscoelastic near-twin (another polymer law than the DMA
table); the user's model is the bare device (double_layer only) with every catalog
candidate the records can reveal.
"""
from __future__ import annotations

import argparse
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    from physics.testbeds.demo import OUTSIDE, outside_catalog_case
    from physics.diagnose.diagnosis import diagnose
    high = total = 0
    print(f"{'truth':9s} {'seed':>4s}  {'status':30s} {'named':22s} {'label':6s} remaining (first descriptor)")
    for kind in OUTSIDE:
        for seed in range(args.seeds):
            ms, tp = outside_catalog_case(kind, seed)
            t0 = time.perf_counter()
            res = diagnose(ms, "ipmc_pt_eg", "none")
            v = res.verdict
            named = v.missing_effect or (" / ".join(v.ambiguous) if v.ambiguous else "-")
            confident = v.missing_effect is not None and v.label == "high"
            high += confident
            total += 1
            sig = [d for d in (res.adequacy.descriptors if res.adequacy else []) if d.get("significant")]
            desc = sig[0]["text"][:90] if sig else ""
            print(f"{kind:9s} {seed:4d}  {v.status:30s} {named:22s} {v.label:6s} {desc}  "
                  f"[{time.perf_counter() - t0:.1f} s; truth {', '.join(f'{k}={x:.3g}' for k, x in tp.items())}]",
                  flush=True)
    print(f"catalog effects named with high confidence for truths outside the catalog: {high}/{total}")


if __name__ == "__main__":
    main()
