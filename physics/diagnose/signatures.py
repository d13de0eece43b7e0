"""What each effect leaves in a base model's residuals, and what data can show it.

**Excitation needed** (each effect's spec: ``excitation`` text and ``reveal`` rule, in its
own module; :func:`revealable` applies the rules to the records and says why when the data
cannot reveal an effect).  For the built-in effects:

==========================  ===========================================================================
effect                      data that expose it
==========================  ===========================================================================
electrode_resistance        a swept sine / multisine reaching ≥ 10 Hz: the phase lag that grows with
                            frequency as the voltage falls along the strip
fractional_coupling         a broadband record spanning ≥ 1 decade (constant log-log slope and
                            constant phase), ideally down to 0.1 Hz; a step shows the creep
fractional_charge           (on request) the same, with the electrodes' resistance in the band (the
                            line sees the constant-phase charge, which tells it from
                            fractional_coupling)
solvent_diffusion           low frequencies: a swept sine starting at ≤ 0.5 Hz, or a square pulse /
                            step holding ≥ 5 s (back-relaxation)
viscoelastic                a broadband record spanning the first resonance (peak shape, stiffness
                            that rises with frequency, loss below resonance)
layered_beam                a broadband record spanning the first resonance; usually cannot be told
                            apart from a stiffer Y (both set EI/ρA), reported as such
humidity                    records at two or more RH levels ≥ 10 % apart
nonlinear_charge            the same excitation at two or more amplitudes (ratio ≥ 1.25) at one RH:
                            the gain falls with amplitude; harmonics show at the larger one
thermal                     (not by default) long large-amplitude records
==========================  ===========================================================================

**Signatures** (:func:`signatures`): features of the base's residual frequency response
(measured/model ratio R(f) in the bands where the residual exceeds its noise floor, see
:mod:`.residuals`), of its dependence on amplitude and RH, and of the residual after steps:

* ``lf_droop_lead`` — below ~5× the lowest excited frequency the model overestimates the
  gain and the measurement leads it (|R| < 0.97, arg R > 0.5°): ``solvent_diffusion``;
* ``lf_excess_lag`` — the opposite (|R| > 1.03, arg R < −0.5°): ``fractional_coupling``;
* ``constant_slope_phase`` — log|R| falls (or rises) linearly in log f with a phase
  offset ≈ 90° × slope (decades per decade) away from the resonance: a constant-phase
  element, ``fractional_coupling``;
* ``hf_phase_lag`` — arg R decreases with frequency in the upper decade (≥ 2° per
  decade, ending below −1°): ``electrode_resistance``;
* ``hf_phase_lead`` — the opposite, arg R increases in the upper decade (≥ 2° per decade,
  ending above +1°): the records lead the model (a derivative term in the sensor's
  conditioning, a latency given larger than the setup's), no catalog effect;
* ``resonance_error`` — the error peaks within ±40 % of the first resonance (peak height,
  width or frequency): ``viscoelastic`` (``layered_beam``);
* ``lf_small_lag`` — a nearly constant small phase lag (−0.5° to −10°) below resonance:
  material loss, ``viscoelastic``;
* ``amplitude_dependence`` — the measured/model gain differs by > 3 % between two amplitudes
  of the same kind of excitation at one RH level (:func:`.residuals.amplitude_contrast`):
  ``nonlinear_charge``; ``harmonics`` — > 5 % of the residual at harmonics, beyond the noise;
* ``rh_dependence`` — records of one design (kind, amplitude level, band) at two RH levels differ in
  measured/model gain by > 5 % or leave residuals beyond the noise differing by > 2×
  (:func:`.residuals.rh_contrast`; records of different designs are not compared, and a model with
  parameters per RH level is not read): ``humidity``;
* ``step_back_relaxation`` / ``step_creep`` — after steps the measurement relaxes back
  (``solvent_diffusion``) or keeps creeping (``fractional_coupling``) relative to the model;
* ``slow_trend`` — the residual moves by more than 3× the noise floor from the first to the
  last tenth of every record, in the same direction (a drift of the reading).

Which features each effect is expected to leave is its spec's ``signature``.  Each effect's
score is the weighted share of its expected features that are present,
counting only features the data can show; it is a plausibility check on a candidate
whose fit improved, not evidence by itself.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .records import RH_SPAN, PreparedRecord, amplitude_groups, rh_levels
from .residuals import AMPLITUDE_CHANGE, HARMONIC_SHARE, ResidualAnalysis
from .specs import excitation, signature, spec_of

FEATURE_TEXT = {
    "lf_droop_lead": "low-frequency droop with phase lead",
    "lf_excess_lag": "low-frequency excess gain with phase lag",
    "constant_slope_phase": "constant log-log slope with matching constant phase",
    "hf_phase_lag": "phase lag growing with frequency",
    "hf_phase_lead": "phase lead growing with frequency",
    "resonance_error": "error concentrated at the resonance",
    "lf_small_lag": "small constant phase lag below resonance (material loss)",
    "amplitude_dependence": "gain that depends on amplitude",
    "harmonics": "harmonic distortion",
    "rh_dependence": "a misfit that depends on RH (one design at two RH levels)",
    "step_back_relaxation": "back-relaxation after steps",
    "step_creep": "creep after steps",
    "slow_trend": "a slow trend of the same sign in every record",
}


def _broadband(records) -> list[PreparedRecord]:
    return [r for r in records if r.kind == "broadband"]


def revealable(effect: str, records: Sequence[PreparedRecord], resonance_hz: float | None = None) -> tuple[bool, str]:
    """(can the records reveal ``effect``?, why / why not): the ``reveal`` rule of its spec
    (:data:`physics.effects.base.REVEAL_RULES`); an effect without a rule is tried on every record."""
    rule = spec_of(effect).get("reveal")
    if not rule:
        return True, "no revealability rule (tried on every record)"
    need = excitation(effect)
    bb = _broadband(records)
    tones = sorted({r.tone_hz for r in records if r.kind == "tone" and r.tone_hz})
    f_lo = min([r.band[0] for r in bb] + tones) if (bb or tones) else math.inf
    f_hi = max([r.band[1] for r in bb] + tones) if (bb or tones) else 0.0
    if "f_hi_min" in rule:
        ok = f_hi >= rule["f_hi_min"]
        return ok, (f"excitation reaches {f_hi:.3g} Hz" if ok else f"the excitation stops at {f_hi:.3g} Hz; needs {need}")
    if "decades_min" in rule:
        ok = f_hi / f_lo >= 10.0 ** rule["decades_min"] if f_lo > 0 and math.isfinite(f_lo) else False
        return ok, (f"broadband over {f_lo:.3g}–{f_hi:.3g} Hz" if ok else f"needs {need}")
    if "f_lo_max" in rule or "hold_s" in rule:
        low = f_lo <= rule.get("f_lo_max", -math.inf)
        hold = rule.get("hold_s")
        long_hold = hold is not None and any(
            r.steps.size and np.max(np.diff(np.concatenate([r.steps, [r.v_d.size]]))) / r.fs_d >= hold
            for r in records if r.kind == "steps")
        why = ([f"excitation down to {f_lo:.3g} Hz"] if low else []) + (["steps with long holds"] if long_hold else [])
        return bool(why), ("; ".join(why) if why else f"nothing below {f_lo:.3g} Hz and no long step; needs {need}")
    if rule.get("spans_resonance"):
        if resonance_hz is None:
            ok = f_hi / max(f_lo, 1e-9) >= 10.0
            return ok, ("broadband (resonance not located)" if ok else f"needs {need}")
        ok = f_lo < 0.7 * resonance_hz and f_hi > 1.3 * resonance_hz
        return ok, (f"the excitation spans the first resonance ({resonance_hz:.3g} Hz)" if ok
                    else f"the excitation ({f_lo:.3g}–{f_hi:.3g} Hz) does not span the first resonance "
                         f"({resonance_hz:.3g} Hz); needs {need}")
    if "rh_levels" in rule:
        lv = rh_levels(records)
        ok = len(lv) >= rule["rh_levels"] and lv[-1] - lv[0] >= RH_SPAN
        return ok, (f"RH levels {', '.join(f'{x:g}' for x in lv)} %" if ok else
                    f"all records are at RH {', '.join(f'{x:g}' for x in lv)} %: one RH level cannot reveal "
                    f"{effect}; needs {need}")
    if "amplitude_levels" in rule:
        multi = {rh: a for rh, a in amplitude_groups(records).items() if len(a) >= rule["amplitude_levels"]}
        if multi:
            rh, a = next(iter(multi.items()))
            return True, f"amplitudes {', '.join(f'{x:.3g}' for x in a)} V at RH {rh:g} %"
        amps = sorted({r.amplitude_level for r in records})
        return False, (f"one amplitude level ({', '.join(f'{x:.3g}' for x in amps)} V) per RH: one amplitude cannot "
                       f"reveal {effect} (its gain change is absorbed by kf); needs {need}")
    return True, ""


def features(ra: ResidualAnalysis, records: Sequence[PreparedRecord], resonance_hz: float | None) -> dict:
    """{feature: {"present": bool | None, "value": ...}} (None: the data cannot show it)."""
    out: dict = {}
    frf = ra.frf
    if frf is not None and frf.freq.size >= 3:
        out.update(_frf_features(frf, resonance_hz))
    if ra.amplitude_contrast:
        g = [c["change"] for c in ra.amplitude_contrast]
        out["amplitude_dependence"] = {"present": bool(max(abs(x) for x in g) > AMPLITUDE_CHANGE), "changes": g}
    else:
        out["amplitude_dependence"] = {"present": None}
    d = [x for x in (a.get("distortion_share_of_residual") for a in ra.by_amplitude) if x is not None]
    out["harmonics"] = {"present": bool(max(d) > HARMONIC_SHARE), "share": max(d)} if d else {"present": None}
    if ra.rh_contrast:
        out["rh_dependence"] = {"present": any(c["depends_on_rh"] for c in ra.rh_contrast),
                                "contrasts": [c["contrast"] for c in ra.rh_contrast],
                                "gain_changes": [c["gain_change"] for c in ra.rh_contrast]}
    else:
        out["rh_dependence"] = {"present": None}
    steps = ra.after_steps
    if steps:
        d = float(np.median([s["back_drift_m"] for s in steps]))
        sig_any = any(s["significant"] for s in steps)
        out["step_back_relaxation"] = {"present": bool(sig_any and d > 0), "drift_m": d}
        out["step_creep"] = {"present": bool(sig_any and d < 0), "drift_m": d}
    else:
        out["step_back_relaxation"] = {"present": None}
        out["step_creep"] = {"present": None}
    tr = getattr(ra, "trend", [])
    same_sign = len({np.sign(t["change_m"]) for t in tr}) == 1
    out["slow_trend"] = {"present": bool(tr and same_sign and all(t["significant"] for t in tr)) if tr else None,
                         "change_m": [t["change_m"] for t in tr]}
    return out


def _frf_features(frf, resonance_hz: float | None) -> dict:
    """The features read from the residual's frequency response ``frf`` (ratio measured/model
    by band): low-frequency droop or lag, constant-slope phase, high-frequency phase lag, the
    error near the resonance ``resonance_hz`` [Hz] and a small lag below it."""
    out: dict = {}
    R = frf.ratio
    sig = frf.significant & np.isfinite(R)
    f = frf.freq
    lg, ph = np.log10(np.abs(R)), np.degrees(np.angle(R))
    lo_edge = f[0] * 10 ** 0.7
    lf = sig & (f <= lo_edge)
    if resonance_hz:
        lf &= f < 0.5 * resonance_hz
    if lf.sum() >= 1:
        g, p = float(np.median(np.abs(R[lf]))), float(np.median(ph[lf]))
        out["lf_droop_lead"] = {"present": bool(g < 0.97 and p > 0.5), "gain": g, "phase_deg": p}
        out["lf_excess_lag"] = {"present": bool(g > 1.03 and p < -0.5), "gain": g, "phase_deg": p}
    else:
        avail = f[0] <= 1.0
        out["lf_droop_lead"] = {"present": False if avail else None}
        out["lf_excess_lag"] = {"present": False if avail else None}
    away = sig.copy()
    if resonance_hz:
        away &= (f < 0.6 * resonance_hz) | (f > 1.6 * resonance_hz)
        away &= f < 2.0 * resonance_hz
    if away.sum() >= 4 and np.ptp(np.log10(f[away])) >= 0.7:
        x = np.log10(f[away])
        slope, icpt = np.polyfit(x, lg[away], 1)
        lin = np.std(lg[away] - (slope * x + icpt))
        pm, ps = float(np.mean(ph[away])), float(np.std(ph[away]))
        match = abs(slope) > 0.02 and np.sign(pm) == np.sign(slope) and \
            abs(pm - 90.0 * slope) < 0.5 * abs(90.0 * slope) + 2.0 and lin < 0.3 * abs(slope) + 0.01 and \
            ps < 0.5 * abs(pm) + 2.0
        out["constant_slope_phase"] = {"present": bool(match), "slope_dec_per_dec": float(slope),
                                       "phase_deg": pm}
    else:
        out["constant_slope_phase"] = {"present": False if f[-1] / f[0] >= 10 else None}
    hi = sig & (f >= f[-1] / 10 ** 0.7)
    if f[-1] >= 10 and hi.sum() >= 3:
        s_ph = float(np.polyfit(np.log10(f[hi]), np.unwrap(np.radians(ph[hi])), 1)[0] * 180 / np.pi)
        out["hf_phase_lag"] = {"present": bool(s_ph < -2.0 and ph[hi][-1] < -1.0), "phase_slope_deg_per_dec": s_ph,
                               "phase_top_deg": float(ph[hi][-1])}
        out["hf_phase_lead"] = {"present": bool(s_ph > 2.0 and ph[hi][-1] > 1.0), "phase_slope_deg_per_dec": s_ph,
                                "phase_top_deg": float(ph[hi][-1])}
    else:
        out["hf_phase_lag"] = {"present": False if f[-1] >= 10 else None}
        out["hf_phase_lead"] = {"present": False if f[-1] >= 10 else None}
    if resonance_hz and f[0] < 0.7 * resonance_hz and f[-1] > 1.3 * resonance_hz:
        err = np.abs(np.log(np.where(np.isfinite(R), R, 1.0)))
        near = (f > 0.7 * resonance_hz) & (f < 1.4 * resonance_hz)
        present = bool((sig & near).any() and err[near].max() >= 0.99 * err[np.isfinite(err)].max())
        out["resonance_error"] = {"present": present, "max_log_error_near": float(err[near].max()) if near.any() else None}
        below = sig & (f < 0.5 * resonance_hz)
        if below.sum() >= 2:
            p = float(np.median(ph[below]))
            out["lf_small_lag"] = {"present": bool(-10.0 < p < -0.5 and np.std(ph[below]) < 3.0), "phase_deg": p}
        else:
            out["lf_small_lag"] = {"present": False}
    else:
        out["resonance_error"] = {"present": None}
        out["lf_small_lag"] = {"present": None}
    return out


def signatures(feats: dict, effects: Sequence[str]) -> dict:
    """{effect: {"score": 0–1 or None, "observed": [...], "expected": [...]}} (module doc)."""
    out = {}
    for e in effects:
        exp = signature(e)
        num = den = 0.0
        observed, missing = [], []
        for name, w in exp:
            st = feats.get(name, {}).get("present")
            if st is None:
                continue
            den += w
            if st:
                num += w
                observed.append(FEATURE_TEXT[name])
            else:
                missing.append(FEATURE_TEXT[name])
        out[e] = {"score": (num / den) if den > 0 else None, "observed": observed, "not_observed": missing,
                  "expected": [FEATURE_TEXT[n] for n, _ in exp]}
    return out
