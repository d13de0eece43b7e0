"""Speed of the reduced simulator (issue 2 targets), against the thesis's COMSOL figure.

Targets: full FRF with all linear effects at 500 frequencies ≤ 20 ms on one core;
100 s at 1 kHz in the time domain with all linear effects ≤ 2 s, and with
nonlinear_charge and thermal ≤ 20 s.  The thesis needed 15 min per frequency point
(i7-3930K, COMSOL, §7).  Run: ``python bench/physics_speed.py [--quick]``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from physics import signals
from physics.solvers.frequency import frequency_response
from physics.model import ActuatorModel
from physics.solvers.timedomain import simulate

THESIS_S_PER_POINT = 15 * 60.0


def timed(fn, repeat):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="shorter records (for smoke runs)")
    args = ap.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})   # one core
    duration = 10.0 if args.quick else 100.0
    f = np.logspace(-1, np.log10(50), 500)
    print(f"one core; records of {duration:g} s at 1 kHz; thesis: {THESIS_S_PER_POINT / 60:g} min per frequency point")
    print(f"{'case':58s} {'median':>10s} {'best':>10s} {'target':>8s}  speed-up vs thesis")
    for dev in ("ipmc_pt_eg", "ip2c_pedot_water"):
        m = ActuatorModel(dev, "linear")
        frequency_response(m, None, f, rh=60)           # warm caches (Prony fit)
        med, best = timed(lambda: frequency_response(m, None, f, rh=60), 20)
        ratio = 500 * THESIS_S_PER_POINT / med
        print(f"{dev + ': FRF, all linear effects, 500 points':58s} {1e3 * med:8.2f} ms {1e3 * best:8.2f} ms"
              f" {'20 ms':>8s}  {ratio:.2e}x")
    sig = signals.sweep(2.0, 0.1, 50.0, duration, 1000.0)
    for dev in ("ipmc_pt_eg", "ip2c_pedot_water"):
        for label, eff, target in (("all linear effects", "linear", 2.0 * duration / 100),
                                   ("linear + nonlinear_charge + thermal", "all", 20.0 * duration / 100)):
            m = ActuatorModel(dev, eff)
            med, best = timed(lambda: simulate(m, None, sig.t, sig.v, rh=60), 3 if eff == "linear" else 1)
            ratio = THESIS_S_PER_POINT / med
            print(f"{dev + f': {duration:g} s sweep, ' + label:58s} {med:8.2f} s  {best:8.2f} s "
                  f"{target:6.1f} s  {ratio:.2e}x (vs one thesis frequency point)")


if __name__ == "__main__":
    main()
