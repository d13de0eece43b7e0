"""Synthetic measurements with a hidden effect, for the demo and the tests.

:func:`hidden_effect_case` simulates a device *with* one extra catalog effect (the
"truth") and measures it through the realistic sensor of :mod:`physics.io.sensor`; the user's
model is the same device *without* it.  Parameters are randomised (seeded) within
plausible ranges — the base's too, so the diagnosis has to fit them:

==========================  ===================================================================
hidden effect               randomised parameters
==========================  ===================================================================
(all)                       kf ×U(0.8, 1.25), beta_f ×U(0.8, 1.25), Y ×U(0.85, 1.15)
electrode_resistance        Rs log-uniform 20–150 Ω/□
fractional_coupling         frac_a U(0.25, 0.6); kf0 so that |kf(1 Hz)| = kf ×U(0.7, 1.4)
solvent_diffusion           h²/Ds log-uniform 8–60 s (water-like; the IPMC's ethylene glycol is ~1 h)
viscoelastic                dma_scale U(0.75, 1.35) on the device's DMA table
humidity                    Table V maps of Y and kf raised to a power U(0.7, 1.3) (the RH
                            dependence 30 % weaker to 30 % stronger than the thesis's)
nonlinear_charge            C_max log-uniform 1500–8000 mol/m³
==========================  ===================================================================

Excitation per effect (:func:`design_for`, from the ``reveal`` rule of the effect's spec):
a logarithmic swept sine 0.1–50 Hz at RH 60 % for every effect; plus a square pulse
(20 s on, 40 s off) for ``solvent_diffusion``; sweeps at RH 40, 70 and 100 % for
``humidity``; the sweep at two amplitudes (×4) for ``nonlinear_charge``.  The amplitude
keeps the largest deflection near 2 mm (the laser's range is ±5 mm).  ``design="rich"``
gives every case all of these records (every candidate can then be evaluated).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from .. import signals
from ..device import Device, load_device
from ..errors import InputError
from ..solvers.frequency import frequency_response
from ..identify.free_parameters import switchable
from ..model import ActuatorModel
from ..io.sensor import SensorModel
from ..solvers.timedomain import simulate
from ..io.timeseries import TimeSeries
from ..effects import EFFECTS
from ..diagnose.specs import spec_of

#: record kinds that satisfy each ``reveal`` rule of an effect's spec beyond the sweep
_RULE_RECORDS = {"hold_s": "pulse", "rh_levels": "rh", "amplitude_levels": "amplitudes"}
RICH = ("sweep", "pulse", "rh", "amplitudes")
PEAK_M = 2.0e-3


@dataclass
class HiddenEffectCase:
    """Measurements (TimeSeries, sensor applied) of a device with ``hidden`` switched on."""

    hidden: str | None
    device: str
    base_effects: tuple[str, ...]
    truth_effects: tuple[str, ...]
    truth_params: dict
    measurements: list
    design: tuple[str, ...]
    noise_floor: float
    notes: list[str] = field(default_factory=list)

    def describe(self) -> dict:
        return {"hidden": self.hidden, "device": self.device, "base_effects": list(self.base_effects),
                "truth_effects": list(self.truth_effects), "truth_params": self.truth_params,
                "design": list(self.design), "records": [m.source for m in self.measurements],
                "noise_floor_m": self.noise_floor}


def design_for(effect: str | None) -> tuple[str, ...]:
    """Records that let the diagnosis see ``effect``: the sweep, plus what its spec's ``reveal``
    rule asks for (a long hold: the pulse; RH levels; amplitude levels)."""
    rule = spec_of(effect).get("reveal", {}) if effect else {}
    return ("sweep",) + tuple(kind for key, kind in _RULE_RECORDS.items() if key in rule)


def hidden_effects() -> tuple[str, ...]:
    """Effects a demo or test bed can hide: those whose module says how to draw a hidden
    truth (the ``draw_truth`` hook, :mod:`physics.effects.base`)."""
    return tuple(e for e, cls in EFFECTS.items() if spec_of(e) and callable(getattr(cls, "draw_truth", None)))


def draw_truth(effect: str | None, dev: Device, rng: np.random.Generator) -> tuple[Device, dict]:
    """The device of a hidden-effect case: the base's gain, damping and stiffness drawn
    around the device's (kf ×U(0.8, 1.25), beta_f ×U(0.8, 1.25), Y ×U(0.85, 1.15)), then the
    hidden effect's own parameters drawn by its ``draw_truth`` hook.  Returns (device, the
    values drawn)."""
    p = dev.params
    tp = {"kf": p["kf"] * rng.uniform(0.8, 1.25), "beta_f": p["beta_f"] * rng.uniform(0.8, 1.25),
          "Y": p["Y"] * rng.uniform(0.85, 1.15)}
    truth = dev.with_params(**tp)
    if effect is not None:
        truth, own = EFFECTS[effect].draw_truth(truth, rng)
        tp.update(own)
    return truth, tp


def hidden_effect_case(effect: str | None = None, seed: int = 0, *, device: str = "ipmc_pt_eg",
                       base_effects: str | tuple = "none", fs: float = 500.0, duration: float = 60.0,
                       design: str | tuple = "auto", sensor: SensorModel | None = None) -> HiddenEffectCase:
    """Measurements of ``device`` with ``effect`` added to ``base_effects`` (None: no hidden
    effect); see the module doc.  ``fs`` [Hz] and ``duration`` [s] of each record."""
    if effect is not None and effect not in hidden_effects():
        raise InputError(f"effect {effect!r}: choose one of {', '.join(hidden_effects())}")
    rng = np.random.default_rng(seed)
    dev = load_device(device)
    base_ids = ActuatorModel(dev, base_effects).effect_ids
    if effect in base_ids:
        raise InputError(f"{effect} is already in the base effects {list(base_ids)}")
    truth_dev, tp = draw_truth(effect, dev, rng)
    truth_ids = switchable(base_ids) + ((effect,) if effect else ())
    truth = ActuatorModel(truth_dev, truth_ids or "none")
    parts = RICH if design == "rich" else (design_for(effect) if design == "auto" else tuple(design))
    rh_list = [60.0] + ([40.0, 100.0] if "rh" in parts else [])
    if "rh" in parts:
        rh_list = [40.0, 70.0, 100.0]
    f = np.geomspace(0.1, 50.0, 300)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        peak = max(float(np.max(np.abs(frequency_response(truth, None, f, rh=rh).deflection))) for rh in rh_list)
    amp = float(f"{min(1.0, PEAK_M / peak):.2g}")
    if "amplitudes" in parts:
        amp = float(f"{min(0.1, PEAK_M / peak / 4):.2g}")
    sensor = sensor or SensorModel()
    plan = []
    for rh in rh_list:
        plan.append(("sweep", amp, rh))
    if "amplitudes" in parts:
        plan.append(("sweep", 4 * amp, rh_list[0]))
    if "pulse" in parts:
        plan.append(("pulse", amp, rh_list[0]))
    out = []
    for k, (kind, a, rh) in enumerate(plan):
        if kind == "sweep":
            sig = signals.sweep(a, 0.1, 50.0, duration, fs)
            hold = "cubic"
        else:
            sig = signals.square(a, t_on=20.0, t_off=40.0, cycles=1, fs=fs)
            hold = "linear"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            y = simulate(truth, None, sig.t, sig.v, rh=rh, hold=hold).deflection
            ts = TimeSeries(sig.t, sig.v, y, rh=np.full(sig.t.size, rh), meta={"signal": sig.describe()},
                            source=f"{kind}_{a:g}V_RH{rh:g}")
            out.append(sensor.apply(ts, seed=int(rng.integers(2 ** 31))))
    return HiddenEffectCase(effect, dev.name, base_ids, truth.effect_ids, tp, out, parts, sensor.noise_floor())


def run_hidden_effect(effect: str | None = None, seed: int = 0, *, out=None, overwrite: bool = False,
                      device: str = "ipmc_pt_eg", design: str = "auto", fs: float = 500.0, duration: float = 60.0,
                      progress=None, **kw):
    """Generate a case (random effect unless given), diagnose it with the base model and
    (with ``out``) write the report folder (:func:`~physics.diagnose.report.write_diagnosis`:
    ``overwrite`` replaces only a folder eap wrote).  Returns (case, result)."""
    from ..diagnose.diagnosis import diagnose
    from ..diagnose.report import write_diagnosis
    if effect == "random":
        effect = hidden_effects()[int(np.random.default_rng(seed).integers(len(hidden_effects())))]
    case = hidden_effect_case(effect, seed, device=device, design=design, fs=fs, duration=duration)
    res = diagnose(case.measurements, device, case.base_effects, progress=progress, seed=seed, **kw)
    if out is not None:
        write_diagnosis(res, out, provenance={"demo": case.describe()}, overwrite=overwrite)
    return case, res


def outside_truth_text(kind: str, tp: dict) -> str:
    """The truth of an :func:`outside_catalog_case` in words, with its parameters and units."""
    if kind == "creep":
        return f"a creeping tip: load × (1 + r/(1 + sτ)), r = {tp['creep_r']:.3g}, τ = {tp['creep_tau_s']:.3g} s"
    if kind == "backlash":
        return f"a play (backlash) of width {1e6 * tp['play_width_m']:.3g} µm on the output"
    if kind == "lowpass":
        return f"a first-order low-pass on the output (a slow sensor), cut-off {tp['cutoff_Hz']:.3g} Hz"
    if kind == "drift":
        return (f"an additive drift {1e6 * tp['drift_m']:+.3g} µm × (1 − e^(−t/τ)) from each record's start, "
                f"τ = {tp['drift_tau_s']:.3g} s")
    return (f"a viscoelastic polymer with another law than the DMA table: storage "
            f"+{100 * tp['storage_rise_per_decade']:.3g} % per decade, loss tangent {tp['tan_delta']:.3g}")


#: Truths outside the catalog (:func:`outside_catalog_case`), each with its randomised parameters.
OUTSIDE = ("creep", "backlash", "twin", "lowpass", "drift")


def outside_catalog_case(kind: str, seed: int = 0, *, device: str = "ipmc_pt_eg", fs: float = 500.0,
                         duration: float = 60.0, lab: bool = False, clean: bool = False):
    """Measurements of the bare ``device`` (effects none) with physics the catalog does not
    have, made here and nowhere else: ``creep`` (tip load × (1 + r/(1+sτ)), r U(0.25, 0.4), τ
    log-uniform 10–30 s), ``backlash`` (a play of width U(60, 100) µm on the output), ``twin``
    (an effect's near twin, drawn by its ``draw_twin`` hook: a viscoelastic polymer with
    another law than the DMA table), ``lowpass`` (a first-order low-pass on the output,
    cut-off log-uniform 12–25 Hz, that the sensor metadata do not state), ``drift`` (an
    additive A·(1 − e^(−t/τ)) from each record's start, |A| log-uniform 8–20 µm with a random
    sign, τ log-uniform 5–60 s).  A sweep 0.1–50 Hz and a 20 s pulse (the twin: the
    sweep), ~2 mm peak, the default sensor.  ``lab``: records as a lab exports them (a sensor with
    3 µm white noise, 0.1 µm steps, an offset ±U(0.03, 0.07) mm, a random-walk drift U(3, 10) µm
    and 0.15 % RMS hygrometer jitter; metadata state neither the excitation nor the sensor;
    write them with ``units={"deflection": "mm"}``).
    Returns (records, truth parameters), and the true deflection per record [m] (what the
    sensor sees) with ``clean``."""
    from scipy.signal import lfilter
    from ..diagnose.forms.play import play
    from ..diagnose.records import sensor_filter
    if kind not in OUTSIDE:
        raise InputError(f"kind {kind!r}: choose one of {', '.join(OUTSIDE)}")
    rng = np.random.default_rng(seed)
    dev = load_device(device)
    truth, tp = ActuatorModel(dev, "none"), {}
    if kind == "creep":
        tp = {"creep_r": float(rng.uniform(0.25, 0.4)), "creep_tau_s": float(np.exp(rng.uniform(np.log(10), np.log(30))))}
    elif kind == "backlash":
        tp = {"play_width_m": float(rng.uniform(60e-6, 100e-6))}
    elif kind == "lowpass":
        tp = {"cutoff_Hz": float(np.exp(rng.uniform(np.log(12.0), np.log(25.0))))}
    elif kind == "drift":
        tp = {"drift_m": float(rng.choice([-1.0, 1.0]) * np.exp(rng.uniform(np.log(8e-6), np.log(20e-6)))),
              "drift_tau_s": float(np.exp(rng.uniform(np.log(5.0), np.log(60.0))))}
    else:
        twin = next(e for e, c in EFFECTS.items() if callable(getattr(c, "draw_twin", None)))
        twin_dev, tp = EFFECTS[twin].draw_twin(dev, rng)
        truth = ActuatorModel(twin_dev, twin)
    plan = [(signals.sweep(1.0, 0.1, 50.0, duration, fs), "cubic")]
    if kind != "twin":
        plan.append((signals.square(1.0, t_on=20.0, t_off=40.0, cycles=1, fs=fs), "linear"))
    out, true = [], []
    for k, (sig, hold) in enumerate(plan):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            y = simulate(truth, None, sig.t, sig.v, rh=60.0, hold=hold).deflection
        g = min(1.0, PEAK_M / float(np.max(np.abs(y))))
        v, y = sig.v * g, y * g
        if kind == "creep":
            a = math.exp(-1.0 / (tp["creep_tau_s"] * fs))
            y = y + tp["creep_r"] * lfilter([1 - a], [1, -a], y)
        elif kind == "backlash":
            y = play(y, tp["play_width_m"])
        elif kind == "lowpass":
            y = sensor_filter(y, fs, tp["cutoff_Hz"])        # exact in continuous time (a discrete
            #                                                   filter's phase error near fs/10 is not physics)
        elif kind == "drift":
            y = y - tp["drift_m"] * np.expm1(-sig.t / tp["drift_tau_s"])
        ts = TimeSeries(sig.t, v, y, rh=np.full(sig.t.size, 60.0), meta={"signal": sig.describe()},
                        source=f"{kind}_{'sweep' if k == 0 else 'pulse'}")
        sensor = SensorModel(deflection_noise=3e-6, deflection_step=1e-7, bandwidth=None, rh_noise=0.15,
                             deflection_offset=float(rng.choice([-1.0, 1.0]) * rng.uniform(3e-5, 7e-5)),
                             deflection_drift=float(rng.uniform(3e-6, 10e-6))) if lab else SensorModel()
        m = sensor.apply(ts, seed=int(rng.integers(2 ** 31)))
        if lab:
            m.meta.pop("signal", None)
            m.meta.pop("sensor", None)
        out.append(m)
        true.append(y)
    return (out, tp, true) if clean else (out, tp)


@dataclass
class OutsideLoop:
    """The out-of-catalog loop run by :func:`outside_loop` (diagnoses of :mod:`.diagnosis`,
    the drafting outcome of :mod:`.draft`)."""

    kind: str
    truth: dict
    files: list                       # the records as written (CSV)
    true_error: float                 # m: measurement − true deflection, nuisance terms removed (as scored)
    before: object                    # diagnosis of the bare model
    outcome: object                   # the drafts (kept, rejected) with their evidence
    checks: dict                      # kept draft file → contract problems ([] = passed)
    after: object | None              # diagnosis with the kept drafts as candidates (None: none kept)


def outside_loop(kind: str, seed: int, folder, *, device: str = "ipmc_pt_eg", fs: float = 200.0,
                 duration: float = 60.0, lab: bool = True) -> OutsideLoop:
    """The loop a user runs on records with physics outside the catalog: the records of
    :func:`outside_catalog_case` written into ``folder/records`` (``lab``: as a lab exports
    them, tip in mm) and read back, the diagnosis of the bare ``device`` (effects none), what
    remains drafted as effect files into ``folder/drafts`` (contract-checked) by the rounds
    ``eap diagnose`` runs (:func:`.draft.draft_effects` with :func:`.draft.rediagnosis`), and
    the diagnosis again with the kept drafts as candidates (what ``--effects-path`` does).
    ``folder`` is created; its parent must exist."""
    from pathlib import Path
    from ..effects import load_effects_file, unregister
    from ..analysis.metrics import remove_nuisance
    from ..io.timeseries import write_timeseries
    from ..diagnose.diagnosis import diagnose
    from ..diagnose.draft import draft_effects, rediagnosis, write_drafts
    from ..identify.options import FitOptions
    folder = Path(folder)
    ms, truth, clean = outside_catalog_case(kind, seed, device=device, fs=fs, duration=duration, lab=lab, clean=True)
    (folder / "records").mkdir(parents=True)
    files = [write_timeseries(m, folder / "records" / f"{m.source}.csv", units={"deflection": "mm"} if lab else None)
             for m in ms]
    err = [remove_nuisance(m.deflection - y, m.time) for m, y in zip(ms, clean)]
    true_error = float(np.sqrt(sum(float(e @ e) for e in err) / sum(e.size for e in err)))
    before = diagnose(files, device, "none")
    outcome = draft_effects(before, rediagnosis(files, before, FitOptions()))
    checks = write_drafts(outcome.kept, folder / "drafts") if outcome.kept else {}
    ids = [i for d in outcome.kept for i in load_effects_file(folder / "drafts" / d.file_name)]
    try:
        after = diagnose(files, device, "none") if ids else None
    finally:
        for i in ids:
            unregister(i)
    return OutsideLoop(kind, truth, files, true_error, before, outcome, checks, after)
