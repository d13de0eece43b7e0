"""Family ``pnp_fd``: a tapered IPMC strip simulated from the equations by our own route.

**Base physics** (every truth):

* charging through the thickness: the linearised Poisson–Nernst–Planck equations by finite
  volumes (:mod:`.pnp`), thesis-like Nafion/EG values drawn ±20 % (ε_r 41.4, D⁺ 1.4e-9 m²/s,
  C⁻ 1100 mol/m³), plus the polymer's leakage σ = 2.16e-3 S/m;
* the moved charge q [C/m²] loads both faces with tractions (thesis eq. 9–10): a distributed
  couple κ·w(z)·t(z)·q per unit length (κ drawn so that the static tip gain is U(0.2, 0.5) mm/V
  × (L/21 mm)²);
* a **non-uniform strip** by Hermite finite elements (:mod:`.febeam`): width tapering by
  U(5, 25) % from clamp to tip, thickness varying linearly by ±U(0, 5) %, platinum electrode
  layers (10 µm, 19 600 kg/m³, cracked: 0.7–1.3 GPa) adding mass and stiffness, a clamp of finite
  rotational stiffness (U(200, 600) EI/L), Rayleigh damping with a mass-proportional (air) and a stiffness-
  proportional (material) part (first-mode damping ratio U(0.06, 0.12));
* the laser spot U(0.2, 0.8) mm short of the tip; the strip is simulated at 4× the logging rate
  (the drive comes from a signal generator) and the tip sampled without anti-aliasing.

The user's model is the bare thesis device (``--effects none``) with the geometry the lab knows
(``--param L_total, L_clamp, width``: the mean width).

**Ingredients** (:mod:`.truthset`), each written here:

===============  ===========================================================================
electrode        sheet resistance R_s log-U(20, 150) Ω/□ on both faces: the voltage falls along
                 the strip (a finite-volume ladder, :func:`.lines.electrode_ladder`)
rough            rough electrodes: a constant-phase double layer bounded at DC, q/V ∝ (s + ω_lo)^(−a)
                 (thesis eq. 14's form), a U(0.25, 0.55), f_lo log-U(1, 3) mHz, |q/V| at 1 Hz
                 U(0.7, 1.4) × the PNP value
solvent          solvent released in a cathode layer δ U(2, 8) µm thick diffusing back
                 (:func:`.lines.solvent_moment`), h²/D_s log-U(8, 60) s; the bend follows it
modulus          Cole–Cole polymer: E*(s) = E0 [1 + Δ (sτ)^γ / (1 + (sτ)^γ)], γ U(0.15, 0.3),
                 Δ U(0.4, 0.8), centre log-U(1, 10) Hz
saturation       steric-limited double layer, q ∝ U_s (sqrt(1 + 2|U|/U_s) − 1),
                 U_s U(0.5, 1.2) × the low drive amplitude, applied as a static map of the drive
                 before the linear chain (the charging is fast against the band)
humidity,        E(RH) = E65 exp(−k_E (RH − 65)/40), k_E U(0.6, 1.0); κ(RH) = κ65 (1 + k_κ
rh_law           (RH − 65)/40), |k_κ| U(0.15, 0.4)
contact          lumped contact resistance at the clamp charging the whole strip: a first-order
                 lag of the drive, corner log-U(6, 20) Hz
partial_relax    back-relaxation that stops at a fraction U(0.3, 0.6) of the bend (the charge's
                 own eigenstress stays): ρ + (1 − ρ)·(solvent factor)
eigen_moment     the charge bends the strip as a swelling bimorph does — an eigen-moment
                 κ·w·t·q per unit length (uniform curvature) instead of the face tractions' couple
zener            one-relaxation polymer, E*(s) = E0 (1 + sτ_ε)/(1 + sτ_σ), τ_ε/τ_σ = 1 + Δ,
                 Δ U(0.3, 0.6), loss peak log-U(1, 8) Hz
creep, lowpass2, drift, play, deadzone: :mod:`.forms`
delay            the deflection channel logged d U(4, 15) ms late (a sensor's or logger's dead time)
ac_coupled       the sensor AC-coupled: a first-order high-pass, corner log-U(0.01, 0.04) Hz
hum              mains pickup: a 50 Hz sinusoid of U(2, 4) µm, its phase drawn per record, added to
                 what is logged
bow, clipped     the laser's characteristic bowed (±U(3, 8) % of the case's largest linear stroke at
                 that stroke), its range cut at U(0.75, 0.9) × that stroke: :mod:`.forms`, between the
                 strip and the sensor's own dynamics
===============  ===========================================================================

Records (lab design, the same for every truth): five 60 s records at 250 Hz — a multisine
0.05–20 Hz at RH 65 % and at 2.5× its amplitude, a 25 s step with a 33 s hold at zero, a
log sweep 0.1–50 Hz at half the amplitude at RH 45 % and the multisine at RH 85 %.  Tip in µm with 1.5 µm laser noise
stated in the sidecars (with the excitation), a zero offset of ±25 µm, RH column ±0.1 %.

Family ``pnp_sweep`` (:data:`SWEEP`): the same physics recorded as a user with two records does —
a 120 s log sweep 0.1–50 Hz and a 60 s bipolar square pulse train (period 10 s), both at RH 65 %,
with 1 µm laser noise; its strips are drawn apart from ``pnp_fd``'s.  One RH level reveals no
humidity dependence, so its truths leave those out (:func:`truths_of`).
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from . import forms
from .case import Case, Record, shared_draw
from .design import Plan, fft_filter, hygrometer, measure
from .febeam import Beam, modal_tip
from .lines import electrode_ladder, solvent_moment
from .pnp import charge_per_volt
from .truthset import TRUTHS

FS, OVER, DURATION = 250.0, 4, 60.0


@dataclass(frozen=True)
class Design:
    """How a family records its strips: its name, the records, the laser's white noise [m]."""

    name: str
    plan: tuple
    noise: float


LAB = Design("pnp_fd", (Plan("multisine", 1.0, 65.0), Plan("multisine", 2.5, 65.0), Plan("step", 1.0, 65.0),
                        Plan("sweep", 0.5, 45.0), Plan("multisine", 1.0, 85.0)), 1.5e-6)
SWEEP = Design("pnp_sweep", (Plan("sweep", 1.0, 65.0, 120.0), Plan("square", 1.0, 65.0)), 1.0e-6)
DESIGNS = {d.name: d for d in (LAB, SWEEP)}
RH_REF = 65.0
N_EL, N_MODES = 24, 8
STEP = 1.0e-7                      # laser resolution [m]
PEAK = 2.0e-3                      # largest tip deflection the lab aims for [m]
LEAK = 2.16e-3                     # polymer conductivity [S/m] (thesis Table III)


@dataclass
class Strip:
    L: float                       # free length [m]
    L_clamp: float
    w: np.ndarray                  # element widths [m]
    t: np.ndarray                  # element polymer thicknesses [m]
    E: float                       # polymer modulus at RH_REF [Pa]
    E_el: float
    rho: float
    k_theta_c: float
    zeta: float
    mass_share: float
    z_sensor: float
    eps_r: float
    D: float
    c0: float
    gain: float                    # static tip gain target [m/V]

    def charge_per_volt(self, f: np.ndarray) -> np.ndarray:
        """The PNP charge per volt [C/m²/V] at ``f`` (solved once per frequency grid)."""
        key = (f.size, float(f[0]), float(f[-1]))
        cache = self.__dict__.setdefault("_q", {})
        if key not in cache:
            cache[key] = charge_per_volt(f, h=0.5 * 180e-6, eps_r=self.eps_r, D=self.D, c0=self.c0)
        return cache[key]


def _draw_strip(rng) -> tuple[Strip, dict]:
    """The strip of a seed (the same for every truth of that seed) and its drawn values."""
    L_total = round(float(rng.uniform(28, 36)) * 2) / 2 * 1e-3
    L_clamp = round(float(rng.uniform(4, 6)) * 2) / 2 * 1e-3
    w0 = float(rng.uniform(7, 10)) * 1e-3
    taper = float(rng.uniform(0.05, 0.25))
    grad = float(rng.uniform(-0.05, 0.05))
    L = L_total - L_clamp
    zc = (np.arange(N_EL) + 0.5) / N_EL
    w = w0 * (1 - taper * zc)
    t = 180e-6 * (1 + grad * (zc - 0.5))
    st = Strip(L, L_clamp, w, t, 0.2e9 * float(rng.uniform(0.85, 1.15)), 1e9 * float(rng.uniform(0.7, 1.3)), 2000.0,
               float(rng.uniform(200, 600)), float(rng.uniform(0.06, 0.12)), float(rng.uniform(0.2, 0.5)),
               L - 1e-3 * float(rng.uniform(0.2, 0.8)), 41.4 * float(rng.uniform(0.8, 1.25)),
               1.4e-9 * float(rng.uniform(0.8, 1.25)), 1100 * float(rng.uniform(0.9, 1.1)),
               1e-3 * float(rng.uniform(0.2, 0.5)) * (L / 0.021) ** 2)
    drawn = {"L_total_mm": 1e3 * L_total, "L_clamp_mm": 1e3 * L_clamp, "width_clamp_mm": 1e3 * w0, "taper": taper,
             "thickness_gradient": grad, "E_GPa": st.E / 1e9, "E_electrode_GPa": st.E_el / 1e9,
             "clamp_stiffness_EI_per_L": st.k_theta_c, "zeta1": st.zeta, "mass_damping_share": st.mass_share,
             "sensor_from_tip_mm": 1e3 * (L - st.z_sensor), "eps_r": st.eps_r, "D_cation": st.D, "C_anion": st.c0,
             "static_gain_mm_per_V": 1e3 * st.gain}
    return st, drawn


def _beam(st: Strip, E: float) -> Beam:
    t_el, rho_el = 10e-6, 19600.0
    EI = E * st.w * st.t ** 3 / 12 + 2 * st.E_el * st.w * (t_el ** 3 / 12 + t_el * (0.5 * st.t + 0.5 * t_el) ** 2)
    m = st.w * (st.rho * st.t + 2 * rho_el * t_el)
    return Beam.build(st.L, EI, m, k_theta=st.k_theta_c * float(EI[0]) / st.L)


def _draw_truth(ingredients, rng, st: Strip) -> dict:
    """Parameters of each ingredient (module doc); amplitude-relative ones as ratios."""
    p = {}
    for ing in ingredients:
        if ing == "electrode":
            p["Rs_ohm_sq"] = float(np.exp(rng.uniform(np.log(20), np.log(150))))
        elif ing == "rough":
            p["cpe_a"] = float(rng.uniform(0.25, 0.55))
            p["cpe_gain_1Hz"] = float(rng.uniform(0.7, 1.4))
            p["cpe_f_lo_Hz"] = float(np.exp(rng.uniform(np.log(1e-3), np.log(3e-3))))
        elif ing in ("solvent", "partial_relax"):
            p["h2_over_Ds_s"] = float(np.exp(rng.uniform(np.log(8), np.log(60))))
            p["solvent_layer_um"] = float(rng.uniform(2, 8))
            if ing == "partial_relax":
                p["relax_keep"] = float(rng.uniform(0.3, 0.6))
        elif ing == "modulus":
            p["cc_gamma"] = float(rng.uniform(0.15, 0.3))
            p["cc_delta"] = float(rng.uniform(0.4, 0.8))
            p["cc_f_Hz"] = float(np.exp(rng.uniform(np.log(1), np.log(10))))
        elif ing in ("humidity", "rh_law"):
            p["rh_kE"] = float(rng.uniform(0.6, 1.0))
            p["rh_kcoupling"] = float(rng.uniform(0.15, 0.4)) * float(rng.choice([-1, 1]))
        elif ing == "contact":
            p["contact_corner_Hz"] = float(np.exp(rng.uniform(np.log(6), np.log(20))))
        else:
            p.update(shared_draw(ing, rng))
    return p


class _Chain:
    """The linear response of one strip at one RH, from drive voltage to the sensor spot."""

    def __init__(self, st: Strip, tp: dict, rh: float, kappa: float | None = None):
        self.st, self.tp = st, tp
        E = st.E * (math.exp(-tp["rh_kE"] * (rh - RH_REF) / 40) if "rh_kE" in tp else 1.0)
        self.kappa_rh = 1.0 + (tp.get("rh_kcoupling", 0.0) * (rh - RH_REF) / 40)
        beam = _beam(st, E)
        om, phi = beam.modes()
        self.omega = om
        self.tip = beam.point_vector(st.z_sensor) @ phi
        self.B = phi.T @ (beam.G if "eigen_moment" in tp else beam.Gc)
        w1 = om[0]
        z = st.zeta
        self.alpha = 2 * z * st.mass_share * w1
        self.beta = 2 * z * (1 - st.mass_share) / w1
        self.kappa = kappa if kappa is not None else 1.0
        self.fg = np.geomspace(1e-5, FS * OVER / 2 * 1.01, 300)
        self._qv = None

    # -- electrochemistry on the log grid
    def charge_per_volt(self, f: np.ndarray) -> np.ndarray:
        st, tp = self.st, self.tp
        q = st.charge_per_volt(f)
        if "cpe_a" in tp:
            q1 = abs(np.interp(0.0, np.log(f), q.real))               # |q/V| at 1 Hz (flat there)
            w_lo = 2 * np.pi * tp["cpe_f_lo_Hz"]

            def shape(ff):
                return (w_lo / (2j * np.pi * ff + w_lo)) ** tp["cpe_a"]

            q = shape(f) * tp["cpe_gain_1Hz"] * q1 / abs(shape(np.array([1.0]))[0])
        if "contact_corner_Hz" in tp:
            q = q / (1 + 1j * f / tp["contact_corner_Hz"])
        return q

    def moments(self, f: np.ndarray) -> np.ndarray:
        """Load per volt of each element (n_el × len(f)): the couple per length [N m/m/V], or the
        eigen-moment [N m/V] with ``eigen_moment``."""
        st, tp = self.st, self.tp
        q = self.charge_per_volt(f)
        if "Rs_ohm_sq" in tp:
            le = st.L / N_EL
            shunt = (st.w * le)[:, None] * (2j * np.pi * f[None, :] * q[None, :] + LEAK / 180e-6)
            w_link = np.concatenate([[st.w[0]], 0.5 * (st.w[1:] + st.w[:-1])])
            r = 2 * tp["Rs_ohm_sq"] * le / w_link
            r[0] *= 0.5
            U = electrode_ladder(shunt, r)
        else:
            U = np.ones((N_EL, f.size))
        load = q[None, :] * U
        if "h2_over_Ds_s" in tp:
            h = 90e-6
            Bs = solvent_moment(f, h, h * h / tp["h2_over_Ds_s"], 1e-6 * tp["solvent_layer_um"])
            if "relax_keep" in tp:
                Bs = tp["relax_keep"] + (1 - tp["relax_keep"]) * Bs
            load = load * Bs[None, :]
        return self.kappa * self.kappa_rh * (st.w * st.t)[:, None] * load

    def modulus_factor(self, f: np.ndarray) -> np.ndarray | float:
        tp = self.tp
        s = 2j * np.pi * f
        if "cc_gamma" in tp:
            x = (s / (2 * np.pi * tp["cc_f_Hz"])) ** tp["cc_gamma"]
            return 1.0 + tp["cc_delta"] * x / (1.0 + x)
        if "zener_delta" in tp:
            d = tp["zener_delta"]
            tau_s = 1 / (2 * np.pi * tp["zener_f_Hz"] * math.sqrt(1 + d))
            return (1 + s * tau_s * (1 + d)) / (1 + s * tau_s)
        return 1.0

    def response(self, f: np.ndarray) -> np.ndarray:
        """Sensor-spot deflection per volt at ``f`` [Hz] (f ≥ 0): modal forces from the log grid,
        the first N_MODES modes dynamic, the others as residual flexibility."""
        fg = self.fg
        F = self.B @ self.moments(fg)                                   # all modes × grid
        res = np.sum((self.tip / self.omega ** 2)[N_MODES:, None] * F[N_MODES:], axis=0)
        lf = np.log(np.maximum(f, fg[0]))
        lg = np.log(fg)

        def interp(v):
            return np.interp(lf, lg, v.real) + 1j * np.interp(lf, lg, v.imag)

        Ff = np.array([interp(F[i]) for i in range(N_MODES)])
        e = self.modulus_factor(np.maximum(f, fg[0]))
        s = 2j * np.pi * f
        return modal_tip(self.omega[:N_MODES], self.tip[:N_MODES], Ff, s, alpha=self.alpha, beta=self.beta,
                         stiffness_factor=e) + interp(res) / e

    def static_gain(self) -> float:
        return float(abs(self.response(np.array([0.0]))[0]))


def _pad(tp: dict) -> float:
    slow = [tp.get("creep_tau_s", 0.0), tp.get("h2_over_Ds_s", 0.0),
            1.0 / (2 * np.pi * tp["cpe_f_lo_Hz"]) if "cpe_a" in tp else 0.0]
    return 40.0 + 10.0 * max(slow)


def _simulate(chain: _Chain, tp: dict, v: np.ndarray, amp_lo: float, t: np.ndarray, rng, noise: float,
              stroke: float) -> np.ndarray:
    """The sensor-spot deflection [m] sampled at FS for the drive ``v`` (on the fine grid);
    ``noise``: the laser's [m], the scale of a drift; ``stroke``: the largest linear deflection of
    the case [m], the scale of the sensor's curve."""
    vf = v
    if "deadzone_over_amp" in tp:
        vf = forms.dead_zone(vf, tp["deadzone_over_amp"] * amp_lo)
    if "sat_Us_over_amp" in tp:
        vf = forms.steric_sqrt(vf, tp["sat_Us_over_amp"] * amp_lo)

    def resp(f):
        h = chain.response(f)
        if "creep_g" in tp:
            h = h * forms.creep_response(f, tp["creep_g"], tp["creep_tau_s"])
        return h

    y = fft_filter(vf, FS * OVER, resp, pad_s=_pad(tp))
    if "play_um" in tp:
        y = forms.play(y, 1e-6 * tp["play_um"])
    if "bow" in tp:
        y = forms.bow(y, tp["bow"], stroke)
    if "clip_over_stroke" in tp:
        y = forms.clip(y, tp["clip_over_stroke"] * stroke)
    if "lowpass_Hz" in tp:
        y = fft_filter(y, FS * OVER, lambda f: forms.lowpass2_response(f, tp["lowpass_Hz"], tp["lowpass_zeta"]))
    if "delay_ms" in tp:        # the deflection channel's dead time, exact for the band-limited signal
        y = fft_filter(y, FS * OVER, lambda f: np.exp(-2j * np.pi * f * 1e-3 * tp["delay_ms"]))
    if "highpass_Hz" in tp:     # an AC-coupled sensor: j f/fc / (1 + j f/fc), padded past its memory
        y = fft_filter(y, FS * OVER, lambda f: 1j * f / tp["highpass_Hz"] / (1 + 1j * f / tp["highpass_Hz"]),
                       pad_s=max(60.0, 10.0 / (2 * np.pi * tp["highpass_Hz"])))
    y = y[::OVER]
    if "hum_um" in tp:          # mains pickup on the sensor's cable
        y = y + 1e-6 * tp["hum_um"] * np.sin(2 * np.pi * 50.0 * t + rng.uniform(0, 2 * np.pi))
    if "drift_over_noise" in tp:
        y = y + forms.thermal_drift(t, rng, tp["drift_over_noise"] * noise)
    return y


def truths_of(design: Design) -> tuple[str, ...]:
    """The truths ``design``'s records can reveal: an RH dependence needs two RH levels."""
    one_rh = len({p.rh for p in design.plan}) < 2
    return tuple(n for n, t in TRUTHS.items()
                 if not (one_rh and {"humidity", "rh_law"} & set(t.ingredients)))


def make_case(truth: str, seed: int, design: Design = LAB) -> Case:
    tr = TRUTHS[truth]
    plan, noise = design.plan, design.noise
    fam = zlib.crc32(design.name.encode())
    st, drawn = _draw_strip(np.random.default_rng([seed, fam]))
    rng = np.random.default_rng([seed, fam, zlib.crc32(truth.encode())])
    tp = _draw_truth(tr.ingredients, rng, st)
    # the coupling κ that gives the drawn static gain on the base strip at the reference RH
    base = _Chain(st, {k: v for k, v in tp.items() if k == "eigen_moment"}, RH_REF)
    kappa = st.gain / base.static_gain()
    rh_true = {p.rh: p.rh + float(rng.uniform(-0.5, 0.5)) for p in plan}
    chains = {rh: _Chain(st, tp, rh_true[rh], kappa) for rh in rh_true}
    # the lab's excitations: the same for every truth of a seed
    # drive from a signal generator, logged at FS (the strip sees the continuous drive: the
    # simulation grid is OVER times finer)
    volts = [p.voltage(1.0, FS * OVER, p.length(DURATION), np.random.default_rng([seed, fam, 7, k]))
             for k, p in enumerate(plan)]
    lin = {k: _Chain(st, {k2: v for k2, v in tp.items() if k2 in ("Rs_ohm_sq", "cpe_a", "cpe_gain_1Hz",
                                                                    "cpe_f_lo_Hz", "contact_corner_Hz",
                                                                    "eigen_moment")},
                     rh_true[p.rh], kappa)
           for k, p in enumerate(plan)}
    peak = max(float(np.max(np.abs(fft_filter(v, FS * OVER, lin[k].response, pad_s=_pad(tp)))))
               for k, (p, v) in enumerate(zip(plan, volts)))
    amp = float(f"{min(1.0, max(0.1, PEAK / peak)):.2g}")
    offset = 1e-6 * float(rng.uniform(-25, 25))
    records = []
    for k, (p, v1) in enumerate(zip(plan, volts)):
        v = amp * v1
        t = np.arange(int(p.length(DURATION) * FS)) / FS
        y = _simulate(chains[p.rh], tp, v, amp, t, rng, noise, amp * peak)
        v = v[::OVER]
        m = measure(y, rng, noise=noise, step_m=STEP, offset=offset)
        meta = {"description": f"IPMC strip, {drawn['L_total_mm']:g} mm, tapered",
                "signal": p.describe(amp, FS, p.length(DURATION)),
                "sensor": {"model": "laser triangulation", "noise_rms_um": 1e6 * noise, "resolution_um": 1e6 * STEP}}
        records.append(Record(p.name(k, amp), t, np.round(v, 5), m, y,
                              hygrometer(rh_true[p.rh], t.size, rng, jitter=0.1), offset, meta))
    tp_all = {**drawn, **tp, "amplitude_V": amp, "kappa": kappa, "rh_true": list(rh_true.values())}
    if "sat_Us_over_amp" in tp:
        tp_all["sat_Us_V"] = tp["sat_Us_over_amp"] * amp
    if "deadzone_over_amp" in tp:
        tp_all["deadzone_V"] = tp["deadzone_over_amp"] * amp
    return Case(design.name, tr, seed, records, drawn_params(drawn), "none", tp_all,
                math.sqrt(noise ** 2 + STEP ** 2 / 12), units={"deflection": "um"})


def drawn_params(drawn: dict) -> dict:
    """``--param`` geometry the lab knows: lengths and the mean width (to 0.5 mm)."""
    return {"L_total": f"{drawn['L_total_mm']:g}mm", "L_clamp": f"{drawn['L_clamp_mm']:g}mm",
            "width": f"{round(2 * drawn['width_clamp_mm'] * (1 - 0.5 * drawn['taper'])) / 2:g}mm"}
