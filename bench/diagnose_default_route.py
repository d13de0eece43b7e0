"""The default route on a creep + humidity strip: ``eap diagnose`` with the thesis device and
``--param`` only, as a new user runs it (issue 34, "the loop by default").

    python bench/diagnose_default_route.py [--seed 0] [--out runs/default_route]

The strip (written here, not by switching the package's effects): the thesis IPMC's base
physics at L_total = 28 mm with its electrode line and polymer modulus but no solvent
back-diffusion (the device file's ethylene-glycol diffusion is not this strip's), its coupling and
stiffness following this bench's own humidity law (kf × U(0.6, 0.8)…U(1.0, 1.2) and Y × 1.6…0.75
from RH 40 to 85 %, not Table V), and a creep on the output, tip × (1 + r/(1 + sτ)) with r = 0.30,
τ = 15 s, applied by a recursive filter.  The user's model is the device's default
(electrode line, solvent diffusion, modulus, Table V humidity law).
Records as a lab exports them (no metadata): at RH 40, 55, 70 and 85 % a multisine
0.05–20 Hz of two 40 s periods recorded after three periods of settling; a square pulse (30 s on,
30 s off, after 2 s of rest) at RH 55 %; a 60 s swept sine 0.1–20 Hz at RH 70 %; 200 Hz, the tip in
mm with 2 µm noise, a +40 µm offset and a slow random-walk drift, RH with ±0.3 % jitter.

Printed: the command, the route it took (the per-RH parameters it freed, the effects it
removed and tried again, the picks, the drafts kept) with the RMS error after each step, the
best model's error against the true model's (scored the same way: each record's offset and
linear drift removed), the offsets it fitted against the true one, and whether the command it
prints to use the best model runs as printed.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RH = (40.0, 55.0, 70.0, 85.0)
Y_OF_RH = {40.0: 1.6, 55.0: 1.25, 70.0: 0.95, 85.0: 0.75}
CREEP_R, CREEP_TAU = 0.30, 15.0
FS, NOISE, OFFSET = 200.0, 2e-6, 40e-6


def records(folder: Path, seed: int) -> tuple[list[str], float]:
    """Write the strip's records into ``folder``; returns (files, true model's RMS error [m])."""
    import dataclasses
    import warnings

    from scipy.signal import lfilter

    from physics import signals
    from physics.device import load_device
    from physics.analysis.metrics import remove_nuisance
    from physics.model import ActuatorModel
    from physics.solvers.timedomain import simulate
    from physics.io.timeseries import TimeSeries, write_timeseries
    warnings.simplefilter("ignore")
    rng = np.random.default_rng([seed, 34])
    kf_of_rh = dict(zip(RH, np.sort(rng.uniform([0.6, 0.75, 0.9, 1.0], [0.8, 0.95, 1.05, 1.2]))))
    dev = load_device("ipmc_pt_eg").with_params(L_total=28e-3)
    folder.mkdir(parents=True, exist_ok=True)
    files, sq, cnt = [], 0.0, 0

    def emit(t, v, rh, name, hold, keep):
        nonlocal sq, cnt
        d = dataclasses.replace(dev.with_params(Y=dev.params["Y"] * Y_OF_RH[rh], kf=dev.params["kf"] * kf_of_rh[rh]),
                                humidity_maps={})
        m = ActuatorModel(d, ["electrode_resistance", "viscoelastic"])
        y = simulate(m, None, t, v, rh=rh, hold=hold).deflection
        a = math.exp(-1.0 / (CREEP_TAU * FS))
        y = (y + CREEP_R * lfilter([1 - a], [1, -a], y))[-keep:]
        tt, vv = t[:keep], v[-keep:]
        n = y.size
        walk = np.cumsum(rng.normal(0, 1, n)) * 2e-6 / math.sqrt(n)
        meas = y + OFFSET + walk + rng.normal(0, NOISE, n)
        ts = TimeSeries(tt, vv, np.round(meas, 7), rh=np.round(rh + rng.normal(0, 0.3, n), 1), meta={}, source=name)
        files.append(str(write_timeseries(ts, folder / f"{name}.csv", units={"deflection": "mm"})))
        e = remove_nuisance(ts.deflection - y, tt)
        sq += float(e @ e)
        cnt += e.size

    for k, rh in enumerate(RH):       # 3 periods of settling, 2 recorded
        sig = signals.multisine(0.3, 0.05, 20.0, 40.0, periods=5, fs=FS, seed=seed * 10 + k)
        emit(sig.t, sig.v, rh, f"{k + 1:02d}_multisine_RH{rh:g}", "cubic", int(80 * FS))
    sq_sig = signals.square(1.0, t_on=30.0, t_off=32.0, cycles=1, fs=FS)
    v = np.roll(sq_sig.v, int(2 * FS))          # 2 s of rest before the drive
    emit(sq_sig.t, v, 55.0, "05_square_RH55", "linear", v.size)
    sw = signals.sweep(0.5, 0.1, 20.0, 60.0, FS)
    emit(sw.t, sw.v, 70.0, "06_sweep_RH70", "cubic", sw.v.size)
    return files, math.sqrt(sq / cnt)


def _eap(args: list[str]) -> tuple[int, str, float]:
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "nnmodel.app.cli", *args], cwd=ROOT, capture_output=True, text=True,
                       env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    return p.returncode, p.stdout + p.stderr, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="runs/default_route")
    args = ap.parse_args(argv)
    out = Path(args.out)
    files, true_e = records(out / "records", args.seed)
    cmd = ["diagnose", *files, "--device", "ipmc_pt_eg", "--param", "L_total=28mm", "--out", str(out / "dx"),
           "--overwrite"]
    print("$ eap " + " ".join(shlex.quote(c) for c in cmd))
    rc, text, wall = _eap(cmd)
    if rc != 0:
        print(text)
        print(f"FAILED: exit status {rc}")
        return 1
    d = json.loads((out / "dx" / "diagnosis.json").read_text())
    v = d["verdict"]
    print(f"  ({wall:.0f} s, shared loaded 2-core machine)")
    for n in d["settings"].get("notes", []):
        print(f"  freed: {n}")
    print(f"  base [{', '.join(d['base']['effects'])}], free {', '.join(d['base']['free'] + d['base']['per_rh'])}: "
          f"{1e6 * d['base']['rmse']:.4g} µm")
    for s in d["steps"]:
        if s["kind"] == "remove":
            print(f"  step {s['step']}: removed {s['removed']['effect']}: {1e6 * s['base_rmse']:.4g} → "
                  f"{1e6 * s['rmse_after']:.4g} µm")
        elif s["picked"]:
            print(f"  step {s['step']}: added {s['picked']}: {1e6 * s['base_rmse']:.4g} → {1e6 * s['rmse_after']:.4g} µm")
        else:
            print(f"  step {s['step']}: no candidate passes ({1e6 * s['base_rmse']:.4g} µm)")
    print(f"  verdict: {v['status']}; noise floor {1e6 * d['noise_floor_m']:.3g} µm")
    best = d.get("best_model") or {}
    final = best.get("rmse_m", v.get("final_rmse_m"))
    for line in text.splitlines():
        if line.startswith("draft:") or line.startswith("best model:"):
            print("  " + line)
    print(f"  best model {1e6 * final:.4g} µm; true model {1e6 * true_e:.4g} µm: {final / true_e:.2f}× "
          "(target ≤ 3×)")
    offs = [r["offset_um"] for r in (v.get("nuisance") or {}).get("records", [])]
    if offs:
        print(f"  fitted offsets {min(offs):+.4g} … {max(offs):+.4g} µm (true {1e6 * OFFSET:+.3g} µm)")
    ap_ = d.get("applied") or {}
    if ap_.get("usage"):
        use = shlex.split(ap_["usage"])[1:] + ["--out", str(out / "compare"), "--overwrite"]
        print(f"$ {ap_['usage']} --out {out / 'compare'}")
        rc2, text2, wall2 = _eap(use)
        print(f"  runs as printed: {'yes' if rc2 == 0 else 'NO (exit ' + str(rc2) + ')'} ({wall2:.0f} s)")
        if rc2 != 0:
            print(text2[-2000:])
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
