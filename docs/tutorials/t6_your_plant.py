"""Tutorial 6: your own plant, in its own unit — a water tank (pump voltage in, level in
cm out) — through the same dataset, training and prediction commands.

Run from anywhere:  python docs/tutorials/t6_your_plant.py
"""
from pathlib import Path

import numpy as np

import nnmodel
from _tutorial import check, eap, out, read_json

OUT = out("t6")
TANK = Path("data/tank")

# --- 1. The files: semicolons, decimal commas, the level in cm -----------------------
print("".join((TANK / "train.csv").open(encoding="utf-8").readlines()[:3]))

# --- 2. A dataset whose output is a level in cm --------------------------------------
COLUMNS = "time=t [s],voltage=pump [V],level=level [cm]"
eap("dataset", "--train", TANK / "train.csv", "--test", TANK / "test.csv",
    "--columns", COLUMNS, "--output", "level:cm", "--out", OUT / "dataset", "--overwrite")
card = read_json(OUT / "dataset" / "dataset.json")
check(card["output"]["name"] == "level" and card["rh_levels"] is None,
      f"the output is the level (in {card['output']['unit']}), and there is no humidity")

# --- 3. Train a network; the linear row is the yardstick -----------------------------
eap("train-compare", OUT / "dataset", "--models", "ff", "--out", OUT / "train",
    "--overwrite", "--quiet")
ff = read_json(OUT / "train" / "compare.json")["models"]["ff"]
check(ff["vs_linear_pct"] < -50,
      f"the network is {-ff['vs_linear_pct']:.0f} % below the best linear model on test")

# --- 4. Predict; the output column is named after the plant's output -----------------
eap("predict", "--model", OUT / "train" / "models" / "ff", "--input", TANK / "test.csv",
    "--columns", COLUMNS, "--out", OUT / "level_prediction.csv", "--overwrite")
header = (OUT / "level_prediction.csv").open(encoding="utf-8").readline().strip()
print(header.split(","))
check("level_cm" in header.split(","), "the prediction's column is the level in cm")

bundle = nnmodel.load(OUT / "train" / "models" / "ff")
text = (TANK / "test.csv").read_text(encoding="utf-8").replace(",", ".")
table = np.loadtxt(text.splitlines()[1:], delimiter=";")   # time, pump, level
level = bundle.predict(table[:, 1], fs=2.0)          # in the card's output unit, cm
print(f"Python: {level.size} samples predicted, the first three {level[:3].round(2)} cm")
check(level.size == table.shape[0] and np.all(np.isfinite(level)),
      "nnmodel.load(...).predict gives one value per sample")
