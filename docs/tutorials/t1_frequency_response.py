"""Tutorial 1: simulate an IPMC strip and read its frequency response across humidity.

Run from anywhere:  python docs/tutorials/t1_frequency_response.py
"""
import numpy as np

import physics
from physics import signals
from _tutorial import check, eap, out

OUT = out("t1")

# --- 1. The frequency response per volt at four humidities ---------------------------
# The thesis device ipmc_pt_eg with its default effects (electrode line, solvent
# diffusion, viscoelastic polymer, the humidity maps of Table V).
f = np.logspace(-1, 2, 600)                           # 0.1–100 Hz
print("RH [%]   first resonance [Hz]   gain there [mm/V]   gain at 0.1 Hz [mm/V]")
resonance = {}
for rh in (40, 60, 80, 100):
    fr = physics.frequency_response("ipmc_pt_eg", "default", f, rh=rh)
    f_res, peak = fr.resonance()
    resonance[rh] = f_res
    print(f"{rh:6}   {f_res:20.1f}   {1e3 * peak:17.2f}   {1e3 * fr.magnitude[0]:21.3f}")
check(all(resonance[a] > resonance[b] for a, b in ((40, 60), (60, 80), (80, 100))),
      "the resonance moves down as the polymer takes up water (drier is stiffer)")

# --- 2. Only the humidity effect: the shift is the beam's sqrt(Y) --------------------
# With the humidity maps alone, the first bending mode of the clamped strip goes as
# sqrt(Y(RH)); Table V gives Y = 0.49 GPa at 40 % and 0.18 GPa at 100 %.
bare = {rh: physics.frequency_response("ipmc_pt_eg", "humidity", f, rh=rh).resonance()[0]
        for rh in (40, 100)}
ratio, expected = bare[40] / bare[100], np.sqrt(0.49 / 0.18)
print(f"\nhumidity only: f_res(40 %)/f_res(100 %) = {ratio:.3f}; "
      f"sqrt(Y40/Y100) = {expected:.3f}")
check(abs(ratio / expected - 1) < 0.03,
      "the resonance shift matches sqrt(Y) of Table V within 3 %")

# --- 3. Time domain: a 1 Hz tone agrees with the frequency response ------------------
sig = signals.tone(amplitude=2.0, frequency=1.0, duration=20.0, fs=500.0)
res = physics.simulate("ipmc_pt_eg", "default", sig.t, sig.v, rh=60)
steady = res.deflection[sig.t >= 10.0]                 # after the start-up transient
amplitude = 0.5 * (steady.max() - steady.min())
gain = physics.frequency_response("ipmc_pt_eg", "default", [1.0], rh=60).magnitude[0]
print(f"\n2 V tone at 1 Hz, RH 60 %: simulated amplitude {1e6 * amplitude:.1f} µm, "
      f"2 V x |H(1 Hz)| = {1e6 * 2 * gain:.1f} µm")
check(abs(amplitude / (2 * gain) - 1) < 0.02,
      "the time solver's steady amplitude is 2 V x |H| within 2 %")

# --- 4. The same from the command line -----------------------------------------------
eap("frf", "--device", "ipmc_pt_eg", "--rh", "60", "--json", OUT / "frf_rh60.json",
    "--csv", OUT / "frf_rh60.csv", "--plot", OUT / "frf_rh60.png", "--overwrite")
check((OUT / "frf_rh60.png").is_file() and (OUT / "frf_rh60.csv").is_file(),
      "eap frf wrote the table and the Bode plot")
eap("simulate", "--device", "ipmc_pt_eg", "--signal", "sweep", "--rh", "60",
    "--out", OUT / "sweep", "--overwrite")
check(any((OUT / "sweep").glob("*.csv")),
      "eap simulate wrote the record (CSV + sidecar) and its plots")
