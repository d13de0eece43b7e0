"""Tutorial 5: train FF, RBF, NARX and LSTM networks on four humidities, compare them,
and predict at a fifth humidity none of them saw.

Run from anywhere:  python docs/tutorials/t5_networks.py
"""
from pathlib import Path

import numpy as np

import nnmodel
from _tutorial import check, eap, out, read_json

OUT = out("t5")
HUMID = Path("data/ipmc_humidity")

# --- 1. The dataset: train at RH 45, 55, 75, 85 %, test at 65 % (held out) -----------
eap("dataset", "--train", *(HUMID / f"sweep_rh{rh}.csv" for rh in (45, 55, 75, 85)),
    "--test", HUMID / "sweep_rh65.csv", "--holdout-rh", "65",
    "--out", OUT / "dataset", "--overwrite")

# --- 2. Train and compare ------------------------------------------------------------
# Budgets are epochs, so the same command gives the same weights on any machine.  They
# are cut here to keep the tutorial short (the recipes' own are in configs/train/).
budgets = ["ff.max_epochs=20", "rbf.max_epochs=20", "rbf.structures=null",
           "narx.max_epochs=5", "lstm.max_epochs=10", "lstm.structures=null"]
eap("train-compare", OUT / "dataset", "--models", "ff,rbf,narx,lstm",
    *(a for s in budgets for a in ("--set", s)), "--out", OUT / "train", "--overwrite",
    "--quiet")
summary = read_json(OUT / "train" / "compare.json")
best = summary["best_heldout"]
print(f"best on the held-out RH: {best['model']} at {100 * best['nrmse']:.1f} % NRMSE")
check(summary["models"][best["model"]]["vs_linear_pct"] < -20,
      "the best network's error at the unseen humidity is 20 % below the linear model's")
check(all((OUT / "train" / "models" / m / "card.json").is_file()
          for m in ("ff", "rbf", "narx", "lstm")),
      "each network is saved as a bundle (card.json + weights) in train/models/")

# --- 3. Predict at RH 65 % from the command line and from Python ---------------------
bundle = OUT / "train" / "models" / best["model"]
eap("predict", "--model", bundle, "--input", HUMID / "sweep_rh65.csv",
    "--init-samples", "0", "--out", OUT / "prediction_rh65.csv", "--overwrite")
pred_cli = np.genfromtxt(OUT / "prediction_rh65.csv", delimiter=",", names=True)
t, v, y_mm, rh = np.loadtxt(HUMID / "sweep_rh65.csv", delimiter=",", skiprows=1,
                            unpack=True)

model = nnmodel.load(bundle)
pred = model.predict(v, rh=rh, fs=100.0)          # tip deflection [m], free run from rest
check(np.allclose(pred, pred_cli["deflection_m"], atol=1e-7),
      "Python and the command line predict the same")
err = 1e-3 * y_mm - pred
nrmse = np.sqrt(np.mean((err - err.mean()) ** 2)) / np.std(1e-3 * y_mm)
print(f"free-run NRMSE at RH 65 %: {100 * nrmse:.1f} %")
check(nrmse < 0.2, "the prediction at the unseen humidity is within 20 % NRMSE")
