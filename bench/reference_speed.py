"""Speed of the reference PNP + solvent solver against the reduced model on the same signals.

Signals (fs = 1 kHz, 2 V = 4 Vpp as in the thesis): one period of a 1 Hz sine, and a 10 s
square pulse (10 s at 2 V, then 10 s at 0 V).  For each device: wall time of the reference
(one slab; and the strip of slices through the electrode resistance with the device's default
effects) and of the reduced model (linear default effects; with ``nonlinear_charge``), and
the speed ratio reference/reduced.  Run: ``python bench/reference_speed.py [--device NAME]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from physics.device import load_device
from physics.reference.strip import ReferenceStrip
from physics.solvers.timedomain import simulate


def _timed(fn, repeat=1):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", action="append", default=None, help="device (repeatable; default both)")
    args = ap.parse_args(argv)
    fs = 1000.0
    t1 = np.arange(0, 1.0 + 1e-9, 1 / fs)
    t2 = np.arange(0, 20.0 + 1e-9, 1 / fs)
    signals = {"1 Hz sine, one period": (t1, 2.0 * np.sin(2 * np.pi * t1)),
               "10 s square pulse": (t2, np.where((t2 > 0) & (t2 < 10.0), 2.0, 0.0))}
    for dev in args.device or ["ipmc_pt_eg", "ip2c_pedot_water"]:
        d = load_device(dev)
        slab_fx = [e for e in d.default_effects if e != "electrode_resistance"]
        for name, (t, v) in signals.items():
            hold = "cubic" if "sine" in name else "linear"
            rows = []
            for label, fx in (("one slab", slab_fx), ("strip, default effects", list(d.default_effects))):
                ref = ReferenceStrip(d, fx, rh=100)
                w_ref, rr = _timed(lambda: ref.simulate(t, v))
                w_lin, _ = _timed(lambda: simulate(d, fx, t, v, rh=100, hold=hold), repeat=3)
                w_nl, _ = _timed(lambda: simulate(d, fx + ["nonlinear_charge"], t, v, rh=100, hold=hold), repeat=3)
                rows.append(f"  {label:24s} reference {w_ref:7.2f} s ({rr.stats['steps']} steps, "
                            f"{ref.edges.size if ref.line else 1} slab(s) × {ref.slab.N} nodes) | reduced linear "
                            f"{1e3 * w_lin:7.1f} ms (reference/reduced {w_ref / w_lin:.3g}×) | reduced + nonlinear_charge "
                            f"{1e3 * w_nl:7.1f} ms (reference/reduced {w_ref / w_nl:.3g}×)")
            print(f"{dev}, {name} ({t.size} samples):")
            print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
