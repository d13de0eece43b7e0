"""Training one network on 2 processes with Lightning's DDP (gloo, CPU) vs 1 process:
wall time and test free-run NRMSE side by side (same epochs, same seed).

    python bench/ddp.py [--epochs 40]

Data: the toy static-cubic system of nnmodel.benchmarks.toy (2 × 4000 training samples);
model: NARX (2 output lags, 4 input lags, 16 hidden units).  On a 2-core machine the gain
is bounded by the process start-up (spawn) and the gradient all-reduce per step.
"""
from __future__ import annotations

import argparse
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=40)
    args = ap.parse_args()
    from nnmodel.benchmarks import toy
    from nnmodel.models import MODELS
    from nnmodel.training import execution
    from physics.analysis.metrics import nrmse
    train = toy.records("static_cubic", 4000, seeds=(1, 2))
    val = toy.records("static_cubic", 1000, seeds=(3,))
    test = toy.records("static_cubic", 2000, seeds=(4,))[0]
    kw = dict(na=2, nb=4, hidden=16, horizon=50, stride=10, max_epochs=args.epochs, patience=10 ** 6,
              max_time=None, progress_bar=False, num_threads=1)
    for label, devices in (("1 process", 1), ("2 processes (ddp_spawn, gloo)", 2)):
        with execution(devices, "ddp_spawn" if devices > 1 else "auto"):
            t0 = time.perf_counter()
            m = MODELS["narx"](**kw).fit(train, val)
            wall = time.perf_counter() - t0
        print(f"{label:32s} {wall:6.1f} s   test free-run NRMSE {100 * nrmse(test.y, m.simulate(test.u)):.2f} %",
              flush=True)


if __name__ == "__main__":
    main()
