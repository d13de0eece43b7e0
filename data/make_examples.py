"""Make the example records in ``data/`` (fixed seed; described in ``data/README.md``).

    python data/make_examples.py            # rewrites the shipped files
    python data/make_examples.py --out DIR  # writes them elsewhere (the tests compare the two)

Three record sets, each exported as a laboratory's acquisition software would:

``ipmc_humidity/``
    An IPMC strip (the ``ipmc_pt_eg`` device) whose stiffness and coupling change with
    humidity — the hidden effect ``humidity`` — driven by 1 V swept sines (0.1–20 Hz) at
    RH 45, 65 and 85 % and a 1 V pulse at 65 %.  Standard columns (``time_s``, ``voltage_V``,
    ``deflection_mm``, ``rh_pct``), tip in mm.
``ipmc_creep/``
    The same kind of strip at RH 50 % with a slow creep of the tip, r/(1 + sτ), that no
    effect of the catalog has: a sweep and a pulse, in the instrument's own headers
    (``Time (s)``, ``Drive (V)``, ``Tip (mm)``), semicolon-separated; RH in the sidecar.
``tank/``
    Not an actuator: a water tank filled by a pump (voltage in, level in cm out, outflow
    through an orifice, q ∝ √level), for the tutorial on a plant in any unit.

Every record carries the sensor's noise (white, a quantisation step, an offset and a slow
random-walk drift) and a sidecar ``NAME.yaml`` saying what a lab would write down.  The
truths (the parameters the records were made with) are printed in ``data/README.md``.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import yaml

SEED = 2026
FS_HZ = 100.0                 # actuator records' sampling rate
DURATION_S = 30.0             # each actuator record
NOISE_M = 3e-6                # laser: RMS white noise [m]
STEP_M = 1e-7                 # and its resolution [m] (4 decimals in mm)
HERE = Path(__file__).resolve().parent
RH_LEVELS = (45.0, 55.0, 65.0, 75.0, 85.0)   # ipmc_humidity's swept sines [%]

# The hidden truths (quoted in data/README.md).
HUMIDITY_TRUTH = {"kf_factor": 1.15, "beta_f_factor": 0.85, "humidity_power": 1.2}
CREEP_TRUTH = {"creep_r": 0.3, "creep_tau_s": 8.0, "rh_pct": 50.0}
TANK_TRUTH = {"area_cm2": 150.0, "pump_cm3_per_s_per_V": 30.0, "outflow_cm2.5_per_s": 9.0, "fs_Hz": 2.0}


def _sensor(y: np.ndarray, t: np.ndarray, rng: np.random.Generator, offset_m: float) -> np.ndarray:
    """The laser's view of the tip deflection ``y`` [m]: offset, a random walk of ~1.5 µm over
    the record, white noise, quantisation."""
    walk = np.cumsum(rng.normal(0.0, 1.5e-6 / math.sqrt(y.size), y.size))
    m = y + offset_m + walk + rng.normal(0.0, NOISE_M, y.size)
    return np.round(m / STEP_M) * STEP_M


def _truth_device():
    """The strip behind ``ipmc_humidity``: the thesis device, its gain and damping a little
    off the nominal values, its humidity maps (Table V) raised to a power (stronger)."""
    import dataclasses
    import physics
    dev = physics.load_device("ipmc_pt_eg")
    p = dev.params
    dev = dev.with_params(kf=p["kf"] * HUMIDITY_TRUTH["kf_factor"], beta_f=p["beta_f"] * HUMIDITY_TRUTH["beta_f_factor"])
    g = HUMIDITY_TRUTH["humidity_power"]
    maps = {}
    for name, m in dev.humidity_maps.items():
        ref = float(np.interp(dev.reference_rh, m.rh, m.values))
        maps[name] = dataclasses.replace(m, values=ref * (m.values / ref) ** g)
    return dataclasses.replace(dev, humidity_maps=maps)


def _excitations():
    from physics import signals
    sweep = signals.sweep(1.0, 0.1, 20.0, DURATION_S, FS_HZ)
    pulse = signals.square(1.0, t_on=10.0, t_off=DURATION_S - 10.0, cycles=1, fs=FS_HZ)
    return sweep, pulse


def _csv(path: Path, header: list[str], columns: list[np.ndarray], formats: list[str], sep: str = ",",
         decimal: str = ".") -> None:
    lines = [sep.join(header)]
    for row in zip(*columns):
        text = sep.join(f % v for f, v in zip(formats, row))
        lines.append(text.replace(".", decimal) if decimal != "." else text)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8", newline="")


def _sidecar(path: Path, meta: dict) -> None:
    path.with_suffix(".yaml").write_text(yaml.safe_dump(meta, sort_keys=False, allow_unicode=True),
                                         encoding="utf-8", newline="")


LAB_SENSOR = {"model": "laser triangulation sensor on the strip's tip", "noise_rms_um": 3.0, "resolution_nm": 100}


def make_humidity(out: Path, rng: np.random.Generator) -> None:
    import physics
    dev = _truth_device()
    sweep, pulse = _excitations()
    plan = [(f"sweep_rh{rh:g}", sweep, rh) for rh in RH_LEVELS] + [("pulse_rh65", pulse, 65.0)]
    out.mkdir(parents=True, exist_ok=True)
    for name, sig, rh in plan:
        rh_true = rh + float(rng.uniform(-0.4, 0.4))
        hold = "linear" if sig.kind == "square" else "cubic"
        y = physics.simulate(dev, ("humidity",), sig.t, sig.v, rh=rh_true, hold=hold).deflection
        tip = _sensor(y, sig.t, rng, offset_m=4e-5)
        rh_read = np.round(rh_true + rng.normal(0.0, 0.15, y.size), 1)
        _csv(out / f"{name}.csv", ["time_s", "voltage_V", "deflection_mm", "rh_pct"],
             [sig.t, sig.v, tip * 1e3, rh_read], ["%.3f", "%.4f", "%.4f", "%.1f"])
        _sidecar(out / f"{name}.csv", {
            "description": f"IPMC strip (Nafion + Pt), {'1 V swept sine 0.1–20 Hz' if sig.kind == 'sweep' else '1 V pulse, 10 s on'}"
                           f" at RH {rh:g} %",
            "device": "Nafion 117 strip with platinum electrodes, 26 mm x 5 mm, clamped 2 mm",
            "sensor": LAB_SENSOR,
        })


def make_creep(out: Path, rng: np.random.Generator) -> None:
    import physics
    from scipy.signal import lfilter
    sweep, pulse = _excitations()
    out.mkdir(parents=True, exist_ok=True)
    r, tau = CREEP_TRUTH["creep_r"], CREEP_TRUTH["creep_tau_s"]
    a = math.exp(-1.0 / (tau * FS_HZ))
    for name, sig in (("sweep", sweep), ("pulse", pulse)):
        hold = "linear" if sig.kind == "square" else "cubic"
        y = physics.simulate("ipmc_pt_eg", "none", sig.t, sig.v, rh=CREEP_TRUTH["rh_pct"], hold=hold).deflection
        y = y + r * lfilter([1 - a], [1, -a], y)          # tip × (1 + r/(1 + sτ)), discretised
        tip = _sensor(y, sig.t, rng, offset_m=-3e-5)
        _csv(out / f"{name}.csv", ["Time (s)", "Drive (V)", "Tip (mm)"], [sig.t, sig.v, tip * 1e3],
             ["%.3f", "%.4f", "%.4f"], sep=";")
        _sidecar(out / f"{name}.csv", {
            "description": f"IPMC strip at RH 50 %, {'1 V swept sine 0.1–20 Hz' if sig.kind == 'sweep' else '1 V pulse, 10 s on'}",
            "rh_pct": CREEP_TRUTH["rh_pct"],
            "sensor": LAB_SENSOR,
        })


def _tank(u: np.ndarray, fs: float) -> np.ndarray:
    """Level [cm] of a tank of area A fed at k·u and drained through an orifice, dh/dt =
    (k u − c √h)/A, integrated with 20 sub-steps per sample (explicit midpoint)."""
    A, k, c = TANK_TRUTH["area_cm2"], TANK_TRUTH["pump_cm3_per_s_per_V"], TANK_TRUTH["outflow_cm2.5_per_s"]
    h, dt, out = 5.0, 1.0 / fs / 20, np.empty(u.size)
    for i, ui in enumerate(u):
        for _ in range(20):
            mid = max(h + 0.5 * dt * (k * ui - c * math.sqrt(max(h, 0.0))) / A, 0.0)
            h = max(h + dt * (k * ui - c * math.sqrt(mid)) / A, 0.0)
        out[i] = h
    return out


def make_tank(out: Path, rng: np.random.Generator) -> None:
    fs = TANK_TRUTH["fs_Hz"]
    out.mkdir(parents=True, exist_ok=True)
    for name, n_steps in (("train", 40), ("test", 12)):
        hold_s = rng.uniform(20.0, 60.0, n_steps)              # a random staircase of pump voltages
        levels = rng.uniform(1.0, 5.0, n_steps)
        t = np.arange(int(round(hold_s.sum() * fs))) / fs
        u = levels[np.minimum(np.searchsorted(np.cumsum(hold_s), t, side="right"), n_steps - 1)]
        h = _tank(u, fs) + rng.normal(0.0, 0.05, t.size)
        _csv(out / f"{name}.csv", ["t [s]", "pump [V]", "level [cm]"], [t, u, np.round(h, 2)],
             ["%.1f", "%.3f", "%.2f"], sep=";", decimal=",")
        _sidecar(out / f"{name}.csv", {
            "description": f"water tank: pump voltage in, level out ({name} record, a random staircase)",
            "sensor": "ultrasonic level sensor, 0.5 mm RMS noise",
        })


def make_all(out: Path) -> None:
    """Write every record set into ``out`` (its sub-folders created)."""
    rng = np.random.default_rng(SEED)
    make_humidity(out / "ipmc_humidity", rng)
    make_creep(out / "ipmc_creep", rng)
    make_tank(out / "tank", rng)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE, help="folder to write into (default: data/)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(HERE.parent))      # the checkout's package, when run from a clone
    make_all(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
