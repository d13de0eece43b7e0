"""Default recipes on a slow plant, against the best linear model fitted on the same data.

The plant (built here, not an actuator): sampled at 0.25 Hz (4 s period), a first-order lag
of 2 minutes in series with a 30 s lag, then a saturation y = tanh(1.5 x) — time constants
of minutes and a hard nonlinearity.  Input: random steps held 1–10 samples.  Training
1500 samples, validation 500, test 1024 (each from its own seed), measurement noise 1 %.
The yardstick is an ARX model written here independently of the package (orders na, nb ≤ 8
chosen on the validation record by free-run error); the package's own linear yardstick
(nnmodel.linear, the 'linear' row of train-compare) is printed beside it.  The networks use
their recipes from configs/train unchanged (memory-filter time constants adapt to the
sampling rate and record length; the recipes start from the linear model, see README).
Target (issue 25): every model at least 20 % below the best ARX.

    python bench/slow_plant.py [--models ff,rbf,narx,lstm,gru]
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.signal import lfilter

FS = 0.25


def plant(n: int, seed: int, gain: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """``n`` samples (input, output) of the plant; ``gain``: of the saturation tanh(gain x)."""
    rng = np.random.default_rng(seed)
    holds = rng.integers(1, 11, n)
    u = np.repeat(rng.uniform(-1.0, 1.0, n), holds)[:n]
    a1, a2 = np.exp(-1 / (120 * FS)), np.exp(-1 / (30 * FS))
    x = lfilter([1 - a2], [1, -a2], lfilter([1 - a1], [1, -a1], u))
    y = np.tanh(gain * x)
    return u, y + 0.01 * np.std(y) * rng.normal(size=n)


def arx_fit(u, y, na, nb):
    k = max(na, nb)
    rows = [np.r_[-y[t - na:t][::-1], u[t - nb + 1:t + 1][::-1]] for t in range(k, len(y))]
    theta, *_ = np.linalg.lstsq(np.array(rows), y[k:], rcond=None)
    return theta


def arx_sim(theta, u, na, nb, y0):
    y = np.zeros_like(u)
    k = max(na, nb)
    y[:k] = y0[:k]
    for t in range(k, len(u)):
        y[t] = -theta[:na] @ y[t - na:t][::-1] + theta[na:] @ u[t - nb + 1:t + 1][::-1]
    return y


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="ff,rbf,narx,lstm,gru")
    args = ap.parse_args()
    from nnmodel.data import Experiment
    from nnmodel.linear import fit_linear
    from nnmodel.recipes import make_model
    (ut, yt), (uv, yv), (us, ys) = plant(1500, 1), plant(500, 2), plant(1024, 3)
    skip = 20
    best = None
    for na in range(1, 9):
        for nb in range(1, 9):
            th = arx_fit(ut, yt, na, nb)
            e = rmse(yv[skip:], arx_sim(th, uv, na, nb, yv)[skip:])
            if np.isfinite(e) and (best is None or e < best[0]):
                best = (e, na, nb, th)
    _, na, nb, th = best
    e_arx = rmse(ys[skip:], arx_sim(th, us, na, nb, ys)[skip:])
    print(f"best ARX (na={na}, nb={nb}, chosen on validation): test free-run RMSE {e_arx:.4f}")
    train, val = [Experiment(ut, yt, None, FS)], [Experiment(uv, yv, None, FS)]
    lin = fit_linear(train, val)
    e_lin = rmse(ys[skip:], lin.simulate(us, y_init=ys[:lin.n_init])[skip:])
    print(f"{'linear':6s} test free-run RMSE {e_lin:.4f} ({100 * (e_lin / e_arx - 1):+.0f} % vs ARX): {lin.label()}")
    met = True
    for name in [m.strip() for m in args.models.split(",") if m.strip()]:
        m = make_model(name, {"progress_bar": False})
        t0 = time.perf_counter()
        m.fit(train, val)
        wall = time.perf_counter() - t0
        yh = m.simulate(us, y_init=ys[:m.n_init_])
        e = rmse(ys[skip:], yh[skip:])
        met &= e <= 0.8 * e_arx
        start = (getattr(m, "reference_start_", None) or {}).get("end", {}).get("kept", "-")
        tried = getattr(m, "structure_search_", None)
        chosen = "" if not tried else f", structure {min(tried, key=lambda t: t['validation_free_run_nrmse'])['structure']}"
        print(f"{name:6s} test free-run RMSE {e:.4f} ({100 * (e / e_arx - 1):+.0f} % vs ARX), trained in {wall:.0f} s, "
              f"kept after training: {start}{chosen}", flush=True)
    print(f"target: every model at least 20 % below the best ARX -> {'MET' if met else 'NOT MET'}")


if __name__ == "__main__":
    main()
