"""Family ``circuit_lab``: an IPMC strip as an electrical engineer models it, exported as a lab does.

Another modelling tradition than the package's (Chen & Tan 2008; Bonomo et al. 2007 style):
one continuous-time state-space model per record, integrated in time (exact for a drive
linear between samples), built from lumped elements:

* **electrical**: the free length cut into six sections joined by the electrodes' series
  resistance 2 R_s ℓ/w (top and bottom face); in each section the polymer is a leak G_p
  (σ = 2.16e-3 S/m across 180 µm) in parallel with its charging branch(es): the double layer
  C_dl U(0.5, 0.75) F/m² behind the bulk resistance (time constant U(20, 100) µs);
* **electromechanical**: the faces' tractions load each section with a couple per length γ × its
  charge per length; each mode's generalised force is ∫ μ φ_i' dz over the sections, with the
  closed-form uniform-cantilever modes φ_i (β₁L = 1.8751, β₂L = 4.6941);
* **mechanical**: two modes (the second U(0.95, 1.03) × the uniform strip's frequency ratio)
  and the next four quasi-statically,
  Kelvin–Voigt damping (first-mode ratio U(0.04, 0.08), the second damped in proportion to its
  frequency), and a polymer modulus with seven Maxwell arms one half-decade apart from 0.1 to
  100 Hz (storage rising ~15 % from 1 to 50 Hz and ~20 % from DC to 3 Hz, as the device's DMA
  table extrapolates);
* **humidity**: Table V of the thesis (40/60/80/100 %: Y 0.49/0.39/0.225/0.18 GPa, kf 0.21/
  0.312/0.15/0.17) interpolated monotonically (PCHIP) as ratios for the modulus and the coupling.

So the base has what the device's default effects model (electrode resistance R_s ≈ 30 Ω/□ ±15 %,
a DMA-like modulus, Table V humidity; the solvent, ethylene glycol, relaxes in hours) and the
user's model is ``--effects default``, less the catalog effect a hidden ingredient stands for
(the lab left it out).  Ingredients, written here:

===============  =============================================================================
electrode        R_s log-U(20, 150) Ω/□ instead of ≈ 30 (user model without electrode_resistance)
contact          equipotential electrodes behind a lumped contact resistance: a first-order lag
                 of the drive, corner log-U(6, 20) Hz (user model without electrode_resistance)
rough            a fractional (constant-phase) double layer as circuit designers build one: 13
                 R–C branches with time constants two a decade from 1 ms to 1000 s, capacitances
                 ∝ τ^a (a U(0.25, 0.55)): charge ∝ s^(−a) in between
solvent          back-relaxation: the first moment of the solvent in a six-cell lumped diffusion
                 line, h²/D_s log-U(8, 60) s (user model without solvent_diffusion)
partial_relax    the same relaxation stopping at U(0.3, 0.6) of the bend
modulus          Maxwell arms 2–4× stronger than the DMA-like base (user model without viscoelastic)
zener            one Maxwell arm (loss peak log-U(1, 8) Hz, strength U(0.3, 0.6)) instead of the
                 seven (user model without viscoelastic)
saturation       large-signal double layer: charge ∝ U_s ln(1 + |U|/U_s), U_s U(0.5, 1.2) × the
                 low drive amplitude, applied as a static map of the drive before the circuit (the
                 electrode line and the branches see the compressed voltage)
humidity         Table V ratios raised to a power (user model without humidity)
rh_law           Table V ratios raised to a power U(1.5, 2) (the user's model keeps Table V)
eigen_moment     the charge bends each section with an eigen-moment (a swelling bimorph's uniform
                 curvature), ∫ M φ_i'' dz, instead of the faces' couple
creep, lowpass2, drift, play, deadzone: :mod:`.forms`
delay            the deflection channel logged d U(4, 15) ms late (a sensor's or logger's dead time)
ac_coupled       the sensor AC-coupled: the fine grid through a first-order high-pass, corner log-U(0.01,
                 0.04) Hz (the deflection less its first-order lag)
hum              mains pickup: a 50 Hz sinusoid of U(2, 4) µm, its phase drawn per record, added to
                 what is logged
bow, clipped     the laser's characteristic bowed (±U(3, 8) % of the case's largest linear stroke at
                 that stroke), its range cut at U(0.75, 0.9) × that stroke: :mod:`.forms`, on the fine
                 grid between the strip and the sensor's own dynamics
===============  =============================================================================

Records as a lab exports them: five 60 s records at 200 Hz — multisines 0.05–20 Hz at RH 40,
60 and 80 % (the one at 60 % also at 2.5× the amplitude), a step held 25 s at RH 60 % — and a
log sweep 0.1–50 Hz at half the amplitude at RH 60 %; tip in mm, a zero offset of ±U(20, 60) µm,
U(2, 3) µm noise, a 0.5 µm resolution, the hygrometer ±0.3 %; sidecars name the instrument and
the sample, not the excitation or the noise.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.linalg import expm
from scipy.signal import lfilter

from . import forms
from .case import Case, Record, shared_draw
from .design import Plan, hygrometer, measure
from .truthset import CATALOG_OF, TRUTHS

NAME = "circuit_lab"
FS, OVER, DURATION = 200.0, 5, 60.0
PLAN = (Plan("multisine", 1.0, 40.0), Plan("multisine", 1.0, 60.0), Plan("multisine", 2.5, 60.0),
        Plan("step", 1.0, 60.0), Plan("sweep", 0.5, 80.0))
N_SEC = 6
N_SOLVENT = 12
BETA_L = (1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349, 14.1371683910, 17.2787595321)
TABLE_RH = (40.0, 60.0, 80.0, 100.0)
TABLE_Y = (0.49, 0.39, 0.225, 0.18)
TABLE_KF = (0.21, 0.312, 0.15, 0.17)
DEFAULT_EFFECTS = ("electrode_resistance", "solvent_diffusion", "viscoelastic", "humidity")
#: ingredients that replace a part of the base the user's default model holds
REPLACES = {"contact": "electrode_resistance", "partial_relax": "solvent_diffusion", "zener": "viscoelastic"}
ARMS_HZ = tuple(0.1 * 10 ** (0.5 * k) for k in range(7))
PEAK = 2.0e-3


def mode_slope(i: int, z: np.ndarray, L: float) -> np.ndarray:
    """φ_i'(z) of the uniform clamped–free beam, φ = cosh βz − cos βz − σ (sinh βz − sin βz)."""
    b = BETA_L[i] / L
    bl = BETA_L[i]
    sig = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    x = b * z
    return b * (np.sinh(x) + np.sin(x) - sig * (np.cosh(x) - np.cos(x)))


def mode_value(i: int, z: float, L: float) -> float:
    bl = BETA_L[i]
    sig = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    x = bl * z / L
    return math.cosh(x) - math.cos(x) - sig * (math.sinh(x) - math.sin(x))


@dataclass
class Strip:
    L: float
    L_clamp: float
    w: float
    f1: float                      # first natural frequency at RH 60 [Hz]
    ratio2: float                  # f2/f1
    zeta1: float
    C_dl: float                    # F/m²
    tau_b: float                   # s
    Rs: float                      # Ω/□
    arm: float                     # Maxwell arm strength of the base
    gain: float                    # static gain target at RH 60 [m/V]
    z_sensor: float
    h2_ds: float                   # h²/D_s of the base solvent [s]


def _draw_strip(rng) -> tuple[Strip, dict]:
    L_total = round(float(rng.uniform(28, 36))) * 1e-3
    L_clamp = 5e-3
    w = round(float(rng.uniform(6, 10))) * 1e-3
    L = L_total - L_clamp
    f1 = 18.0 * (0.025 / L) ** 2 * float(rng.uniform(0.85, 1.15))
    st = Strip(L, L_clamp, w, f1, (BETA_L[1] / BETA_L[0]) ** 2 * float(rng.uniform(0.95, 1.03)),
               float(rng.uniform(0.04, 0.08)), float(rng.uniform(0.5, 0.75)), 1e-6 * float(rng.uniform(20, 100)),
               30.0 * float(rng.uniform(0.85, 1.15)), float(rng.uniform(0.045, 0.06)),
               1e-3 * float(rng.uniform(0.3, 0.7)) * (L / 0.021) ** 2, L - 1e-3 * float(rng.uniform(0.2, 0.8)),
               (90e-6) ** 2 / 2.4e-12 * float(rng.uniform(0.8, 1.25)))
    drawn = {"L_total_mm": 1e3 * L_total, "L_clamp_mm": 1e3 * L_clamp, "width_mm": 1e3 * w, "f1_RH60_Hz": st.f1,
             "f2_over_f1": st.ratio2, "zeta1": st.zeta1, "C_dl_F_m2": st.C_dl, "tau_bulk_s": st.tau_b,
             "Rs_base_ohm_sq": st.Rs, "maxwell_arm": st.arm, "static_gain_mm_per_V": 1e3 * st.gain,
             "sensor_from_tip_mm": 1e3 * (L - st.z_sensor), "h2_over_Ds_base_s": st.h2_ds}
    return st, drawn


def _draw_truth(ingredients, rng) -> dict:
    p = {}
    for ing in ingredients:
        if ing == "electrode":
            p["Rs_ohm_sq"] = float(np.exp(rng.uniform(np.log(20), np.log(150))))
        elif ing == "contact":
            p["contact_corner_Hz"] = float(np.exp(rng.uniform(np.log(6), np.log(20))))
        elif ing == "rough":
            p["cpe_a"] = float(rng.uniform(0.25, 0.55))
        elif ing in ("solvent", "partial_relax"):
            p["h2_over_Ds_s"] = float(np.exp(rng.uniform(np.log(8), np.log(60))))
            if ing == "partial_relax":
                p["relax_keep"] = float(rng.uniform(0.3, 0.6))
        elif ing == "modulus":
            p["arm_factor"] = float(rng.uniform(2.0, 4.0))
        elif ing == "humidity":
            p["rh_power"] = float(rng.uniform(0.6, 1.4)) if rng.uniform() < 0.5 else float(rng.uniform(1.4, 2.0))
        elif ing == "rh_law":
            p["rh_power"] = float(rng.uniform(1.5, 2.0))
        else:
            p.update(shared_draw(ing, rng))
    return p


def solvent_line(h2_over_ds: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A lumped diffusion line across the half thickness (normalised to 1), cells growing
    geometrically from the face (the first 1/400 thick), the mid-plane held at zero (odd
    symmetry), no flux at the face: ż = −K z + P F releases the solvent carried by the load F in
    the face cell; G(s) F = cᵀ z is the share of its first moment that has diffused back
    (G(0) = 1): the load the strip feels is F − G F."""
    lo, hi = 1.0 + 1e-9, 2.0
    for _ in range(100):                                 # growth factor r: (r^n − 1)/(r − 1)/400 = 1
        mid = 0.5 * (lo + hi)
        if (mid ** n - 1) / (mid - 1) / 400 > 1.0:
            hi = mid
        else:
            lo = mid
    widths = np.geomspace(1.0, mid ** (n - 1), n) / 400
    widths = widths[::-1] / widths.sum()                 # mid-plane first, thinnest at the face
    edges = np.concatenate([[0.0], np.cumsum(widths)])
    x = 0.5 * (edges[1:] + edges[:-1])
    D = 1.0 / h2_over_ds
    gaps = np.diff(np.concatenate([[0.0], x]))           # mid-plane to x_1, then centre to centre
    Kd = np.zeros((n, n))                                # amount balance: vol ż = −Kd z
    Kd[0, 0] = D / gaps[0]                               # to the mid-plane (z = 0 there)
    for i in range(n):
        if i + 1 < n:
            g = D / gaps[i + 1]
            Kd[i, i] += g
            Kd[i + 1, i + 1] += g
            Kd[i, i + 1] -= g
            Kd[i + 1, i] -= g
    K = Kd / widths[:, None]
    P = np.zeros(n)
    P[-1] = 1.0 / widths[-1]
    c = (x * widths) @ K / x[-1]
    return K, P, c


def user_effects(ingredients) -> str:
    """``default`` less the default effects a hidden ingredient stands for."""
    drop = []
    for ing in ingredients:
        e = CATALOG_OF.get(ing) or REPLACES.get(ing)
        if e in DEFAULT_EFFECTS and e not in drop:
            drop.append(e)
    return "default" + "".join(f",-{e}" for e in drop)


def _rh_ratio(table, rh: float, power: float = 1.0) -> float:
    f = PchipInterpolator(TABLE_RH, np.log(np.asarray(table) / table[1]))
    return float(np.exp(power * f(np.clip(rh, TABLE_RH[0], TABLE_RH[-1]))))


class _Model:
    """The state-space model (A, B, C) of one strip at one RH; the input is the drive voltage
    after any large-signal map, the output the deflection at the laser spot [m]."""

    def __init__(self, st: Strip, tp: dict, rh: float, gamma: float = 1.0):
        power = tp.get("rh_power", 1.0)
        ey, ek = _rh_ratio(TABLE_Y, rh, power), _rh_ratio(TABLE_KF, rh, power)
        blocks = []                                    # (A, B, C) pieces assembled below
        # ---- electrical: section charges (one or more branches per section)
        ell = st.L / N_SEC
        area = st.w * ell
        if "cpe_a" in tp:
            taus = np.geomspace(1e-3, 1e3, 13)
            cw = taus ** tp["cpe_a"]
            cw *= st.C_dl / cw[np.searchsorted(taus, 0.1)]         # C_dl-like at ~1 Hz
            branches = [(c * area, t / (c * area)) for c, t in zip(cw, taus)]
        else:
            branches = [(st.C_dl * area, st.tau_b / (st.C_dl * area))]
        nb = len(branches)
        G_p = 2.16e-3 / 180e-6 * area
        contact = "contact_corner_Hz" in tp
        rs = 0.0 if contact else tp.get("Rs_ohm_sq", st.Rs)
        ne = N_SEC * nb
        Ae = np.zeros((ne, ne))
        Be = np.zeros(ne)
        if rs > 0:
            # node voltages u = M⁻¹ (b0 V + P q): KCL at each node with the link conductances
            g = np.full(N_SEC, st.w / (2 * rs * ell))
            g[0] *= 2.0                               # half a section from the clamp
            Mn = np.zeros((N_SEC, N_SEC))
            for k in range(N_SEC):
                Mn[k, k] += g[k] + G_p + sum(1 / R for _, R in branches)
                if k + 1 < N_SEC:
                    Mn[k, k] += g[k + 1]
                    Mn[k, k + 1] -= g[k + 1]
                    Mn[k + 1, k] -= g[k + 1]
            b0 = np.zeros(N_SEC)
            b0[0] = g[0]
            P = np.zeros((N_SEC, ne))
            for k in range(N_SEC):
                for j, (C, R) in enumerate(branches):
                    P[k, k * nb + j] = 1 / (R * C)
            Mi = np.linalg.inv(Mn)
            for k in range(N_SEC):                    # q̇_kj = (u_k − q_kj/C_j)/R_j
                for j, (C, R) in enumerate(branches):
                    r = k * nb + j
                    Ae[r] = Mi[k] @ P / R
                    Ae[r, r] -= 1 / (R * C)
                    Be[r] = Mi[k] @ b0 / R
        else:                                         # equipotential electrodes: u_k = drive
            for k in range(N_SEC):
                for j, (C, R) in enumerate(branches):
                    r = k * nb + j
                    Ae[r, r] = -1 / (R * C)
                    Be[r] = 1 / R
        # contact lag on the drive: one more state v_c, v̇_c = (V − v_c)/τ_c feeding the network
        # ---- loads → modal forces: a couple per length μ_k = γ (charge of section k)/ℓ gives
        # F_i = Σ_k μ_k [φ_i(z_{k+1}) − φ_i(z_k)]; an eigen-moment M_k, Σ_k M_k [φ_i'(z_{k+1}) − φ_i'(z_k)]
        edges = np.linspace(0, st.L, N_SEC + 1)
        if "eigen_moment" in tp:
            Wf = np.array([[(mode_slope(i, edges[k + 1:k + 2], st.L) - mode_slope(i, edges[k:k + 1], st.L))[0]
                            / ell for k in range(N_SEC)] for i in range(2)])
        else:
            Wf = np.array([[(mode_value(i, edges[k + 1], st.L) - mode_value(i, edges[k], st.L)) / ell
                            for k in range(N_SEC)] for i in range(2)])
        Sq = np.kron(np.eye(N_SEC), np.ones((1, nb)))          # section charge from branch charges
        Fq = gamma * ek * Wf @ Sq                               # 2 × ne
        # ---- solvent back-relaxation: F_eff = F − G(s) F (six-cell diffusion, module doc)
        solvent = not tp.get("_static", False)        # the gain is normalised without back-diffusion
        tp = {**tp, "h2_over_Ds_s": tp.get("h2_over_Ds_s", st.h2_ds)}      # the EG solvent: hours
        # ---- mechanics per mode: q, q̇ and Maxwell arm states
        w = 2 * np.pi * st.f1 * np.array([1.0, st.ratio2]) * math.sqrt(ey)
        eta = 2 * st.zeta1 / w[0]
        if "zener_delta" in tp:
            arms = [(tp["zener_delta"], 1 / (2 * np.pi * tp["zener_f_Hz"]))]
        else:
            a = st.arm * tp.get("arm_factor", 1.0)
            arms = [(a, 1 / (2 * np.pi * f)) for f in ARMS_HZ]
        # assemble
        n_sol = N_SOLVENT if solvent else 0
        n_mech = 2 * (2 + len(arms))
        n = ne + (1 if contact else 0) + 2 * n_sol + n_mech
        A = np.zeros((n, n))
        B = np.zeros(n)
        ie = slice(0, ne)
        A[ie, ie] = Ae
        if contact:
            ic = ne
            A[ie, ic] = Be
            A[ic, ic] = -2 * np.pi * tp["contact_corner_Hz"]
            B[ic] = 2 * np.pi * tp["contact_corner_Hz"]
        else:
            B[ie] = Be
        off = ne + (1 if contact else 0)
        # forces as rows over the state (F = Fq q_e); with solvent F_eff = F − c_sᵀ z, ż = −K z + P_s F
        Frows = np.zeros((2, n))
        Frows[:, ie] = Fq
        if solvent:
            K, Ps, cs = solvent_line(tp["h2_over_Ds_s"], n_sol)
            keep = tp.get("relax_keep", 0.0)
            for i in range(2):
                zi = slice(off + i * n_sol, off + (i + 1) * n_sol)
                A[zi, zi] = -K
                A[zi] += np.outer(Ps, Frows[i])
                Frows[i, zi] -= (1 - keep) * cs
            off += 2 * n_sol
        tip = np.array([mode_value(i, st.z_sensor, st.L) for i in range(2)])
        C = np.zeros(n)
        for i in range(2):
            base = off + i * (2 + len(arms))
            q, v = base, base + 1
            A[q, v] = 1.0
            k2 = w[i] ** 2
            A[v, q] -= k2 * (1 + sum(d for d, _ in arms))
            A[v, v] -= eta * k2
            A[v] += Frows[i] / st.L                            # modal mass m L; m absorbed in γ
            for m_, (d, tau) in enumerate(arms):
                r = base + 2 + m_
                A[v, r] += k2 * d
                A[r, q] += 1 / tau
                A[r, r] -= 1 / tau
            C[q] = tip[i]
        # the higher modes 3–6 answer quasi-statically (residual flexibility of the load's shape)
        hs = 1 + sum(d for d, _ in arms)
        for i in range(2, len(BETA_L)):
            wi2 = (2 * np.pi * st.f1 * (BETA_L[i] / BETA_L[0]) ** 2) ** 2 * ey * hs
            if "eigen_moment" in tp:
                wf = [(mode_slope(i, edges[k + 1:k + 2], st.L) - mode_slope(i, edges[k:k + 1], st.L))[0] / ell
                      for k in range(N_SEC)]
            else:
                wf = [(mode_value(i, edges[k + 1], st.L) - mode_value(i, edges[k], st.L)) / ell for k in range(N_SEC)]
            C[ie] += mode_value(i, st.z_sensor, st.L) * (gamma * ek * np.asarray(wf) @ Sq) / (st.L * wi2)
        self.A, self.B, self.C = A, B, C

    def static_gain(self) -> float:
        return float(-self.C @ np.linalg.solve(self.A, self.B))

    def simulate(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Output for the drive ``u`` sampled on the uniform grid ``t`` from rest: exact for a
        drive linear between samples (first-order hold, the matrix exponential of the
        augmented system), run mode by mode in the eigenbasis of the discrete system."""
        return lti_foh(self.A, self.B, self.C, u, float(t[1] - t[0]))


def lti_foh(A: np.ndarray, B: np.ndarray, C: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """y of ẋ = A x + B u, y = C x, x(0) = 0, with u linear between samples (module doc of
    :meth:`_Model.simulate`)."""
    n = A.shape[0]
    aug = np.zeros((n + 2, n + 2))
    aug[:n, :n] = A * dt
    aug[:n, n] = B * dt
    aug[n, n + 1] = 1.0
    E = expm(aug)
    Ad, b1, b2 = E[:n, :n], E[:n, n], E[:n, n + 1]
    lam, V = np.linalg.eig(Ad)
    Vi = np.linalg.inv(V)
    ba, bb = Vi @ (b1 - b2), Vi @ b2
    cv = C @ V
    u = np.asarray(u, dtype=float)
    un = np.append(u[1:], u[-1])
    y = np.zeros(u.size)
    for j in range(n):
        d = ba[j] * u + bb[j] * un
        xi = lfilter([0.0, 1.0], [1.0, -lam[j]], d)
        y += (cv[j] * xi).real
    return y


def _simulate(model: _Model, tp: dict, v: np.ndarray, amp_lo: float, tf: np.ndarray, t: np.ndarray, rng,
              noise: float, stroke: float) -> np.ndarray:
    """The laser-spot deflection [m] sampled at FS for the drive ``v`` on the fine grid ``tf``;
    ``stroke``: the largest linear deflection of the case [m], the scale of the sensor's curve."""
    u = v
    if "deadzone_over_amp" in tp:
        u = forms.dead_zone(u, tp["deadzone_over_amp"] * amp_lo)
    if "sat_Us_over_amp" in tp:
        u = forms.log_saturation(u, tp["sat_Us_over_amp"] * amp_lo)
    y = model.simulate(tf, u)
    dt = float(tf[1] - tf[0])
    if "creep_g" in tp:
        a = math.exp(-dt / tp["creep_tau_s"])
        y = y + tp["creep_g"] * lfilter([1 - a], [1, -a], y)
    if "play_um" in tp:
        y = forms.play(y, 1e-6 * tp["play_um"])
    if "bow" in tp:
        y = forms.bow(y, tp["bow"], stroke)
    if "clip_over_stroke" in tp:
        y = forms.clip(y, tp["clip_over_stroke"] * stroke)
    if "lowpass_Hz" in tp:
        w0, z = 2 * np.pi * tp["lowpass_Hz"], tp["lowpass_zeta"]
        A = np.array([[0.0, 1.0], [-w0 * w0, -2 * z * w0]])
        y = lti_foh(A, np.array([0.0, w0 * w0]), np.array([1.0, 0.0]), y, dt)
    if "delay_ms" in tp:        # the deflection channel read d later: the fine grid's value at t − d
        y = np.interp(tf - 1e-3 * tp["delay_ms"], tf, y, left=float(y[0]))
    if "highpass_Hz" in tp:     # an AC-coupled sensor: the deflection less its first-order lag
        tau = 1.0 / (2 * np.pi * tp["highpass_Hz"])
        y = y - lti_foh(np.array([[-1.0 / tau]]), np.array([1.0 / tau]), np.array([1.0]), y, dt)
    y = np.asarray(y, dtype=float)[::OVER]
    if "hum_um" in tp:          # mains pickup on the sensor's cable
        y = y + 1e-6 * tp["hum_um"] * np.sin(2 * np.pi * 50.0 * t + rng.uniform(0, 2 * np.pi))
    if "drift_over_noise" in tp:
        y = y + forms.thermal_drift(t, rng, tp["drift_over_noise"] * noise)
    return y


def make_case(truth: str, seed: int) -> Case:
    tr = TRUTHS[truth]
    fam = zlib.crc32(NAME.encode())
    st, drawn = _draw_strip(np.random.default_rng([seed, fam]))
    rng = np.random.default_rng([seed, fam, zlib.crc32(truth.encode())])
    tp = _draw_truth(tr.ingredients, rng)
    gamma = st.gain / _Model(st, {**{k: v for k, v in tp.items() if k == "eigen_moment"}, "_static": True},
                             60.0).static_gain()
    rh_true = {p.rh: p.rh + float(rng.uniform(-0.5, 0.5)) for p in PLAN}
    models = {rh: _Model(st, tp, rh_true[rh], gamma) for rh in rh_true}
    tf = np.arange(int(DURATION * FS * OVER)) / (FS * OVER)
    t = tf[::OVER]
    volts = [p.voltage(1.0, FS * OVER, DURATION, np.random.default_rng([seed, fam, 7, k])) for k, p in enumerate(PLAN)]
    lin = {k: v for k, v in tp.items() if k not in ("sat_Us_over_amp", "deadzone_over_amp", "play_um", "drift_over_noise",
                                                     "bow", "clip_over_stroke")}
    lin_models = {rh: _Model(st, lin, rh_true[rh], gamma) for rh in rh_true}
    peak = max(float(np.max(np.abs(lin_models[p.rh].simulate(tf, v)))) for p, v in zip(PLAN, volts))
    amp = float(f"{min(2.0, max(0.1, PEAK / peak)):.2g}")
    noise = 1e-6 * float(rng.uniform(2.0, 3.0))
    offset = 1e-6 * float(rng.uniform(20, 60)) * float(rng.choice([-1.0, 1.0]))
    records = []
    meta = {"instrument": "laser displacement sensor (tip, mm), capacitive hygrometer",
            "sample": f"IPMC strip {drawn['L_total_mm']:g} x {drawn['width_mm']:g} mm", "exported_by": "DAQ software"}
    for k, (p, v1) in enumerate(zip(PLAN, volts)):
        v = amp * v1
        y = _simulate(models[p.rh], tp, v, amp, tf, t, rng, noise, amp * peak)
        m = measure(y, rng, noise=noise, step_m=0.5e-6, offset=offset)
        records.append(Record(p.name(k, amp), t, np.round(v[::OVER], 4), m, y,
                              hygrometer(rh_true[p.rh], t.size, rng, jitter=0.3), offset, dict(meta)))
    tp_all = {**drawn, **tp, "amplitude_V": amp, "gamma": gamma, "noise_um": 1e6 * noise, "offset_um": 1e6 * offset,
              "rh_true": list(rh_true.values())}
    params = {"L_total": f"{drawn['L_total_mm']:g}mm", "L_clamp": f"{drawn['L_clamp_mm']:g}mm",
              "width": f"{drawn['width_mm']:g}mm"}
    return Case(NAME, tr, seed, records, params, user_effects(tr.ingredients), tp_all,
                math.sqrt(noise ** 2 + (0.5e-6) ** 2 / 12), units={"deflection": "mm"})
