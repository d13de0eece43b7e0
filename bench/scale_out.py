"""Scale-out figures on this machine, ratios measured in one run (physics/execution/parallel.py):

* `eap generate --config default`: serial vs 2 local workers, and whether the dataset
  hashes are identical;
* a 1,000-point `eap sweep` of the FRF: serial vs 2 workers, the per-task cost of the
  physics and the per-task overhead of the engine;
* `eap diagnose` with every candidate forced (the "rich" hidden-effect design: sweeps at 3 RH
  levels and 2 amplitudes plus a pulse): serial vs 2 workers, and whether the verdict is the same.

Every parallel run starts its local cluster cold, as one command of the CLI does (the
cluster start and the workers' imports are inside the timed interval).

    python bench/scale_out.py [--config default] [--points 1000]
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="default")
    ap.add_argument("--points", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    from nnmodel.dataset import generate
    from physics.execution.parallel import ParallelSettings, shutdown
    from physics.solvers.sweep import run_sweep
    par = ParallelSettings(args.workers)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        a = generate(Path(tmp) / "serial", args.config, progress=False)
        t1 = time.perf_counter()
        b = generate(Path(tmp) / "parallel", args.config, progress=False, settings=par)
        t2 = time.perf_counter()
        shutdown()
        ha = [e["sha256"] for e in json.loads((a / "dataset.json").read_text())["files"]]
        hb = [e["sha256"] for e in json.loads((b / "dataset.json").read_text())["files"]]
    print(f"generate --config {args.config}: serial {t1 - t0:.1f} s, {args.workers} workers {t2 - t1:.1f} s "
          f"(×{(t1 - t0) / (t2 - t1):.2f}); {len(ha)} files, hashes identical: {ha == hb}")
    n = int(round(np.sqrt(args.points)))
    grid = {"Y": np.geomspace(5e7, 5e8, n).tolist(), "rh": np.linspace(40, 100, args.points // n).tolist()}
    t0 = time.perf_counter()
    s = run_sweep("ipmc_pt_eg", "none", grid, progress=False)
    t1 = time.perf_counter()
    p = run_sweep("ipmc_pt_eg", "none", grid, settings=par, progress=False)
    t2 = time.perf_counter()
    shutdown()
    task = (t1 - t0) / len(s)
    ideal = (t1 - t0) / args.workers
    overhead = max(0.0, (t2 - t1) - ideal) / len(s)
    print(f"sweep of {len(s)} FRF points: serial {t1 - t0:.1f} s ({1e3 * task:.1f} ms per task), "
          f"{args.workers} workers {t2 - t1:.1f} s (×{(t1 - t0) / (t2 - t1):.2f}); engine overhead "
          f"≈ {1e3 * overhead:.2f} ms per task (cluster start included); tables identical: {s.equals(p)}")
    from physics.testbeds.demo import hidden_effect_case
    from physics.diagnose.diagnosis import diagnose
    case = hidden_effect_case("solvent_diffusion", 0, design="rich")
    runs = {}
    for label, st in (("serial", None), (f"{args.workers} workers", par)):
        t0 = time.perf_counter()
        res = diagnose(case.measurements, "ipmc_pt_eg", case.base_effects, force=True, settings=st)
        runs[label] = (time.perf_counter() - t0, res.verdict.missing_effect, len(res.ranking))
        shutdown()
    (ts, vs, n), (tp, vp, _) = runs.values()
    print(f"diagnose, {n} candidates forced: serial {ts:.1f} s, {args.workers} workers {tp:.1f} s (×{ts / tp:.2f}); "
          f"verdict {vs} / {vp}")


if __name__ == "__main__":
    main()
