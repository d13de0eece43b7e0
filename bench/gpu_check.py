"""GPU readiness: the Silverbox LSTM and ss recipes trained on the CPU and on the GPU.

Trains each recipe (configs/train/lstm.yaml, ss.yaml; one structure, so both devices run the
same epochs) for ``--epochs`` epochs on Silverbox's standard split (training part
[40650:105712], its last 15 % validating; multisine test [105712:127400]) with the same seed
on the CPU and on the GPU, and prints the wall time and the free-run test RMSE (mV) of each.
Then checks that the same seed on the same device gives the same weights twice (small
models, a short record): exit 1 if it does not, or if a training fails.  Without a CUDA
device it says so and exits 0.  Budgets are epochs; the wall-clock guard is off.

    python bench/gpu_check.py [--epochs 15] [--models lstm,ss] [--data SNLS80mV.csv]

Measured once on an NVIDIA H200 machine with 16 CPU cores (torch 2.11.0+cu130), 15 epochs, the
CPU runs on the recipes' one thread: 244 s for the whole script.  LSTM 20.5 s on the CPU, 2.7 s
on the GPU (4.52 and 4.10 mV after 15 epochs); ss 55.7 s on the CPU, 131.3 s on the GPU (0.284
and 0.294 mV): the state-space loop of small steps over a batch of 64 windows is bound by kernel
launches on a GPU, so ss trains faster on one CPU core.  Same seed, same device: identical
weights on both devices for both models.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
import sys
import time
import warnings

import numpy as np

#: the measured benchmark lies beside the checkout (bench only: the package takes --data or EAP_SILVERBOX)
os.environ.setdefault("EAP_SILVERBOX", str(Path(__file__).resolve().parents[2] / "shared" / "benchmarks" / "silverbox"))

SPLIT = {"train": slice(40650, 105712), "test": slice(105712, 127400), "fs": 610.35, "val_fraction": 0.15}
N_INIT = 50


def silverbox(path):
    from nnmodel.benchmarks.silverbox import find_data
    from nnmodel.data import Experiment
    data = np.genfromtxt(find_data(path), delimiter=",", names=True, usecols=("V1", "V2"))
    u, y = data["V1"].astype(float), data["V2"].astype(float)
    rec = {k: Experiment(u[s], y[s], None, SPLIT["fs"], k) for k, s in SPLIT.items() if isinstance(s, slice)}
    return rec["train"], rec["test"]


def train(name: str, overrides: dict, train_rec, test_rec=None):
    """(model, wall s, test RMSE mV or None)."""
    from nnmodel.recipes import make_model
    model = make_model(name, {"structures": None, "progress_bar": False, "max_time": None,
                              "val_fraction": SPLIT["val_fraction"], **overrides})
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        model.fit([train_rec])
    wall = time.perf_counter() - t0
    err = None
    if test_rec is not None:
        y = model.simulate(test_rec.u, y_init=test_rec.y[:N_INIT])
        err = 1e3 * float(np.sqrt(np.mean((y[N_INIT:] - test_rec.y[N_INIT:]) ** 2)))
    return model, wall, err


SMALL = {"lstm": dict(hidden=8, encoder_hidden=8, n_init=10, horizon=50, stride=50),
         "ss": dict(hidden=16, encoder_hidden=16, n_init=10, horizon=50, stride=50)}


def same_weights(name: str, accelerator: str, rec) -> tuple[bool, float]:
    """Two fits of a small model with one seed on one device: (identical, max |difference|)."""
    states = [train(name, {**SMALL[name], "max_epochs": 2, "seed": 7, "accelerator": accelerator}, rec)[0]
              .net_.state_dict() for _ in range(2)]
    diff = max(float((states[0][k].double() - states[1][k].double()).abs().max()) for k in states[0])
    return diff == 0.0, diff


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=15)
    ap.add_argument("--models", default="lstm,ss")
    ap.add_argument("--data", default=None, help="SNLS80mV.csv (default: $EAP_SILVERBOX, else ../shared/benchmarks/silverbox beside the checkout)")
    args = ap.parse_args()
    import torch
    if not torch.cuda.is_available():
        print(f"torch {torch.__version__}: torch.cuda is not available on this machine; nothing to check")
        return 0
    print(f"torch {torch.__version__}, {torch.cuda.get_device_name(0)}, {os.cpu_count()} CPU cores")
    from physics.errors import InputError
    try:
        train_rec, test_rec = silverbox(args.data or os.environ.get("EAP_SILVERBOX"))
    except InputError as exc:
        print(f"gpu_check: {exc}")
        return 2
    names = [m.strip() for m in args.models.split(",") if m.strip()]
    ok = True
    print(f"\n{'model':6s} {'device':6s} {'epochs':>6s} {'wall s':>8s} {'test RMSE mV':>13s}", flush=True)
    walls = {}
    for name in names:
        for acc in ("cpu", "gpu"):
            try:
                m, wall, err = train(name, {"max_epochs": args.epochs, "seed": 0, "accelerator": acc}, train_rec, test_rec)
            except Exception as exc:  # noqa: BLE001 - report and go on with the next
                print(f"{name:6s} {acc:6s} FAILED: {type(exc).__name__}: {exc}", flush=True)
                ok = False
                continue
            walls[name, acc] = wall
            epochs = (getattr(m, "training_summary_", None) or {}).get("epochs_run", "-")
            print(f"{name:6s} {acc:6s} {epochs!s:>6s} {wall:8.1f} {err:13.3f}", flush=True)
        if (name, "cpu") in walls and (name, "gpu") in walls:
            print(f"{name:6s} CPU/GPU wall-time ratio {walls[name, 'cpu'] / walls[name, 'gpu']:.2f}", flush=True)
    print("\nsame seed, same device, twice (small models, 2 epochs on 8 000 samples):")
    short = train_rec[:8000]
    for name in names:
        for acc in ("cpu", "gpu"):
            try:
                same, diff = same_weights(name, acc, short)
            except Exception as exc:  # noqa: BLE001
                print(f"  {name:6s} {acc}: FAILED: {type(exc).__name__}: {exc}")
                ok = False
                continue
            ok &= same
            print(f"  {name:6s} {acc}: {'identical weights' if same else f'weights DIFFER (max {diff:.3g})'}")
    print("\nGPU check: " + ("passed" if ok else "FAILED"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
