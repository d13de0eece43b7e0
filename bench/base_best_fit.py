"""How close can the user's model get to a truth family's records?  A reference for the
diagnosis's base fit: the user's model (the case's device, ``--param`` geometry and ``--effects``)
with its coupling gain, stiffness and damping fitted by plain least squares on the time records
(each record's offset and linear drift removed, as the diagnosis scores), from the device's values.

    python bench/base_best_fit.py pnp_fd none 0 [--max-nfev 40]

Prints the RMS error [µm] per record and overall, beside the true model's error.  The fit is
slow (one simulation of every record per evaluation) and only a reference: where the diagnosis's
base leaves much more than this, its fit stopped short; where this is far above the true model's
error, the family's base physics is outside the user's model.
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def best_fit(case, max_nfev: int = 40) -> dict:
    from scipy.optimize import least_squares
    from physics.device import load_device
    from physics.model import ActuatorModel
    from physics.solvers.timedomain import simulate
    from physics.io.units import to_si
    from bench.truths.case import remove_trend
    dev = load_device(case.device)

    def si(text: str) -> float:                      # "32.5mm" → 0.0325 (geometry: lengths)
        num = text.rstrip("abcdefghijklmnopqrstuvwxyzµ")
        return to_si(float(num), text[len(num):], "m")

    dev = dev.with_params(**{k: si(v) for k, v in case.params.items()})
    eff = case.effects
    stiff = "dma_scale" if eff.startswith("default") and "-viscoelastic" not in eff else "Y"
    free = ["kf", stiff, "beta_f"]
    x0 = np.log([dev.params.get(k, 1.0) for k in free])
    upper = np.where(np.array(free) == "beta_f", np.log(0.05), x0 + 4)

    def resid(x):
        d = dev.with_params(**dict(zip(free, np.exp(x))))
        m = ActuatorModel(d, eff)
        out = []
        for r in case.records:
            y = simulate(m, None, r.time, r.voltage, rh=float(np.mean(r.rh))).deflection
            out.append(remove_trend(r.measured - y, r.time))
        return np.concatenate(out) * 1e6

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = least_squares(resid, x0, diff_step=1e-3, max_nfev=max_nfev, bounds=(x0 - 4, upper))
        e = resid(res.x)
    per, n = {}, 0
    for r in case.records:
        k = r.time.size
        per[r.name] = float(np.sqrt(np.mean(e[n:n + k] ** 2)))
        n += k
    return {"rms_um": float(np.sqrt(np.mean(e ** 2))), "per_record_um": per,
            "values": dict(zip(free, np.exp(res.x).tolist())), "true_um": 1e6 * case.true_error()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("family")
    ap.add_argument("truth")
    ap.add_argument("seed", type=int)
    ap.add_argument("--max-nfev", type=int, default=40)
    args = ap.parse_args(argv)
    from bench.truths import make_case
    case = make_case(args.family, args.truth, args.seed)
    out = best_fit(case, args.max_nfev)
    print(f"{args.family}/{args.truth}/s{args.seed}: user's model --effects {case.effects}, fitted "
          + ", ".join(f"{k} = {v:.4g}" for k, v in out["values"].items()))
    for k, v in out["per_record_um"].items():
        print(f"  {k:32s} {v:8.3g} µm")
    print(f"  best fit {out['rms_um']:.3g} µm; true model {out['true_um']:.3g} µm "
          f"({out['rms_um'] / out['true_um']:.2f}×)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
