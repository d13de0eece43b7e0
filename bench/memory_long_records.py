"""Peak memory (RSS) and wall time of `eap predict` and `eap compare` (physics model and
neural bundle) on long records.

Each measurement runs the command in a fresh process and reads that process's own peak
RSS (``VmHWM``; ``ru_maxrss`` would also count this script's size at the fork); an
address-space cap (``--cap-GB``) keeps a run that would exhaust the machine from doing so
(it then reports the package's out-of-memory error instead of a figure).

    python bench/memory_long_records.py                 # 1e5, 1e6, 1e7 samples
    python bench/memory_long_records.py --sizes 2e6,1e7 --commands predict,compare-nn
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RUNNER = r"""
import json, resource, sys, time
cap = int(float(sys.argv[1]) * 2**30)
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
from nnmodel.app.cli import main
t0 = time.perf_counter()
rc = main(sys.argv[2:])
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")]
print(json.dumps({"rc": rc, "s": time.perf_counter() - t0, "peak_MB": int(hwm[0].split()[1]) / 1024}))
"""


def _record(path: Path, n: int, fs: float) -> None:
    """A 1.3 Hz sine record with a first-order response, written in 1 M-row blocks."""
    from scipy.signal import lfilter
    with open(path, "w") as fh:
        fh.write("time_s,voltage_V,deflection_m,rh_pct\n")
        zi = np.zeros(1)
        for a in range(0, n, 1 << 20):
            i = np.arange(a, min(n, a + (1 << 20)))
            t = i / fs
            v = np.sin(2 * np.pi * 1.3 * t)
            y, zi = lfilter([0.01e-4], [1, -0.99], v, zi=zi)
            np.savetxt(fh, np.column_stack([t, v, y, np.full(i.size, 60.0)]), delimiter=",", fmt="%.9g")


def _bundle(folder: Path, fs: float) -> Path:
    from scipy.signal import lfilter

    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    rng = np.random.default_rng(0)
    u = np.convolve(rng.normal(size=20000), np.ones(20) / 20, "same")
    y = lfilter([0.01], [1, -0.99], u) * 1e-3
    rec = Experiment(u=u, y=y, rh=np.full(u.size, 60.0), fs=fs)
    m = MODELS["ff"](max_epochs=2, progress_bar=False)
    m.fit([rec], [rec])
    return save(m, folder / "ff")


def _measure(cap_gb: float, argv: list[str]) -> dict:
    proc = subprocess.run([sys.executable, "-c", RUNNER, str(cap_gb), *argv], capture_output=True, text=True)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        return {"rc": proc.returncode, "error": proc.stderr.strip().splitlines()[-1:] or ["?"]}
    out = json.loads(lines[-1])
    if out["rc"] != 0:
        out["error"] = proc.stderr.strip().splitlines()[-1:]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e5,1e6,1e7", help="record lengths [samples]")
    ap.add_argument("--fs-Hz", type=float, default=1000.0)
    ap.add_argument("--cap-GB", type=float, default=12.0, help="address-space cap per run")
    ap.add_argument("--commands", default="predict,compare,compare-nn", help="which runs to measure")
    args = ap.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bundle = _bundle(tmp, args.fs_Hz)
        base = _measure(args.cap_GB, ["effects"])
        print(f"baseline (imports, `eap effects`): {base.get('peak_MB', float('nan')):.0f} MB")
        print(f"{'samples':>10s} {'command':10s} {'peak MB':>9s} {'time s':>8s}  note")
        for n in sizes:
            rec = tmp / f"r{n}.csv"
            _record(rec, n, args.fs_Hz)
            runs = {"predict": ["predict", "--model", str(bundle), "--input", str(rec), "--out",
                                str(tmp / f"p{n}.csv"), "--overwrite"],
                    "compare": ["compare", str(rec), "--model", "ip2c_pedot_water", "--out", str(tmp / f"c{n}"),
                                "--overwrite"],
                    "compare-nn": ["compare", str(rec), "--model", str(bundle), "--out", str(tmp / f"n{n}"),
                                   "--overwrite"]}
            for name, argv in runs.items():
                if name not in args.commands.split(","):
                    continue
                t0 = time.perf_counter()
                r = _measure(args.cap_GB, argv)
                note = "" if r.get("rc") == 0 else f"FAILED: {' '.join(r.get('error', []))[:120]}"
                print(f"{n:10d} {name:10s} {r.get('peak_MB', float('nan')):9.0f} "
                      f"{r.get('s', time.perf_counter() - t0):8.1f}  {note}", flush=True)
            rec.unlink()


if __name__ == "__main__":
    main()
