"""Validation report: the reduced model against the reference PNP + solvent solver.

:func:`run_validation` writes a folder with PNG plots, ``figures.json`` (every number and
curve plotted) and a self-contained page ``index.html``, and returns the summary.  Sections:

1. small signal: reduced FRF (closed form) vs the reference linearised on its own
   discretisation, for the device's default effects at the reference RH; slab-level checks
   against the closed forms (capacitance κe/(2λ), corner D/(2πλh), ΔC⁺(h)/U, B(s));
2. amplitude sweep (sine, 0.05–2 V): error of the linear reduced model and of
   ``nonlinear_charge`` (C_max = ∞, the like-for-like plain Poisson–Boltzmann, and the
   device's C_max) against the reference, amplitudes where the linear model's error passes
   5 % and 20 %, harmonic distortion of current and deflection.  The electrode resistance is
   left out here (one slab stands for the strip) so that only the double layer differs;
3. the whole strip with the electrode resistance (reference slices on the electrode ladder)
   at small and large signal;
4. profiles at the thesis's snapshots (4 Vpp, 1 Hz: Fig. 13/15/30) and the square pulse
   (Ton 20 s, Toff 80 s: Fig. 17): accumulation layer, concentrations, solvent transients.

Errors are normalised RMS differences over the last period, rms(y − y_ref)/rms(y_ref).
"""
from __future__ import annotations

import html
import time
from pathlib import Path

import numpy as np

from ..device import load_device
from ..effects import EFFECTS, stage_of
from ..effects.double_layer import DoubleLayer
from ..io.fileio import write_json
from ..solvers.frequency import frequency_response
from ..model import ActuatorModel
from ..solvers.timedomain import simulate, tip_from_interface_excess
from .strip import ReferenceStrip

DEVICES = ("ipmc_pt_eg", "ip2c_pedot_water")
AMPLITUDES = (0.05, 0.1, 0.2, 0.5, 1.0, 1.5, 2.0)


def _lumped(effects) -> list[str]:
    """``effects`` without the one replacing the electrode line (every slice then sees Vin)."""
    return [e for e in effects if getattr(stage_of(EFFECTS[e]), "stage", None) != "line"]


def large_signal_law() -> tuple[str, dict]:
    """(id, limit) of the large-signal charge law the report validates: the effect replacing the
    charge-law stage with large-signal behaviour, and its ``reference_limit`` (the parameters
    under which it is the plain Poisson–Boltzmann law the reference solver computes)."""
    cls = next(c for c in EFFECTS.values() if getattr(stage_of(c), "stage", None) == "charge_law" and not c.linear)
    return cls.id, dict(cls.reference_limit)


def _label(law: str, params: dict) -> str:
    return f"{law} ({', '.join(f'{k}={v:g}' for k, v in params.items())})"


def _nrmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / max(np.sqrt(np.mean(b ** 2)), 1e-300))


def _harmonics(y, n_per, k_max=5):
    """Complex amplitudes of harmonics 1..k_max over the last period (linear trend removed)."""
    seg = y[-n_per - 1:]
    ramp = np.linspace(0.0, 1.0, seg.size)
    seg = (seg - seg[0] - (seg[-1] - seg[0]) * ramp)[:-1]
    X = np.fft.rfft(seg) * 2.0 / n_per
    return X[1:k_max + 1]


def _thd(y, n_per):
    X = _harmonics(y, n_per)
    return float(np.sqrt(np.sum(np.abs(X[1:]) ** 2)) / max(abs(X[0]), 1e-300))


def _crossing(amps, err, level):
    """First amplitude where ``err`` passes ``level`` (log–log interpolation), or None."""
    amps, err = np.asarray(amps), np.asarray(err)
    above = np.nonzero(err >= level)[0]
    if above.size == 0:
        return None
    i = above[0]
    if i == 0:
        return float(amps[0])
    la, le = np.log(amps[i - 1:i + 1]), np.log(np.maximum(err[i - 1:i + 1], 1e-300))
    return float(np.exp(la[0] + (np.log(level) - le[0]) * (la[1] - la[0]) / (le[1] - le[0])))


# ------------------------------------------------------------------------------------------
def small_signal(device: str, rh: float = 100.0, n_freq: int = 60) -> dict:
    """Reduced vs reference FRF (default effects) and slab checks against the closed forms."""
    dev = load_device(device)
    f = np.logspace(-1, np.log10(50.0), n_freq)
    ref = ReferenceStrip(dev, "default", rh=rh)
    t0 = time.perf_counter()
    r = ref.frequency_response(f)
    t_ref = time.perf_counter() - t0
    red = frequency_response(ref.model, None, f, rh=rh)
    ratio = r["deflection"] / red.deflection
    mag_err = np.abs(ratio) - 1.0
    ph_err = np.degrees(np.angle(ratio))
    # slab checks over a wide band
    p = ref.p
    d = DoubleLayer.props(p)
    fw = np.logspace(-1, np.log10(50 * d.corner_hz), 80)
    sw = 2j * np.pi * fw
    slab = ref.slab_response(sw)
    q, c = DoubleLayer.charge_per_volt(sw, d)
    B = ref.model.hook("solvent_factor")(sw, p)
    ph = np.angle(slab["Q"] / slab["Q"][0])
    corner = float(np.exp(np.interp(-np.pi / 4, -ph, np.log(fw)) if False else np.interp(np.pi / 4, -ph, np.log(fw))))
    return {
        "device": device, "effects": list(ref.model.effect_ids), "rh_pct": rh,
        "freq_Hz": f.tolist(),
        "reduced_mag_m_per_V": np.abs(red.deflection).tolist(), "reference_mag_m_per_V": np.abs(r["deflection"]).tolist(),
        "reduced_phase_deg": red.phase_deg.tolist(), "reference_phase_deg": np.degrees(np.unwrap(np.angle(r["deflection"]))).tolist(),
        "mag_err_pct": (100 * mag_err).tolist(), "phase_err_deg": ph_err.tolist(),
        "max_mag_err_pct": float(100 * np.max(np.abs(mag_err))), "max_phase_err_deg": float(np.max(np.abs(ph_err))),
        "max_current_err_pct": float(100 * np.max(np.abs(r["current"] / red.current - 1))),
        "max_cs_up_err_pct": float(100 * np.max(np.abs(r["cs_up"] / red.cs_up - 1))),
        "reference_frf_wall_s": t_ref, "mesh_nodes": int(ref.slab.N),
        "slab": {
            "capacitance_0p1Hz_F_m2": float(slab["Q"][0].real), "kappa_over_2lambda_F_m2": float(d.kappa / (2 * d.lam)),
            "corner_Hz": corner, "D_over_2pi_lambda_h_Hz": float(d.D / (2 * np.pi * d.lam * d.h)),
            "freq_Hz": fw.tolist(),
            "Q_err_pct": (100 * np.abs(slab["Q"] / q - 1)).tolist(),
            "c_up_err_pct": (100 * np.abs(slab["c_up"] / c - 1)).tolist(),
            "B_err_pct": (100 * np.abs(slab["B"] / B - 1)).tolist(),
            "max_Q_err_pct": float(100 * np.max(np.abs(slab["Q"] / q - 1))),
            "max_c_up_err_pct": float(100 * np.max(np.abs(slab["c_up"] / c - 1))),
            "max_B_err_pct_0p1_50Hz": float(100 * np.max(np.abs(slab["B"] / B - 1)[fw <= 50])),
        },
    }


def amplitude_sweep(device: str, amps=AMPLITUDES, f0: float = 1.0, periods: int = 3, fs: float = 1000.0,
                    rh: float = 100.0) -> dict:
    """Sine of ``f0`` [Hz] at each amplitude [V]: reference vs reduced (linear, the large-signal
    charge law at its reference limit and with the device's values, and the charge-based load
    variant)."""
    dev = load_device(device)
    base_fx = _lumped(dev.default_effects)
    n_per = int(round(fs / f0))
    t = np.arange(periods * n_per + 1) / fs
    last = t >= t[-1] - 1.0 / f0 - 1e-9
    law, limit = large_signal_law()
    plain = _label(law, limit)
    variants = {
        "linear": ActuatorModel(dev, base_fx),
        plain: ActuatorModel(dev.with_params(**limit), base_fx + [law]),
        _label(law, {k: EFFECTS[law](dev).value(dev.params, k) for k in limit}): ActuatorModel(dev, base_fx + [law]),
    }
    out = {"device": device, "effects": base_fx, "f0_Hz": f0, "fs_Hz": fs, "periods": periods,
           "amplitudes_V": list(map(float, amps)), "models": {}, "reference": {"thd_current": [], "thd_deflection": [],
                                                                              "wall_s": [], "steps": [],
                                                                              "H1_deflection_m_per_V": [],
                                                                              "H1_current_A_per_V": []}}
    names = list(variants) + [f"{plain}, charge-based load"]
    for k in names:
        out["models"][k] = {"err_deflection": [], "err_current": [], "thd_current": [], "thd_deflection": []}
    for A in amps:
        v = A * np.sin(2 * np.pi * f0 * t)
        ref = ReferenceStrip(dev, base_fx, rh=rh)
        rr = ref.simulate(t, v)
        R = out["reference"]
        R["thd_current"].append(_thd(rr.current, n_per))
        R["thd_deflection"].append(_thd(rr.deflection, n_per))
        R["wall_s"].append(rr.stats["wall_s"])
        R["steps"].append(rr.stats["steps"])
        R["H1_deflection_m_per_V"].append(float(abs(_harmonics(rr.deflection, n_per)[0]) / A))
        R["H1_current_A_per_V"].append(float(abs(_harmonics(rr.current, n_per)[0]) / A))
        for name, m in variants.items():
            fields = ("charge",) if name == plain else ()
            res = simulate(m, None, t, v, rh=rh, hold="linear", n_segments=1, fields=fields)
            _score(out["models"][name], res.deflection, res.current, rr, last, n_per)
            if fields:
                p = m.params_at(rh)
                d = m.double_layer_props(p)
                ell_q = res.fields["charge"] * d.c0 / d.C0
                tip_q = tip_from_interface_excess(m, t, ell_q, np.array([0.0, m.free_length]), rh, hold="linear")
                _score(out["models"][names[-1]], tip_q, res.current, rr, last, n_per)
    for name, m in out["models"].items():
        for what in ("deflection", "current"):
            e = np.array(m[f"err_{what}"])
            m[f"amp_err_{what}_5pct_V"] = _crossing(amps, e, 0.05)
            m[f"amp_err_{what}_20pct_V"] = _crossing(amps, e, 0.20)
    return out


def line_large_signal(device: str, amps=(0.05, 2.0), f0: float = 1.0, periods: int = 2, fs: float = 1000.0,
                      rh: float = 100.0) -> dict:
    """The whole strip with the electrode resistance (default effects): reference slices on the
    electrode ladder vs the reduced transmission line, small and large signal."""
    dev = load_device(device)
    fx = list(dev.default_effects)
    n_per = int(round(fs / f0))
    t = np.arange(periods * n_per + 1) / fs
    last = t >= t[-1] - 1.0 / f0 - 1e-9
    lin = ActuatorModel(dev, fx)
    law, limit = large_signal_law()
    plain = _label(law, limit)
    nl = ActuatorModel(dev.with_params(**limit), fx + [law])
    n_seg = 16
    edges = np.asarray(lin.free_length * np.linspace(0.0, 1.0, n_seg + 1) ** 1.5)
    out = {"device": device, "effects": fx, "f0_Hz": f0, "amplitudes_V": list(map(float, amps)), "rows": []}
    for A in amps:
        v = A * np.sin(2 * np.pi * f0 * t)
        ref = ReferenceStrip(dev, fx, rh=rh)
        rr = ref.simulate(t, v)
        r_lin = simulate(lin, None, t, v, rh=rh, hold="linear", n_segments=n_seg)
        r_nl = simulate(nl, None, t, v, rh=rh, hold="linear", n_segments=n_seg, fields=("charge", "voltage"))
        d = nl.double_layer_props(nl.params_at(rh))
        tip_q = tip_from_interface_excess(nl, t, r_nl.fields["charge"] * d.c0 / d.C0, edges, rh, hold="linear")
        z_ref = rr.z[1:]
        amp_ref = np.max(np.abs(rr.U[1:, last]), axis=1) / A
        amp_red = np.interp(z_ref, r_nl.z, np.max(np.abs(r_nl.fields["voltage"][:, last]), axis=1) / A)
        out["rows"].append({
            "amplitude_V": float(A), "reference_wall_s": rr.stats["wall_s"], "slices": int(rr.U.shape[0]),
            "err_deflection": {"linear": _nrmse(r_lin.deflection[last], rr.deflection[last]),
                               plain: _nrmse(r_nl.deflection[last], rr.deflection[last]),
                               "charge-based load": _nrmse(tip_q[last], rr.deflection[last])},
            "err_current": {"linear": _nrmse(r_lin.current[last], rr.current[last]),
                            plain: _nrmse(r_nl.current[last], rr.current[last])},
            "z_m": z_ref.tolist(), "U_amp_reference": amp_ref.tolist(), "U_amp_reduced_nonlinear": amp_red.tolist(),
        })
    return out


def _score(m, tip, current, rr, last, n_per):
    m["err_deflection"].append(_nrmse(tip[last], rr.deflection[last]))
    m["err_current"].append(_nrmse(current[last], rr.current[last]))
    m["thd_current"].append(_thd(current, n_per))
    m["thd_deflection"].append(_thd(tip, n_per))


def _layer_facts(x, C, C_anion, h):
    """Facts of one cation profile: extremes, thickness of the perturbed layers, and the mean
    over the first µm from each face (what a µm-sized mesh cell would show)."""
    dC = C - C_anion
    d_face = h - np.abs(x)
    pert = d_face[np.abs(dC) > 0.01 * C_anion]
    out = {"C_max_mol_m3": float(C.max()), "C_min_mol_m3": float(C.min()),
           "layer_1pct_nm": float(1e9 * pert.max()) if pert.size else 0.0,
           "centre_dev_mol_m3": float(abs(dC[np.argmin(np.abs(x))]))}
    for face, sel in (("upper", x > 0), ("lower", x < 0)):
        m = sel & (d_face <= 1e-6)
        out[f"mean_first_um_{face}_mol_m3"] = float(C_anion + abs(np.trapezoid(dC[m], x[m])) * np.sign(dC[m][np.argmin(d_face[m])]) / 1e-6)
    return out


def _solvent_zones(x, Cs, Cs0, h):
    """∫ΔCs dx [mol/m²] in the inner (< 10 nm) and outer (10 nm – 5 µm) zones of each face, and
    the distance [µm] of the first sign change of ΔCs beyond 10 nm from the upper face (the
    front of solvent left over from the previous polarity; None if there is none)."""
    d = h - np.abs(x)
    dC = Cs - Cs0
    z = {}
    for face, sel in (("upper", x > 0), ("lower", x < 0)):
        for zone, (a, b) in (("inner", (0, 1e-8)), ("outer", (1e-8, 5e-6))):
            m = sel & (d >= a) & (d <= b)
            z[f"{face}_{zone}_mol_m2"] = float(np.trapezoid(dC[m], x[m]))
    m = (x > 0) & (d >= 1e-8) & (np.abs(dC) > 1e-6 * np.max(np.abs(dC)))
    dd, v = d[m][::-1], dC[m][::-1]                      # from the face inwards
    flip = np.nonzero(np.sign(v[1:]) != np.sign(v[:-1]))[0]
    z["upper_sign_change_um"] = float(1e6 * dd[flip[0]]) if flip.size else None
    return z


def profiles_sine(device: str, A: float = 2.0, f0: float = 1.0, rh: float = 100.0) -> dict:
    """4 Vpp at 1 Hz (thesis Fig. 13–15, 30): profiles at Vin max/min of the first period and at 3 s."""
    dev = load_device(device)
    fx = _lumped(dev.default_effects)
    t = np.arange(0, 3.0 + 1e-9, 1e-3)
    snaps = [0.25, 0.75, 2.25, 3.0]
    ref = ReferenceStrip(dev, fx, rh=rh)
    rr = ref.simulate(t, A * np.sin(2 * np.pi * f0 * t), snapshots=snaps)
    prm = ref.prm
    out = {"device": device, "amplitude_V": A, "f0_Hz": f0, "snapshots_s": snaps, "facts": {}, "profiles": {},
           "conservation": rr.conservation}
    for ts in snaps:
        pr = rr.profiles[ts]
        x, C, Cs = pr["x"], pr["C+"][1], pr["Cs"][1]
        f = _layer_facts(x, C, prm.C_anion, prm.h)
        f.update(_solvent_zones(x, Cs, prm.C_solvent0, prm.h))
        f["Vin_V"] = float(A * np.sin(2 * np.pi * f0 * ts))
        out["facts"][str(ts)] = f
        out["profiles"][str(ts)] = {"x_m": x.tolist(), "C+_mol_m3": C.tolist(), "Cs_mol_m3": Cs.tolist()}
    return out


def square_pulse(device: str, A: float = 2.0, t_on: float = 20.0, t_off: float = 80.0, fs: float = 50.0,
                 rh: float = 100.0) -> dict:
    """Square pulse (thesis Fig. 17): solvent accumulation during Ton and what is left during Toff."""
    dev = load_device(device)
    fx = _lumped(dev.default_effects)
    t = np.arange(0, t_on + t_off + 1e-9, 1.0 / fs)
    v = np.where(t < t_on, A, 0.0)
    v[0] = 0.0
    t_end_on = float(t[t < t_on][-1])                 # last sample at the full voltage
    snaps = [5.0, t_end_on, t_on + 1.0, t_on + 10.0, t_on + 40.0, t_on + t_off]
    ref = ReferenceStrip(dev, fx, rh=rh)
    rr = ref.simulate(t, v, snapshots=snaps)
    red = simulate(ActuatorModel(dev, fx), None, t, v, rh=rh, hold="linear", n_segments=1)
    i_on = int(np.searchsorted(t, t_end_on - 1e-9))
    probe = [t_on + 0.1, t_on + 1.0, t_on + 10.0, t_on + 30.0, t_on + t_off]
    idx = [int(np.searchsorted(t, x - 1e-9)) for x in probe]
    prm = ref.prm
    on = t < t_on
    cs_pk = rr.cs_up[on][np.argmax(np.abs(rr.cs_up[on]))]             # peak during Ton (signed)
    tip_pk = rr.deflection[on][np.argmax(np.abs(rr.deflection[on]))]
    return {
        "device": device, "amplitude_V": A, "t_on_s": t_on, "t_off_s": t_off, "conservation": rr.conservation,
        "wall_s": rr.stats["wall_s"], "steps": rr.stats["steps"],
        "cs_up_end_on_mol_m3": float(rr.cs_up[i_on]), "cs_up_peak_on_mol_m3": float(cs_pk),
        "residual_after_s": [p - t_on for p in probe],
        "cs_up_residual_fraction": [float(rr.cs_up[i] / cs_pk) for i in idx],
        "cation_excess_residual_fraction": [float(rr.c_up[1, i] / rr.c_up[1, i_on]) for i in idx],
        "deflection_residual_fraction": [float(rr.deflection[i] / tip_pk) for i in idx],
        "t_s": t[::max(1, int(fs / 5))].tolist(),
        "reference_cs_up": rr.cs_up[::max(1, int(fs / 5))].tolist(),
        "reference_deflection_m": rr.deflection[::max(1, int(fs / 5))].tolist(),
        "reduced_linear_deflection_m": red.deflection[::max(1, int(fs / 5))].tolist(),
        "profiles": {str(ts): {"x_m": rr.profiles[ts]["x"].tolist(),
                               "Cs_minus_Cs0_mol_m3": (rr.profiles[ts]["Cs"][1] - prm.C_solvent0).tolist()}
                     for ts in snaps},
    }


# ------------------------------------------------------------------------------------------
def run_validation(out_dir, devices=DEVICES, amps=AMPLITUDES, quick: bool = False, log=print) -> dict:
    """Run every section for ``devices`` and write the report folder ``out_dir``.  ``quick``:
    three amplitudes and no square pulse (for a smoke run)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if quick:
        amps = (amps[0], amps[len(amps) // 2], amps[-1])
    figs = {"devices": list(devices)}
    for dev in devices:
        t0 = time.perf_counter()
        ss = small_signal(dev)
        log(f"[{dev}] small signal: FRF reduced vs reference max |Δmag| {ss['max_mag_err_pct']:.3f} %, "
            f"max |Δphase| {ss['max_phase_err_deg']:.3f}° over 0.1–50 Hz ({ss['effects']}); current "
            f"{ss['max_current_err_pct']:.3f} %; slab C(0.1 Hz) {ss['slab']['capacitance_0p1Hz_F_m2']:.4g} F/m² vs "
            f"κe/2λ {ss['slab']['kappa_over_2lambda_F_m2']:.4g}; corner {ss['slab']['corner_Hz']:.4g} Hz vs "
            f"D/(2πλh) {ss['slab']['D_over_2pi_lambda_h_Hz']:.4g} Hz")
        sw = amplitude_sweep(dev, amps)
        for name, m in sw["models"].items():
            log(f"[{dev}] {name}: deflection error " + ", ".join(f"{a:g} V {100 * e:.2f} %" for a, e in
                                                                 zip(sw["amplitudes_V"], m["err_deflection"]))
                + f"; passes 5 % at {_fmt(m['amp_err_deflection_5pct_V'])}, 20 % at {_fmt(m['amp_err_deflection_20pct_V'])}"
                + "; current error " + ", ".join(f"{100 * e:.2f} %" for e in m["err_current"])
                + f"; passes 5 % at {_fmt(m['amp_err_current_5pct_V'])}, 20 % at {_fmt(m['amp_err_current_20pct_V'])}")
        R = sw["reference"]
        log(f"[{dev}] reference THD current " + ", ".join(f"{a:g} V {100 * x:.2f} %" for a, x in
                                                         zip(sw["amplitudes_V"], R["thd_current"]))
            + "; THD deflection " + ", ".join(f"{100 * x:.2f} %" for x in R["thd_deflection"]))
        pr = profiles_sine(dev)
        for ts, f in pr["facts"].items():
            log(f"[{dev}] 4 Vpp 1 Hz, t = {ts} s (Vin {f['Vin_V']:+.2f} V): C+ {f['C_min_mol_m3']:.4g}…"
                f"{f['C_max_mol_m3']:.4g} mol/m³, layer (|ΔC+| > 1 % C⁻) {f['layer_1pct_nm']:.3g} nm, centre "
                f"|ΔC+| {f['centre_dev_mol_m3']:.2g}, mean over 1 µm: upper {f['mean_first_um_upper_mol_m3']:.4g}, lower "
                f"{f['mean_first_um_lower_mol_m3']:.4g} mol/m³; solvent ∫ΔCs upper inner/outer "
                f"{f['upper_inner_mol_m2']:.3g}/{f['upper_outer_mol_m2']:.3g}, lower inner/outer "
                f"{f['lower_inner_mol_m2']:.3g}/{f['lower_outer_mol_m2']:.3g} mol/m², upper ΔCs changes sign at "
                f"{_um(f['upper_sign_change_um'])}")
        figs[dev] = {"small_signal": ss, "amplitude_sweep": sw, "profiles": pr}
        if not quick:
            ln = line_large_signal(dev)
            for r in ln["rows"]:
                log(f"[{dev}] strip with electrode resistance, {r['amplitude_V']:g} V at 1 Hz ({r['slices']} slices, "
                    f"{r['reference_wall_s']:.1f} s): deflection error " + ", ".join(f"{k} {100 * e:.2f} %" for k, e in
                                                                            r["err_deflection"].items())
                    + "; current error " + ", ".join(f"{k} {100 * e:.2f} %" for k, e in r["err_current"].items())
                    + f"; voltage amplitude at z = {1e3 * r['z_m'][-1]:.1f} mm: reference {r['U_amp_reference'][-1]:.4f}, "
                    f"reduced {r['U_amp_reduced_nonlinear'][-1]:.4f} of Vin")
            figs[dev]["line"] = ln
        if not quick:
            sq = square_pulse(dev)
            log(f"[{dev}] square pulse 2 V, 20 s on / 80 s off: Cs_up peak during Ton {sq['cs_up_peak_on_mol_m3']:.4g}, at "
                f"its end {sq['cs_up_end_on_mol_m3']:.4g} mol/m³; after switch-off (fractions of the Ton peak; C+ excess: "
                "of its end-of-Ton value) " + ", ".join(f"{a:g} s: Cs_up {c:.3f}, C+ excess {e:.1e}, deflection {dd:.3f}"
                                                       for a, c, e, dd in zip(sq["residual_after_s"],
                                                                              sq["cs_up_residual_fraction"],
                                                                              sq["cation_excess_residual_fraction"],
                                                                              sq["deflection_residual_fraction"]))
                + f" (reference {sq['steps']} steps, {sq['wall_s']:.1f} s)")
            figs[dev]["square_pulse"] = sq
        log(f"[{dev}] done in {time.perf_counter() - t0:.0f} s")
    pngs = _plots(figs, out)
    write_json(out / "figures.json", _clean(figs))
    _page(figs, pngs).write_index(out)
    return figs


def _um(a):
    return "no depth (one sign)" if a is None else f"{a:.3g} µm"


def _fmt(a):
    return "never (≤ 2 V)" if a is None else f"{a:.3g} V"


def _clean(o):
    """JSON-safe copy (non-finite numbers become None)."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    return o


def _plots(figs, out: Path) -> list[Path]:
    """The page's figures for every device (frequency response, amplitude sweep, profiles and,
    when run, the square pulse): their paths."""
    paths = []
    for dev in figs["devices"]:
        F = figs[dev]
        paths += [_plot_frf(dev, F["small_signal"], out), _plot_amplitude(dev, F["amplitude_sweep"], out),
                  _plot_profiles(dev, F["profiles"], out)]
        if "square_pulse" in F:
            paths.append(_plot_square(dev, F["square_pulse"], out))
    return paths


def _saved(fig, path: Path) -> Path:
    """``fig`` saved as the PNG ``path`` (atomically, then closed); returns ``path``."""
    from ..pages.plotting import save
    save(fig, path)
    return path


def _plot_frf(dev: str, ss: dict, out: Path) -> Path:
    """Small-signal FRF, reduced vs reference, and their differences: ``frf_DEV.png``."""
    from ..pages.plotting import plt
    fig, ax = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    f = ss["freq_Hz"]
    ax[0].loglog(f, 1e3 * np.asarray(ss["reduced_mag_m_per_V"]), label="reduced (closed form)")
    ax[0].loglog(f, 1e3 * np.asarray(ss["reference_mag_m_per_V"]), "--", label="reference (linearised PNP)")
    ax[0].set_ylabel("|δ/V| [mm/V]")
    ax[0].legend()
    ax[1].semilogx(f, ss["reduced_phase_deg"])
    ax[1].semilogx(f, ss["reference_phase_deg"], "--")
    ax[1].set_ylabel("phase [°]")
    ax[2].semilogx(f, ss["mag_err_pct"], label="magnitude [%]")
    ax[2].semilogx(f, ss["phase_err_deg"], label="phase [°]")
    ax[2].set_ylabel("reference/reduced − 1")
    ax[2].set_xlabel("frequency [Hz]")
    ax[2].legend()
    ax[0].set_title(f"{dev}: small-signal FRF ({', '.join(ss['effects'])})")
    return _saved(fig, out / f"frf_{dev}.png")


def _plot_amplitude(dev: str, sw: dict, out: Path) -> Path:
    """Deflection and current errors and THD over the amplitude sweep: ``amplitude_DEV.png``."""
    from ..pages.plotting import plt
    a = sw["amplitudes_V"]
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for name, m in sw["models"].items():
        ax[0].loglog(a, 100 * np.array(m["err_deflection"]), "o-", label=name)
        ax[1].loglog(a, 100 * np.array(m["err_current"]), "o-", label=name)
    for k in (0, 1):
        ax[k].axhline(5, color="k", lw=0.6, ls=":")
        ax[k].axhline(20, color="k", lw=0.6, ls=":")
        ax[k].set_xlabel("amplitude [V]")
    ax[0].set_ylabel("deflection error vs reference [%]")
    ax[1].set_ylabel("current error vs reference [%]")
    ax[0].legend(fontsize=7)
    R = sw["reference"]
    ax[2].loglog(a, 100 * np.maximum(R["thd_current"], 1e-9), "o-", label="reference current")
    ax[2].loglog(a, 100 * np.maximum(R["thd_deflection"], 1e-9), "s-", label="reference deflection")
    law, limit = large_signal_law()
    nl = sw["models"][_label(law, limit)]
    ax[2].loglog(a, 100 * np.maximum(nl["thd_current"], 1e-9), "o--", label=f"{law} current")
    ax[2].loglog(a, 100 * np.maximum(nl["thd_deflection"], 1e-9), "s--", label=f"{law} deflection")
    cb = sw["models"][f"{_label(law, limit)}, charge-based load"]
    ax[2].loglog(a, 100 * np.maximum(cb["thd_deflection"], 1e-9), "^:", label="charge-based load deflection")
    ax[2].set_ylabel("THD (harmonics 2–5) [%]")
    ax[2].set_xlabel("amplitude [V]")
    ax[2].legend(fontsize=7)
    fig.suptitle(f"{dev}: sine {sw['f0_Hz']:g} Hz, amplitude sweep")
    return _saved(fig, out / f"amplitude_{dev}.png")


def _plot_profiles(dev: str, pr: dict, out: Path) -> Path:
    """Cation and solvent profiles near both faces: ``profiles_DEV.png``."""
    from ..pages.plotting import plt
    fig, ax = plt.subplots(2, 2, figsize=(12, 7))
    for ts, P in pr["profiles"].items():
        x = np.array(P["x_m"])
        h = x[-1]
        for col, sel, sgn in ((0, x < 0, -1), (1, x > 0, 1)):
            d = h - np.abs(x[sel])
            ax[0, col].loglog(np.maximum(d, 1e-12), np.array(P["C+_mol_m3"])[sel], label=f"t = {ts} s")
            ax[1, col].semilogx(np.maximum(d, 1e-12), np.array(P["Cs_mol_m3"])[sel], label=f"t = {ts} s")
        for col, name in ((0, "lower face (x = −h)"), (1, "upper face (x = +h)")):
            ax[0, col].set_title(name)
            ax[1, col].set_xlabel("distance from the face [m]")
    ax[0, 0].set_ylabel("C+ [mol/m³]")
    ax[1, 0].set_ylabel("Cs [mol/m³]")
    ax[0, 0].legend(fontsize=7)
    fig.suptitle(f"{dev}: 4 Vpp, 1 Hz — cation and solvent profiles (thesis Fig. 13/15/30)")
    return _saved(fig, out / f"profiles_{dev}.png")


def _plot_square(dev: str, sq: dict, out: Path) -> Path:
    """Square pulse: reference Cs_up, tip deflection and solvent profiles: ``square_DEV.png``."""
    from ..pages.plotting import plt
    fig, ax = plt.subplots(1, 3, figsize=(16, 4))
    ax[0].plot(sq["t_s"], sq["reference_cs_up"])
    ax[0].set_ylabel("reference Cs_up (first-moment equivalent) [mol/m³]")
    ax[0].set_xlabel("time [s]")
    ax[1].plot(sq["t_s"], 1e6 * np.array(sq["reference_deflection_m"]), label="reference")
    ax[1].plot(sq["t_s"], 1e6 * np.array(sq["reduced_linear_deflection_m"]), "--", label="reduced, linear")
    ax[1].set_ylabel("tip deflection [µm]")
    ax[1].set_xlabel("time [s]")
    ax[1].legend(fontsize=7)
    for ts, P in sq["profiles"].items():
        x = np.array(P["x_m"])
        sel = x > 0
        ax[2].semilogx(np.maximum(x[-1] - x[sel], 1e-12), np.array(P["Cs_minus_Cs0_mol_m3"])[sel],
                       label=f"t = {ts} s")
    ax[2].set_xlabel("distance from the upper face [m]")
    ax[2].set_ylabel("Cs − Cs0 [mol/m³]")
    ax[2].legend(fontsize=7)
    fig.suptitle(f"{dev}: square pulse 2 V, Ton 20 s / Toff 80 s (thesis Fig. 17)")
    return _saved(fig, out / f"square_{dev}.png")


_NOTES = """<h2>How to read it</h2><ul>
<li>Small signal: both are the linearised PNP + solvent model; the reference solves it on its own graded
finite-volume mesh, so agreement checks the reduced model's closed forms and its strip and beam chain.</li>
<li>Plain Poisson–Boltzmann layers obey e^{−x_c} − e^{−x_a} = x_a − x_c (equal charges on both faces): the
antisymmetric interface cation excess (C⁺(h) − C⁺(−h))/2 equals C⁻U/(2V_T) at every amplitude.  The
reduced model's load is that interface excess, so at {limit} <code>{law}</code> leaves the
deflection exactly linear: it fixes the current (the charge saturates as sqrt(U)) but not the deflection.
The solvent the cations carry follows the moved charge, not the peak concentration; the variant
'charge-based load' (ℓ = Q·c0/C0 from the same <code>{law}</code> run) shows what that closes.</li>
<li>Cations pile up within nanometres of the faces (Debye length with bulk εr is sub-nm); averaged over
a micrometre-sized cell they differ from C⁻ by a few mol/m³ only.</li></ul>"""


#: What each figure of the page shows (by the first word of its file name).
_CAPTIONS = {"frf": "small-signal frequency response, reduced vs reference: |δ/V| [mm/V], phase [°] and their "
                    "differences",
             "amplitude": "amplitude sweep: deflection and current errors vs the reference [%] and harmonic "
                          "distortion [%] against the amplitude [V]",
             "profiles": "cation and solvent concentration profiles [mol/m³] near both faces, 4 Vpp at 1 Hz",
             "square": "square pulse 2 V: reference Cs_up [mol/m³], tip deflection [µm] and solvent profiles"}


def _device(stem: str) -> str:
    return stem.split("_", 1)[1] if "_" in stem else stem


def _page(figs, pngs):
    """The page of ``eap validate`` (a :class:`physics.pages.report.Report`)."""
    rows = []
    for dev in figs["devices"]:
        F = figs[dev]
        ss, sw = F["small_signal"], F["amplitude_sweep"]
        rows.append(f"<h2>{html.escape(dev)}</h2><h3>Small signal ({html.escape(', '.join(ss['effects']))}, "
                    f"RH {ss['rh_pct']:g} %)</h3><ul>"
                    f"<li>FRF reduced vs reference, 0.1–50 Hz: max |Δmag| {ss['max_mag_err_pct']:.3f} %, "
                    f"max |Δphase| {ss['max_phase_err_deg']:.3f}° (criterion 1 % / 1°)</li>"
                    f"<li>current {ss['max_current_err_pct']:.3f} %, Cs_up {ss['max_cs_up_err_pct']:.3f} %</li>"
                    f"<li>slab: C(0.1 Hz) = {ss['slab']['capacitance_0p1Hz_F_m2']:.5g} F/m² vs κe/(2λ) = "
                    f"{ss['slab']['kappa_over_2lambda_F_m2']:.5g}; corner {ss['slab']['corner_Hz']:.4g} Hz vs "
                    f"D/(2πλh) = {ss['slab']['D_over_2pi_lambda_h_Hz']:.4g} Hz; max error vs closed forms: "
                    f"Q {ss['slab']['max_Q_err_pct']:.3f} %, ΔC⁺(h) {ss['slab']['max_c_up_err_pct']:.3f} %, "
                    f"B(s) {ss['slab']['max_B_err_pct_0p1_50Hz']:.3f} % (0.1–50 Hz); {ss['mesh_nodes']} mesh nodes</li></ul>")
        t = ["<table border=1 cellpadding=3><tr><th>model</th>" + "".join(f"<th>{a:g} V</th>" for a in sw["amplitudes_V"])
             + "<th>5 % at</th><th>20 % at</th></tr>"]
        for what in ("deflection", "current"):
            for name, m in sw["models"].items():
                t.append(f"<tr><td>{html.escape(name)} — {what}</td>"
                         + "".join(f"<td>{100 * e:.2f} %</td>" for e in m[f"err_{what}"])
                         + f"<td>{_fmt(m[f'amp_err_{what}_5pct_V'])}</td><td>{_fmt(m[f'amp_err_{what}_20pct_V'])}</td></tr>")
        R = sw["reference"]
        for k in ("thd_current", "thd_deflection"):
            t.append(f"<tr><td>reference {k.replace('_', ' ')}</td>" + "".join(f"<td>{100 * x:.2f} %</td>" for x in R[k])
                     + "<td></td><td></td></tr>")
        t.append("</table>")
        rows.append(f"<h3>Amplitude sweep (sine {sw['f0_Hz']:g} Hz, {html.escape(', '.join(sw['effects']))}; "
                    "normalised RMS error over the last period)</h3>" + "".join(t))
        pr = F["profiles"]
        li = "".join(f"<li>t = {ts} s (Vin {f['Vin_V']:+.2f} V): C⁺ {f['C_min_mol_m3']:.4g} … {f['C_max_mol_m3']:.4g} mol/m³; "
                     f"layer with |ΔC⁺| &gt; 1 % of C⁻: {f['layer_1pct_nm']:.3g} nm; mean C⁺ over the first µm: upper "
                     f"{f['mean_first_um_upper_mol_m3']:.4g}, lower {f['mean_first_um_lower_mol_m3']:.4g} mol/m³; "
                     f"solvent ∫ΔCs upper inner/outer {f['upper_inner_mol_m2']:.3g}/{f['upper_outer_mol_m2']:.3g}, "
                     f"lower inner/outer {f['lower_inner_mol_m2']:.3g}/{f['lower_outer_mol_m2']:.3g} mol/m²; upper ΔCs changes "
                     f"sign at {_um(f['upper_sign_change_um'])}</li>"
                     for ts, f in pr["facts"].items())
        rows.append(f"<h3>Profiles, 4 Vpp at 1 Hz</h3><ul>{li}</ul><p>Conservation (relative drift): "
                    f"{html.escape(str(pr['conservation']))}</p>")
        if "line" in F:
            li = "".join(f"<li>{r['amplitude_V']:g} V: deflection error " + ", ".join(
                f"{html.escape(k)} {100 * e:.2f} %" for k, e in r["err_deflection"].items()) + "; current error " + ", ".join(
                f"{html.escape(k)} {100 * e:.2f} %" for k, e in r["err_current"].items())
                + f"; voltage amplitude at the last slice (z = {1e3 * r['z_m'][-1]:.1f} mm): reference "
                f"{r['U_amp_reference'][-1]:.4f}, reduced {r['U_amp_reduced_nonlinear'][-1]:.4f} of Vin</li>"
                for r in F["line"]["rows"])
            rows.append(f"<h3>Whole strip with the electrode resistance (default effects, 1 Hz)</h3><ul>{li}</ul>")
        if "square_pulse" in F:
            sq = F["square_pulse"]
            li = "".join(f"<li>{a:g} s after switch-off: Cs_up {c:.3f}, deflection {d:.3f} (fractions of their peak "
                         f"during Ton), interface C⁺ excess {e:.1e} (of its end-of-Ton value)</li>"
                         for a, c, e, d in zip(sq["residual_after_s"], sq["cs_up_residual_fraction"],
                                               sq["cation_excess_residual_fraction"], sq["deflection_residual_fraction"]))
            rows.append(f"<h3>Square pulse 2 V, Ton 20 s / Toff 80 s</h3><ul>{li}</ul>")
    from ..pages.report import Report
    rep = Report("Reduced model vs reference PNP + solvent solver", "eap validate")
    rep.paragraph(f"{__doc__.strip().splitlines()[0]} See physics/reference/strip.py for how the load is "
                  "compared: ℓ_ref = ∫x(Cs − Cs0)dx / (n⁺Λ), which equals the reduced model's ℓ·B(s) in the "
                  "small-signal limit.")
    law, limit = large_signal_law()
    notes = _NOTES.replace("{law}", law).replace("{limit}", ", ".join(f"{k} = {v:g}" for k, v in limit.items()))
    rep.raw(notes + "".join(rows))
    for p in pngs:
        rep.image(p, _CAPTIONS.get(p.stem.split("_")[0], p.stem.replace("_", " ")) + f" ({_device(p.stem)})")
    return rep
