"""Tutorial 4: the loop — where the model fails, which effect is missing, add it, the
error falls; then physics outside the catalog, drafted as an effect file.

Run from anywhere:  python docs/tutorials/t4_the_loop.py
"""
from pathlib import Path

from _tutorial import check, eap, out, read_json

OUT = out("t4")
HUMID = Path("data/ipmc_humidity")
CREEP = Path("data/ipmc_creep")

# --- 1. Diagnose the bare model on records at three humidities -----------------------
records = [HUMID / "sweep_rh45.csv", HUMID / "sweep_rh65.csv", HUMID / "sweep_rh85.csv",
           HUMID / "pulse_rh65.csv"]
eap("diagnose", *records, "--device", "ipmc_pt_eg", "--effects", "none",
    "--max-effects", "1", "--apply", "--name", "strip_rh",
    "--out", OUT / "diagnose", "--overwrite", "--quiet")
dx = read_json(OUT / "diagnose" / "diagnosis.json")
verdict = dx["verdict"]
check(verdict["missing_effect"] == "humidity" and verdict["confidence_label"] == "high",
      "the diagnosis names the hidden effect, humidity, with high confidence")
picked = next(r for r in dx["ranking"] if r["effect"] == "humidity")
check(picked["rmse_after"] < dx["base"]["rmse"] / 10, "adding it lowers the error "
      f"{1e6 * dx['base']['rmse']:.1f} -> {1e6 * picked['rmse_after']:.2f} µm")
check(verdict["adequacy"]["adequate"],
      "and the model is then adequate (within 1.3x the noise floor)")

# --- 2. The extended device on records the diagnosis never saw (RH 55 and 75 %) ------
unseen = [HUMID / "sweep_rh55.csv", HUMID / "sweep_rh75.csv"]
models = {"bare": ("ipmc_pt_eg", "none"),
          "extended": (OUT / "diagnose" / "strip_rh.yaml", "default")}
rms = {}
for name, (model, effects) in models.items():
    eap("compare", *unseen, "--model", model, "--effects", effects,
        "--out", OUT / f"compare_{name}", "--overwrite")
    report = read_json(OUT / f"compare_{name}" / "report.json")
    rms[name] = report["overall"]["rmse_m_rms"]
check(rms["extended"] < rms["bare"] / 3, "on unseen RH levels the error falls "
      f"{1e6 * rms['bare']:.1f} -> {1e6 * rms['extended']:.1f} µm")

# --- 3. Physics no effect has: a creeping tip ----------------------------------------
LAB = "time=Time (s),voltage=Drive (V),deflection=Tip (mm)"
creep = [CREEP / "sweep.csv", CREEP / "pulse.csv"]
drafts = OUT / "drafts"
eap("diagnose", *creep, "--columns", LAB, "--device", "ipmc_pt_eg", "--effects", "none",
    "--draft-effects", drafts, "--out", OUT / "diagnose_creep", "--overwrite", "--quiet")
dx = read_json(OUT / "diagnose_creep" / "diagnosis.json")
check(dx["verdict"]["status"] == "not explained by the catalog",
      "no catalog effect explains the creep")
draft = drafts / "drafted_slow_pole.py"
check(draft.is_file(), "what remains, a slow pole on the output, is drafted as an effect")
eap("effects", "--check", draft, "--fast")

# --- 4. Pass the draft back: the loop closes -----------------------------------------
eap("diagnose", *creep, "--columns", LAB, "--device", "ipmc_pt_eg", "--effects", "none",
    "--effects-path", draft, "--out", OUT / "diagnose_with_draft", "--overwrite",
    "--quiet")
again = read_json(OUT / "diagnose_with_draft" / "diagnosis.json")
check(again["verdict"]["missing_effect"] == "drafted_slow_pole"
      and again["verdict"]["adequacy"]["adequate"],
      "with the draft as a candidate the diagnosis picks it and the model is adequate")
fitted = next(r for r in again["ranking"]
              if r["effect"] == "drafted_slow_pole")["effect_parameters"]
r, tau = fitted["slow_pole_r"], fitted["slow_pole_tau"]
print(f"drafted slow pole: r = {r:.3f}, tau = {tau:.2f} s")
check(abs(r / 0.3 - 1) < 0.1 and abs(tau / 8.0 - 1) < 0.1,
      "its fitted values are within 10 % of the creep in data/README.md (r 0.3, tau 8 s)")
