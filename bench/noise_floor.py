"""How well does the diagnosis read the noise floor of records it never made?  For each case of
a truth family (written to a temporary folder as a lab would export it, read back as ``eap
diagnose`` reads it) the noise floor the records give — the spectrum's white level alone, and the
reading in force (:func:`physics.diagnose.records.deflection_spectrum`: the spectrum, the record's
quietest segments, the difference of a periodic record's periods) — against the level the family
drew (its sensor's white noise and quantisation).

    python bench/noise_floor.py --family circuit_lab --truths clipped,play,none --seeds 80,81

Prints one row per case (the records' floors pooled by sample count, as the diagnosis pools them)
and a summary: how many cases read more than 1.1× or less than 0.9× the drawn level.  Cases whose
records state their sensor (the floor is then the sidecar's, not estimated) are listed and skipped.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def read_floors(case) -> tuple[float, float] | None:
    """(spectrum-only, in-force) noise floor [m] of ``case``'s records, pooled by sample count;
    None when the records state their sensor."""
    from physics.analysis.frf_estimation import noise_level
    from physics.compare import load_measurements
    from physics.diagnose.records import classify, deflection_spectrum, record_period, sensor_noise_floor
    with tempfile.TemporaryDirectory() as d:
        ms = load_measurements([f for f in case.write(d) if str(f).endswith(".csv")])
    if sensor_noise_floor(ms[0]) is not None:
        return None
    spec = used = n = 0.0
    for ts in ms:
        kind, _, _, how = classify(ts)
        s = math.sqrt(noise_level(ts.deflection, ts.fs)[0] * ts.fs / 2)
        u = deflection_spectrum(ts, record_period(ts, how) if kind == "broadband" else None)[0]
        spec, used, n = spec + ts.n * s * s, used + ts.n * u * u, n + ts.n
    return math.sqrt(spec / n), math.sqrt(used / n)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="circuit_lab", help="truth family (bench/truths)")
    ap.add_argument("--truths", default="clipped,play,bow,none", help="comma-separated truths of the family")
    ap.add_argument("--seeds", default="80,81", help="comma-separated seeds")
    a = ap.parse_args(argv)
    from bench.truths import make_case
    warnings.filterwarnings("ignore")
    old, new = [], []
    print(f"{'truth':<12} {'seed':>4}  {'spectrum':>8}  {'in force':>8}   (÷ the drawn level)")
    for truth in a.truths.split(","):
        for seed in (int(s) for s in a.seeds.split(",")):
            case = make_case(a.family, truth, seed)
            got = read_floors(case)
            if got is None:
                print(f"{truth:<12} {seed:>4}  the records state their sensor: skipped")
                continue
            old.append(got[0] / case.noise_floor)
            new.append(got[1] / case.noise_floor)
            print(f"{truth:<12} {seed:>4}  {old[-1]:8.3f}  {new[-1]:8.3f}", flush=True)
    if not old:
        return 0
    o, n = np.array(old), np.array(new)
    print(f"{o.size} cases: spectrum median {np.median(o):.3f} max {o.max():.3f}, >1.1 {int((o > 1.1).sum())}, "
          f"<0.9 {int((o < 0.9).sum())}; in force median {np.median(n):.3f} max {n.max():.3f}, "
          f">1.1 {int((n > 1.1).sum())}, <0.9 {int((n < 0.9).sum())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
