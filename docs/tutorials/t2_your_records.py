"""Tutorial 2: bring your own records in — columns, units, sidecars — and compare a
model with them.

Run from anywhere:  python docs/tutorials/t2_your_records.py
"""
from pathlib import Path

from _tutorial import check, eap, out, read_json

OUT = out("t2")
CREEP = Path("data/ipmc_creep")
HUMID = Path("data/ipmc_humidity")

# --- 1. A record as the acquisition software wrote it --------------------------------
# Its own headers, semicolons, the tip in millimetres; the humidity is in the sidecar.
print("".join((CREEP / "sweep.csv").open(encoding="utf-8").readlines()[:4]))
print((CREEP / "sweep.yaml").read_text(encoding="utf-8"))

# --- 2. Compare the bare thesis model with it ----------------------------------------
# --columns maps each quantity to a header; a unit in a header ("Tip (mm)") is used.
LAB = "time=Time (s),voltage=Drive (V),deflection=Tip (mm)"
eap("compare", CREEP / "sweep.csv", CREEP / "pulse.csv", "--columns", LAB,
    "--model", "ipmc_pt_eg", "--effects", "none", "--out", OUT / "compare", "--overwrite")
report = read_json(OUT / "compare" / "report.json")
fit = {Path(r["source"]).stem: r["time_metrics"] for r in report["records"]}
check(fit["sweep"]["fit_percent"] > 90,
      f"the swept sine is followed closely (fit {fit['sweep']['fit_percent']:.1f} %)")
check(not fit["pulse"]["residual_tests"]["white"],
      "but the pulse's residual is not white: something slow is missing (tutorial 4)")
check((OUT / "compare" / "index.html").is_file(),
      "the page index.html shows overlays, residuals and Bode plots")

# --- 3. A dataset from standard files ------------------------------------------------
# These files use the standard column names (time_s, voltage_V, deflection_mm, rh_pct):
# no map needed.  Train on four humidities, test on the fifth, held out.
train = [HUMID / f"sweep_rh{rh}.csv" for rh in (45, 55, 75, 85)]
eap("dataset", "--train", *train, "--test", HUMID / "sweep_rh65.csv",
    "--holdout-rh", "65", "--out", OUT / "dataset", "--overwrite")
card = read_json(OUT / "dataset" / "dataset.json")
print({k: card[k] for k in ("schema", "fs_Hz", "rh_levels", "output", "noise_floor_m")})
check(len(card["files"]) == 5 and all(len(e["sha256"]) == 64 for e in card["files"]),
      "dataset.json lists the five records, each with its SHA-256")
check(abs(card["noise_floor_m"] - 3e-6) < 0.2e-6,
      "the sensor's noise (3 µm, from the sidecars) is the noise floor")
eap("dataset", "--check", OUT / "dataset")
