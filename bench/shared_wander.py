"""False-alarm rate and power of the shared-wander test (:func:`physics.diagnose.wander.shared_wander`)
by simulation, on the records of the *outside* suite's drift case (a sweep and a pulse, 60 s at
200 Hz, as :func:`physics.testbeds.demo.outside_catalog_case` makes them and the diagnosis
prepares them: classified from the voltage, their noise floors estimated).

    python bench/shared_wander.py [--cases 200] [--seed 0]

The residuals are simulated, not fitted (a perfect model): 3 µm white noise plus, in each
record, its own sensor random walk (std U(3, 10) µm at the end, as the lab export), then

* ``walk`` (null): nothing else;
* ``smooth`` (null): each record's own smooth wander, the lab suite's ``drift`` truth (doubly
  low-passed noise, 10 s, RMS U(3, 6) × the white noise after its trend);
* ``shared`` (power): A·(1 − e^(−t/τ)) the same in every record, |A| log-uniform 8–20 µm, τ
  log-uniform 5–60 s (the outside suite's drift truth).

Each record's offset and linear trend are removed (the nuisance terms), as a fit does.  Printed:
the share of cases called shared (p < SHARED_ALPHA) and hinting (p < HINT_P) with a 95 %
Clopper–Pearson interval; for ``shared`` also by τ.
"""
from __future__ import annotations

import argparse
import math
import warnings

import numpy as np
from scipy.signal import lfilter
from scipy.stats import beta


def _records():
    from physics.testbeds.demo import outside_catalog_case
    from physics.diagnose.records import prepare_records
    ms, _ = outside_catalog_case("drift", 0, fs=200.0, duration=60.0, lab=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return prepare_records(ms)


def _case(kind: str, records, rng) -> tuple[float, float]:
    """(p-value, τ [s] of the shared drift or NaN) of one simulated case."""
    from physics.diagnose.wander import shared_wander, slow_wander
    from physics.analysis.metrics import nuisance_terms, remove_nuisance
    amp = rng.choice([-1.0, 1.0]) * math.exp(rng.uniform(math.log(8e-6), math.log(20e-6)))
    tau = math.exp(rng.uniform(math.log(5.0), math.log(60.0)))
    smooth = rng.uniform(3.0, 6.0) * 3e-6
    resid, nui = [], []
    for r in records:
        n = r.y_d.size
        t = np.arange(n) / r.fs_d
        y = rng.normal(0.0, 3e-6, n) + np.cumsum(rng.normal(0.0, rng.uniform(3e-6, 10e-6) / math.sqrt(n), n))
        if kind == "smooth":
            a = math.exp(-1.0 / (10.0 * r.fs_d))
            w = remove_nuisance(lfilter([1 - a], [1, -a], lfilter([1 - a], [1, -a], rng.normal(0.0, 1.0, n))), t)
            y = y + smooth * w / w.std()
        elif kind == "shared":
            y = y - amp * np.expm1(-t / tau)
        nui.append(nuisance_terms(y, t))
        resid.append(remove_nuisance(y, t))
    s = shared_wander(records, resid, nui, slow_wander(records, resid, nui))
    return s.p_value, (tau if kind == "shared" else math.nan)


def _rate(hits: int, n: int) -> str:
    lo = beta.ppf(0.025, hits, n - hits + 1) if hits else 0.0
    hi = beta.ppf(0.975, hits + 1, n - hits) if hits < n else 1.0
    return f"{hits}/{n} = {100 * hits / n:.1f} % (95 %: {100 * lo:.1f}–{100 * hi:.1f} %)"


def main() -> None:
    from physics.diagnose.wander import HINT_P, SHARED_ALPHA
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    records = _records()
    print(f"records: {', '.join(f'{r.source} ({r.kind}, {r.ts.duration:.0f} s, fs_d {r.fs_d:.0f} Hz)' for r in records)}")
    for kind in ("walk", "smooth", "shared"):
        rng = np.random.default_rng(args.seed)
        rows = np.array([_case(kind, records, rng) for _ in range(args.cases)])
        p, tau = rows[:, 0], rows[:, 1]
        what = "power" if kind == "shared" else "false alarms"
        print(f"{kind:6s} {what}: shared (p < {SHARED_ALPHA:g}) {_rate(int(np.sum(p < SHARED_ALPHA)), p.size)}; "
              f"hint (p < {HINT_P:g}) {_rate(int(np.sum(p < HINT_P)), p.size)}", flush=True)
        if kind == "shared":
            for lo, hi in ((5, 15), (15, 30), (30, 60)):
                m = (tau >= lo) & (tau < hi)
                print(f"       τ {lo}–{hi} s: shared {_rate(int(np.sum(p[m] < SHARED_ALPHA)), int(m.sum()))}")


if __name__ == "__main__":
    main()
