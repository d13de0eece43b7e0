"""Tutorial 6: your own plant, in its own unit — a water tank (pump voltage in, level in cm
out) — through the same dataset, training and prediction commands.

Run from anywhere:  python docs/tutorials/t6_your_plant.py
"""
from pathlib import Path

import numpy as np

import nnmodel
from _tutorial import check, eap, out, read_json

OUT = out("t6")
TANK = Path("data/tank")

# --- 1. The files: semicolons, decimal commas, the level in cm ---------------------------------
print("".join((TANK / "train.csv").open(encoding="utf-8").readlines()[:3]))

# --- 2. A dataset whose output is a level in cm ------------------------------------------------
COLUMNS = "time=t [s],voltage=pump [V],level=level [cm]"
eap("dataset", "--train", TANK / "train.csv", "--test", TANK / "test.csv", "--columns", COLUMNS,
    "--output", "level:cm", "--out", OUT / "dataset", "--overwrite")
card = read_json(OUT / "dataset" / "dataset.json")
check(card["output"]["name"] == "level" and card["rh_levels"] is None,
      f"the dataset's output is the level (stored in {card['output']['unit']}), and it has no humidity")

# --- 3. Train a network; the linear row is the yardstick ------------------------------------
eap("train-compare", OUT / "dataset", "--models", "ff", "--out", OUT / "train", "--overwrite", "--quiet")
ff = read_json(OUT / "train" / "compare.json")["models"]["ff"]
check(ff["vs_linear_pct"] < -50, f"the network is {-ff['vs_linear_pct']:.0f} % below the best linear model on the test record")

# --- 4. Predict; the output column is named after the plant's output ---------------------------
eap("predict", "--model", OUT / "train" / "models" / "ff", "--input", TANK / "test.csv", "--columns", COLUMNS,
    "--out", OUT / "level_prediction.csv", "--overwrite")
header = (OUT / "level_prediction.csv").open(encoding="utf-8").readline().strip().split(",")
print(header)
check(any(h.startswith("level_") for h in header), "the prediction's column is a level, with its unit")

bundle = nnmodel.load(OUT / "train" / "models" / "ff")
table = np.genfromtxt(TANK / "test.csv", delimiter=";", skip_header=1,
                      converters={i: lambda s: float(s.replace(",", ".")) for i in range(3)})
level = bundle.predict(table[:, 1], fs=2.0)             # the model's output unit (see the card)
print(f"Python: {level.size} samples predicted, first {level[:3]}")
check(level.size == table.shape[0] and np.all(np.isfinite(level)), "nnmodel.load(...).predict gives one value per sample")
