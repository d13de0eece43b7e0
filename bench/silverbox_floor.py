"""How much of a free-run error on Silverbox's multisine test no input-driven model can remove.

Silverbox's test part is odd random-phase multisines (Wigren and Schoukens, 2013): each block one
period of 8192 samples whose odd DFT lines up to 200 Hz are all excited and whose even lines are
not.  A model error of the response to the drive shows on the lines the drive excites (the
linear part and the odd-order distortion the circuit's cubic term makes) and, for even-order
distortion, on the even lines; a disturbance that does not come from the drive (noise entering
before the resonance, sensor noise) spreads over all lines alike.  For each model bundle of a
finished ``eap train-compare`` run this script predicts the test record in free run (as
``eap predict`` does), takes each complete period of the test part (the input's zero gaps mark
them), and prints, band by band, the mean residual power per odd (excited) and per even line.
Where the even lines carry as much residual as the odd ones the error is mostly not the drive's
response; the printed floor is the RMS error left if the odd lines fell to the even lines' level
(an estimate: even-order distortion a model misses counts towards it, so it is an upper bound of
the noise and a lower bound of what a model can reach only if its even-order response is right).

    python bench/silverbox_floor.py --run RUN [--models ff,ss] [--data SNLS80mV.csv]

RUN is a ``train-compare`` output trained on ``bench/silverbox_generic.py``'s split.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

os.environ.setdefault("EAP_SILVERBOX", str(Path(__file__).resolve().parents[2] / "shared" / "benchmarks" / "silverbox"))

TEST = (105712, 127400)                        # the standard multisine test part
PERIOD, FS = 8192, 610.35                      # samples per multisine period, sampling rate [Hz]
BANDS = ((1, 40), (40, 55), (55, 65), (65, 80), (80, 120), (120, 200))      # Hz
GAP_RMS, GAP_SAMPLES = 2e-3, 10                # a zero gap: the input's 50-sample RMS below 2 mV for 10+ samples


def periods(u: np.ndarray) -> list[int]:
    """Starts (indices of ``u``) of the complete multisine periods that follow a zero gap: the first
    sample after each gap that leaves the gap's level by more than five times its spread."""
    mean = np.convolve(u, np.ones(50) / 50, "same")
    rms = np.sqrt(np.convolve((u - mean) ** 2, np.ones(50) / 50, "same"))
    low = np.flatnonzero(rms < GAP_RMS)
    if low.size == 0:
        return []
    starts = []
    for run in np.split(low, np.flatnonzero(np.diff(low) > 1) + 1):
        if run.size < GAP_SAMPLES:
            continue
        gap = u[run]
        level, spread = np.median(gap), max(float(np.std(gap)), 1e-9)
        away = np.flatnonzero(np.abs(u[run[0]:] - level) > 5.0 * spread)
        if away.size and run[0] + away[0] + PERIOD <= u.size:
            starts.append(int(run[0] + away[0]))
    return starts


def line_powers(residual: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies [Hz] and power per DFT line of one period of ``residual`` [V²]."""
    r = np.fft.rfft(residual)
    return np.arange(r.size) * FS / PERIOD, np.abs(r) ** 2 * 2.0 / PERIOD ** 2


def error_split(residual: np.ndarray, starts: list[int]) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Mean residual power per odd and per even DFT line in each of :data:`BANDS` [V²/line]
    (averaged over the periods starting at ``starts``), the RMS residual over those periods [V],
    and the RMS residual left if each band's odd lines fell to its even lines' level [V]."""
    odd_p, even_p, total, excess = np.zeros(len(BANDS)), np.zeros(len(BANDS)), [], 0.0
    for s in starts:
        f, pw = line_powers(residual[s:s + PERIOD])
        k = np.arange(f.size)
        for i, (lo, hi) in enumerate(BANDS):
            band = (f >= lo) & (f < hi)
            odd, even = pw[band & (k % 2 == 1)], pw[band & (k % 2 == 0)].mean()
            odd_p[i] += odd.mean() / len(starts)
            even_p[i] += even / len(starts)
            excess += max(odd.sum() - even * odd.size, 0.0) / len(starts)     # the odd lines above the even level
        total.append(np.mean(residual[s:s + PERIOD] ** 2))
    rmse = float(np.sqrt(np.mean(total)))
    return odd_p, even_p, rmse, float(np.sqrt(max(rmse ** 2 - excess, 0.0)))


def predict(bundle: Path, record: Path, out: Path) -> np.ndarray:
    from nnmodel.app.cli import main
    if main(["predict", "--model", str(bundle), "--input", str(record), "--out", str(out), "--quiet", "--overwrite"]):
        sys.exit(f"eap predict failed for {bundle}")
    import pandas as pd
    return pd.read_csv(out).iloc[:, -1].to_numpy()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="an eap train-compare output folder (RUN/models/<name>)")
    ap.add_argument("--models", default=None, help="comma-separated bundles (default: every bundle but linear)")
    ap.add_argument("--data", default=None, help="SNLS80mV.csv (default: $EAP_SILVERBOX)")
    args = ap.parse_args(argv)
    import pandas as pd
    data = Path(args.data or os.environ["EAP_SILVERBOX"])
    data = data / "SNLS80mV.csv" if data.is_dir() else data
    raw = pd.read_csv(data)
    u, y = raw["V1"].to_numpy()[slice(*TEST)], raw["V2"].to_numpy()[slice(*TEST)]
    starts = periods(u)
    run = Path(args.run)
    names = args.models.split(",") if args.models else sorted(
        p.name for p in (run / "models").iterdir() if (p / "card.json").is_file() and p.name != "linear")
    print(f"{data.name} test [{TEST[0]}:{TEST[1]}]: {len(starts)} complete periods of {PERIOD} samples "
          f"(from test sample {', '.join(map(str, starts))})")
    u_odd, u_even, _, _ = error_split(u - u.mean(), starts)
    print(f"the input's power on the even lines is {u_even.sum() / u_odd.sum():.1e} of the odd lines' "
          "(near zero: the periods are aligned)")
    with tempfile.TemporaryDirectory(prefix="eap-floor-") as tmp:
        record = Path(tmp) / "test.csv"
        pd.DataFrame({"time_s": np.arange(u.size) / FS, "voltage_V": u, "y_V": y}).to_csv(record, index=False)
        for name in names:
            pred = predict(run / "models" / name, record, Path(tmp) / f"{name}.csv")
            odd_p, even_p, rmse, floor = error_split(pred - y, starts)
            print(f"\n{name}: free-run RMS error on these periods {1e3 * rmse:.3f} mV")
            print(f"  {'band Hz':>9s} {'odd (excited) V²/line':>22s} {'even V²/line':>13s} {'odd/even':>9s}")
            for (lo, hi), o, e in zip(BANDS, odd_p, even_p):
                print(f"  {lo:>4d}-{hi:<4d} {o:22.3g} {e:13.3g} {o / e:9.2f}")
            print(f"  the error if every band's odd lines fell to its even lines' level: {1e3 * floor:.3f} mV "
                  f"({100 * floor ** 2 / rmse ** 2:.0f} % of the error power is at the even lines' level)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
