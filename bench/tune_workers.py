"""`train-compare --tune N` on one and on two workers: the same trials and bundle, and the wall time.

Generates a small synthetic dataset (`eap generate`, two training RH levels, 6 s records),
then runs `eap train-compare DATASET --models MODELS --tune N` with `--workers 1` and
`--workers 2`, and prints every bundle's weight hash and the wall times.  The trials of a
batch (4) run side by side; the second run starts its local Dask cluster cold, as a command
does.  Timings on a shared machine are inflated by whatever else runs there.

    python bench/tune_workers.py [--models ff,rbf] [--tune 8] [--out runs/tune-workers]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

TINY = """fs_Hz: 100.0
f_max_Hz: 20.0
duration_s: 6.0
train_rh_pct: [40, 100]
heldout_rh_pct: [70]
excitations: [sweep, noise]
validation_per_rh: 1
test_per_train_rh: 1
test_per_heldout_rh: 1
varying_rh: {train: 0, test: 1, range_pct: [40, 100]}
measurement_like: {effects: [nonlinear_charge], count: 0, rh_pct: [55]}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="ff,rbf")
    ap.add_argument("--tune", type=int, default=8)
    ap.add_argument("--out", default="runs/tune-workers")
    args = ap.parse_args()
    from nnmodel.app.cli import main as eap
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tiny.yaml").write_text(TINY)
    ds = out / "dataset"
    if not ds.exists() and eap(["generate", "--config", str(out / "tiny.yaml"), "--out", str(ds)]):
        sys.exit("eap generate failed")
    runs = {}
    for w in (1, 2):
        t0 = time.perf_counter()
        code = eap(["train-compare", str(ds), "--models", args.models, "--tune", str(args.tune), "--workers", str(w),
                    "--quiet", "--overwrite", "--out", str(out / f"workers{w}")])
        if code:
            sys.exit(f"train-compare --workers {w} failed with exit {code}")
        runs[w] = time.perf_counter() - t0
    same = True
    for name in args.models.split(","):
        h = [json.loads((out / f"workers{w}" / "models" / name / "card.json").read_text())["weights"]["sha256"]
             for w in (1, 2)]
        same &= h[0] == h[1]
        verdict = "identical" if h[0] == h[1] else "DIFFERENT"
        print(f"{name}: weights sha256 workers 1 {h[0][:16]}  workers 2 {h[1][:16]}  {verdict}")
    print(f"--tune {args.tune}, models {args.models}: wall time 1 worker {runs[1]:.1f} s, 2 workers {runs[2]:.1f} s "
          f"(x{runs[1] / runs[2]:.2f}); bundles {'identical' if same else 'DIFFERENT'}")


if __name__ == "__main__":
    main()
