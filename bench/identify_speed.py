"""Speed of parameter identification (issue 4 target), against the thesis loop.

Target: identifying 2–5 parameters from a 400-point FRF takes ≤ 5 s (default method:
bounded multi-start least squares, 5 starts, uncertainty included).

Data: the closed-form FRF of the thesis devices at their file parameters, 400 log-spaced
points over 0.1–50 Hz, with 1 % complex Gaussian noise (seeded), written as FRF data with
a coherence matching that noise.  Starting values are the true values perturbed by
factors 1.4–0.7 (orders by ±0.1).

Cases: IPMC case I (kf, βf; thesis Table III), IP2C eq. 16 (kf0, a, p, b, βf), and the
thesis procedure (Nelder–Mead on J_err, eq. 13, 100 iterations, tol 1e-6) on both.

Thesis loop (the ratio printed): 100 iterations × 15 min per frequency point × 400
points = 10 000 h ≈ 417 days.  Assumption: one model evaluation per Nelder–Mead
iteration, each solving every frequency point with COMSOL at 15 min per frequency
(thesis §7: i7-3930K, 64 GB) — a lower bound, since Nelder–Mead needs 1–2 evaluations
per iteration plus shrink steps.

Run: ``python bench/identify_speed.py``; exits with status 1 if a least-squares case
misses the 5 s target.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings

import numpy as np

from physics.solvers.frequency import frequency_response
from physics.io.frfdata import FRFData
from physics.identify import THESIS_MAX_ITER, THESIS_SECONDS_PER_FREQUENCY, IdentifiabilityWarning, identify
from physics.model import ActuatorModel

TARGET_S = 5.0
N_POINTS = 400
NOISE = 0.01

CASES = [
    ("IPMC case I (kf, beta_f)", "ipmc_pt_eg", "default", {"kf": 1.4, "beta_f": 0.7}),
    ("IP2C eq. 16 (kf0, a, p, b, beta_f)", "ip2c_pedot_water", "default",
     {"kf0": 1.4, "frac_a": 0.1, "frac_p": 0.7, "frac_b": -0.1, "beta_f": 1.3}),
]


def make_frf(device: str, effects: str, rh: float, seed: int) -> tuple[FRFData, dict]:
    model = ActuatorModel(device, effects)
    f = np.logspace(-1, np.log10(50.0), N_POINTS)
    H = frequency_response(model, None, f, rh=rh).deflection
    rng = np.random.default_rng(seed)
    Hn = H * (1 + NOISE / np.sqrt(2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
    coh = np.full(f.size, 1.0 / (1.0 + NOISE ** 2))   # |H|²/(|H|² + noise) for this noise level
    return FRFData(f, Hn, coherence=coh, rh=rh, source=f"synthetic {device} FRF"), model.device.params


def start_values(truth: dict, perturb: dict) -> dict:
    out = {}
    for k, fac in perturb.items():
        if k.startswith("frac_") and k != "frac_p":
            out[k] = min(max(truth[k] + fac, 0.01), 0.99)
        else:
            out[k] = truth[k] * fac
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3, help="repetitions; the median wall time is reported")
    args = ap.parse_args(argv)
    thesis_s = THESIS_MAX_ITER * THESIS_SECONDS_PER_FREQUENCY * N_POINTS
    print(f"identification from a {N_POINTS}-point FRF (0.1-50 Hz, {100 * NOISE:g} % noise); target <= {TARGET_S:g} s")
    print(f"thesis loop: {THESIS_MAX_ITER} iterations x 15 min x {N_POINTS} points = {thesis_s / 3600:.0f} h "
          f"({thesis_s / 86400:.0f} days; 1 evaluation per iteration, a lower bound)\n")
    header = f"{'case':38s} {'method':12s} {'wall [s]':>9s} {'evals':>6s} {'max |err|':>10s} {'J_err [m/V]':>12s} {'speed-up':>10s}"
    print(header)
    print("-" * len(header))
    ok = True
    for label, device, effects, perturb in CASES:
        frf, truth = make_frf(device, effects, 100.0, args.seed)
        names = list(perturb)
        start = start_values(truth, perturb)
        for method in ("lsq", "nelder-mead"):
            walls, res = [], None
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", IdentifiabilityWarning)
                    res = identify([frf], device, effects, names, start=start, method=method)
                walls.append(time.perf_counter() - t0)
            wall = float(np.median(walls))
            err = max(abs(v / truth[n] - 1) for n, v in zip(names, res.fit.theta))
            print(f"{label:38s} {method:12s} {wall:9.2f} {res.fit.nfev:6d} {100 * err:9.2f}% "
                  f"{res.fit.j_err:12.3g} {thesis_s / wall:10.3g}")
            if method == "lsq":
                detail = ", ".join(f"{n} {v:.4g}±{s:.2g}" for n, v, s in zip(names, res.fit.theta, res.fit.std_error))
                print(f"{'':38s} {'':12s} {detail}")
                if wall > TARGET_S:
                    ok = False
    print()
    print("PASS: every least-squares identification within the target" if ok
          else f"FAIL: a least-squares identification took more than {TARGET_S:g} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
