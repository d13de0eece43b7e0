"""Implicit time stepper for the electrochemistry along the strip when it is not LTI:
large-signal double layer (``nonlinear_charge``), Joule heating (``thermal``) or
electrochemical parameters that follow a time-varying RH.

Each segment of the strip (and the clamped part, which sits at Vin) is a branch: bulk
resistance R_b in series with the double layer's equilibrium law U_eq(Q), with the
electronic leakage σ/(2h) in parallel; the branches hang on the resistive ladder of the
electrodes.  The state is the electrode charge per area Q of every branch:

    dQ/dt = (U − U_eq(Q)) / R_b,    M U = g0 Vin e0 + (A/R_b) ∘ U_eq(Q)   (Kirchhoff).

Double-layer charging (tens of µs) is far faster than the sampling step, so the system
is stiff: it is integrated by the L-stable, stiffly accurate two-stage SDIRK method of
Alexander (1977).  Each stage is solved by full Newton iterations (quadratic
convergence, so a small Newton step means a small error) started from a quadratic
extrapolation of the previous samples, halving the step when Newton fails; the current
and Joule power of a step come from the stage equation at the converged charge.  Where
the input is constant and the charge has reached equilibrium (flat parts of pulses and
steps) the state is held without stepping, unless ``thermal`` is on.  (A
linearly implicit Rosenbrock method and simplified Newton were tried and rejected: at
1 ms steps they were off by tens of per cent in the interface concentration, which
depends exponentially on the interface potential.)  The temperature of each segment
follows a backward-Euler heat balance with the Joule power of the step.

Accuracy: with ``nonlinear_charge`` the current is rich in harmonics; like any sampled
record it is only resolved up to the Nyquist frequency, so sample at ≥ 20× the highest
fundamental when the current waveform matters (the deflection is low-pass and converges
much faster: 2e-4 of its range at 1 kHz for a 0.1–50 Hz, 4 Vpp sweep).
"""
from __future__ import annotations

import numpy as np
from scipy import linalg
from scipy.linalg.lapack import dgesv

from ..errors import ModelError
from ..execution.progress import Progress

_GAMMA = 1.0 - 1.0 / np.sqrt(2.0)
#: Temperature change [K] after which the electrochemical properties are re-derived
#: (the mobility changes by 1/T, eq. 6: 0.02 K is a 7e-5 relative change).
_T_REFRESH = 0.02
#: Newton tolerance relative to max|Q| + C0·V_T (a 20 s, 4 Vpp sweep then agrees with a
#: 1e-11 solution within 1e-8 of the deflection and 3e-5 of the current range).
_TOL = 1e-7
# Newton predictors: stage 1 from Q + γ∇Q + γ(γ+1)/2 ∇²Q; stage 2 from the quadratic through
# Q(t − h), Q(t), Y1(t + γh) at t + h: Q − (1−γ)/(1+γ) ∇Q + 2/(γ(1+γ)) (Y1 − Q).
_CURVE_1 = 0.5 * _GAMMA * (_GAMMA + 1.0)
_PRED_PREV = (1.0 - _GAMMA) / (1.0 + _GAMMA)
_PRED_STAGE = 2.0 / (_GAMMA * (1.0 + _GAMMA))


class BranchNetwork:
    """The clamp branch (index 0) plus the free branches, at given parameters and temperatures.

    ``lumped``: all free segments see Vin and the same temperature, so one free branch
    (of their total area) stands for all of them."""

    def __init__(self, model, p: dict, edges: np.ndarray, lumped: bool = False):
        self.model, self.p = model, p
        self.compile_law = model.hook("compiled")
        areas = p["width"] * np.diff(edges)
        if lumped:
            areas = np.array([areas.sum()])
        self.area = np.concatenate([[p["width"] * p["L_clamp"]], areas])
        self.g = None if lumped else model.hook("series_conductances")(p, edges)
        self.half_g = None if self.g is None else 0.5 * self.g   # None: every branch at Vin (no line)
        self.n = self.area.size
        self.set_temperature(np.full(self.n, p["T_ext"]))

    def set_temperature(self, T: np.ndarray):
        self.T = np.array(T, dtype=float)
        self.d = self.model.double_layer_props(self.p, self.T)
        self.law = self.compile_law(self.d, self.p)
        self.Rb = np.broadcast_to(self.d.R_bulk, (self.n,)).astype(float)
        self.inv_Rb = 1.0 / self.Rb
        self.G = float(self.d.G_leak)
        self.area_Rb, self.area_G = self.area * self.Rb, self.area * self.G
        self.load_ratio = self.d.c0 / self.d.C0   # first-moment-equivalent excess per charge
        self.q_scale = float(np.max(self.d.C0) * np.max(self.d.V_T))  # charge of a thermal voltage
        self._hg = None
        # node voltages U = V @ (Vin, U_eq[1:]) by Kirchhoff, M U_free = g0 Vin e0 + (A/R_b) U_eq
        V = np.zeros((self.n, self.n))
        V[:, 0] = 1.0
        if self.g is not None:
            g = self.g
            nf = self.n - 1
            M = np.zeros((nf, nf))
            idx = np.arange(nf)
            M[idx, idx] = g + np.append(g[1:], 0.0) + self.area[1:] * (self.inv_Rb[1:] + self.G)
            M[idx[:-1], idx[1:]] = M[idx[1:], idx[:-1]] = -g[1:]
            Minv = linalg.inv(M)
            V[1:, 0] = Minv[:, 0] * g[0]
            V[1:, 1:] = Minv * (self.area[1:] * self.inv_Rb[1:])[None, :]
        self.V = V
        self.coupling = self.inv_Rb[:, None] * V   # ∂(dQ/dt)/∂U_eq off the diagonal term
        self.coupling[:, 0] = 0.0

    def _voltages(self, Ueq: np.ndarray, vin: float) -> np.ndarray:
        w = Ueq.copy()
        w[0] = vin
        return self.V @ w

    def evaluate(self, Q, vin):
        """(dQ/dt [A/m²], U [V], U_eq [V], dU_eq/dQ [V m²/C]) at the charge Q [C/m²] and input
        vin [V]; U[0] is the clamp branch, at vin."""
        Ueq, dU = self.law.evaluate(Q)
        U = self._voltages(Ueq, vin)
        return (U - Ueq) * self.inv_Rb, U, Ueq, dU

    def newton_matrix(self, dU, hg, shift=1.0):
        """shift·I − hg·∂(dQ/dt)/∂Q at the slopes dU (hg [s]).  ∂(dQ/dt)/∂Q is
        R_b⁻¹ V diag(dU) (the ladder, without its Vin column) minus diag(dU/R_b)."""
        if hg != self._hg:
            self._hg, self._hg_coupling, self._hg_inv_Rb = hg, -hg * self.coupling, hg * self.inv_Rb
        B = self._hg_coupling * dU
        B.ravel()[::self.n + 1] += shift + self._hg_inv_Rb * dU
        return B

    def current(self, f, U) -> float:
        """Input current [A] from :meth:`evaluate`'s f and U: the clamp branch plus what enters
        the electrode ladder."""
        if self.g is None:
            return float(self.area @ (f + self.G * U))
        return self.area[0] * (f[0] + self.G * U[0]) + self.g[0] * (U[0] - U[1])

    def joule(self, f, U) -> np.ndarray:
        """Joule power of every branch and of the electrode links [W] (links split half/half),
        from :meth:`evaluate`'s f and U: (U − U_eq)²/R_b = f² R_b."""
        P = self.area_Rb * f * f + self.area_G * U * U
        if self.g is not None:
            drop = U[1:] - U[:-1]            # U[0] = Vin: the first link is clamp → segment 1
            half = self.half_g * drop * drop
            P[:-1] += half
            P[1:] += half
        return P


def _vin_stage(v: np.ndarray) -> np.ndarray:
    """Vin at t_n + gamma*dt for every step, cubic Lagrange through the neighbouring samples."""
    vp = np.concatenate([[2 * v[0] - v[1]], v, [2 * v[-1] - v[-2]]])
    x = _GAMMA
    lag = [-x * (x - 1) * (x - 2) / 6, (x + 1) * (x - 1) * (x - 2) / 2, -(x + 1) * x * (x - 2) / 2,
           (x + 1) * x * (x - 1) / 6]
    n = v.size - 1
    return sum(lj * vp[j:j + n] for j, lj in enumerate(lag))


def run(model, params_at, t: np.ndarray, vin: np.ndarray, rh: np.ndarray, edges: np.ndarray,
        want: set[str], progress: bool = False) -> dict[str, np.ndarray]:
    """Integrate the branch network.  ``params_at(rh)`` gives the parameters at an RH.

    Returns per-sample arrays: ``current`` (A) and ``load`` (first-moment-equivalent
    interface cation excess (c0/C0)·Q, mol/m³, per branch; branch 0 = clamp), and, if
    requested in ``want``, ``c_up``/``c_low`` (key ``"c"``: cation excess at the faces,
    mol/m³), ``U`` (V), ``Q`` (C/m²) and ``T`` (K) per branch."""
    N = t.size
    dt = float(t[1] - t[0])
    # the network is rebuilt when the RH moves by a quarter percent, at the RH it has then: a map
    # fitted per RH level ends at a level's own RH (40.3 %), which a rounded key (40.25 %) left
    rh_key = np.round(rh / 0.25) * 0.25
    p0 = params_at(float(rh[0]))
    tn = model.hook("network")(p0, edges)             # heat network (None: isothermal)
    thermal = tn is not None
    lumped = not thermal and model.hook("series_conductances")(p0, edges) is None
    net = BranchNetwork(model, p0, edges, lumped)
    nb = net.n
    Qs, current = np.empty((N, nb)), np.empty(N)
    Us = np.empty((N, nb)) if "U" in want else None
    Ts = np.full((N, nb), net.p["T_ext"]) if "T" in want else None
    if thermal:
        heat_inv, heat_hold, heat_ext = _heat_step(tn, nb, dt)
        T = np.full(nb, tn.T_ext)
        T_props = T.copy()
    v_stage = _vin_stage(vin)
    hold_until = None if thermal else _constant_input_runs(vin, v_stage, rh_key)
    Q = _equilibrium_charge(net, vin[0])
    Q_prev, d1_prev = Q, 0.0
    f, U = net.evaluate(Q, vin[0])[:2]
    newton = _Newton()
    # (first sample, law, load ratio) wherever they change; set_temperature replaces both
    epochs = [(0, net.law, net.load_ratio)]
    key = rh_key[0]
    n = reported = 0
    with Progress(N - 1, "electrochemistry", enabled=progress) as bar:
        while True:
            Qs[n] = Q
            current[n] = net.current(f, U)
            if Us is not None:
                Us[n] = U
            if Ts is not None and thermal:
                Ts[n] = T
            if n - reported >= 1000:
                bar.update(n - reported)
                reported = n
            if n == N - 1:
                break
            if hold_until is not None and hold_until[n] > n and _at_rest(net, Q, f, vin[n], dt):
                m = hold_until[n]           # constant input, at rest: the state holds until sample m
                Qs[n + 1:m + 1], current[n + 1:m + 1] = Q, current[n]
                if Us is not None:
                    Us[n + 1:m + 1] = U
                Q_prev, d1_prev, n = Q, 0.0, m
                continue
            if rh_key[n + 1] != key:
                key = rh_key[n + 1]
                Tcur = net.T
                net = BranchNetwork(model, params_at(float(rh[n + 1])), edges, lumped)
                net.set_temperature(Tcur)
                epochs.append((n + 1, net.law, net.load_ratio))
            d1 = Q - Q_prev
            Q_prev, Q, (f, U) = Q, *_step(net, newton, Q, dt, (vin[n], v_stage[n], vin[n + 1]),
                                          (d1, d1 - d1_prev))
            d1_prev = d1
            if thermal:
                T = heat_inv @ (heat_hold * T + net.joule(f, U) + heat_ext)
                if np.abs(T - T_props).max() > _T_REFRESH:
                    net.set_temperature(T)
                    T_props = T.copy()
                    f, U = net.evaluate(Q, vin[n + 1])[:2]
                    epochs.append((n + 1, net.law, net.load_ratio))
            n += 1
        bar.update(n - reported)
    return _outputs(want, current, Qs, Us, Ts, epochs, edges, lumped)


def _heat_step(tn, nb: int, dt: float):
    """(inverse, hold, source) of the implicit heat step T' = inverse @ (hold·T + Joule +
    source) of the heat network ``tn`` on ``nb`` branches (constant: one inverse, then matvecs)."""
    Kt = np.diag(tn.convection)
    i = np.arange(nb - 1)
    Kt[i, i] += tn.links
    Kt[i + 1, i + 1] += tn.links
    Kt[i, i + 1] -= tn.links
    Kt[i + 1, i] -= tn.links
    heat_inv = linalg.inv(np.diag(tn.capacity / dt) + Kt)
    return heat_inv, tn.capacity / dt, tn.convection * tn.T_ext


def _outputs(want, current, Qs, Us, Ts, epochs, edges, lumped) -> dict[str, np.ndarray]:
    """The arrays :func:`run` returns, (branch, sample) from the per-sample charges ``Qs``
    (and ``Us``, ``Ts``), the load and face excess by the law of each epoch."""
    N = current.size
    out = {"current": current, "load": np.empty_like(Qs)}
    if "c" in want:
        out["c_up"], out["c_low"] = np.empty_like(Qs), np.empty_like(Qs)
    for (a, law, ratio), b in zip(epochs, [e[0] for e in epochs[1:]] + [N]):
        out["load"][a:b] = ratio * Qs[a:b]
        if "c" in want:
            out["c_up"][a:b], out["c_low"][a:b] = law.excess(Qs[a:b])
    out.update({k: v for k, v in (("U", Us), ("Q", Qs), ("T", Ts)) if k in want})
    out = {k: v if k == "current" else np.ascontiguousarray(v.T) for k, v in out.items()}  # (branch, sample)
    if lumped:  # every free segment is the lumped free branch
        nseg = edges.size - 1
        for k, arr in out.items():
            if arr.ndim == 2:
                out[k] = np.vstack([arr[:1], np.repeat(arr[1:2], nseg, axis=0)])
    return out


def _equilibrium_charge(net: BranchNetwork, vin: float) -> np.ndarray:
    """Charge in equilibrium with a constant Vin (the state before the record starts)."""
    Q = np.zeros(net.n)
    for _ in range(100):
        dQ = _equilibrium_step(net, Q, vin)
        Q = Q + dQ
        if np.max(np.abs(dQ)) <= 1e-12 * (np.max(np.abs(Q)) + net.q_scale):
            return Q
    raise ModelError(f"no equilibrium double-layer charge found for Vin = {vin:g} V")


def _equilibrium_step(net: BranchNetwork, Q: np.ndarray, vin: float) -> np.ndarray:
    """Newton step towards dQ/dt = 0 at a constant Vin: solves −J dQ = f."""
    f, _, _, dU = net.evaluate(Q, vin)
    return dgesv(net.newton_matrix(dU, 1.0, shift=0.0), f)[2]


def _tolerance(net: BranchNetwork, Q: np.ndarray) -> float:
    """Newton tolerance [C/m²] at the charge Q: ``_TOL`` of max|Q| + C0·V_T."""
    return _TOL * (np.abs(Q).max() + net.q_scale)


def _at_rest(net: BranchNetwork, Q, f, vin: float, dt: float) -> bool:
    """True if the charge is within the Newton tolerance of its equilibrium at ``vin``: then
    an SDIRK step at that constant input returns it unchanged.  ``f`` (dQ/dt) is a cheap
    first test."""
    tol = _tolerance(net, Q)
    return np.abs(f).max() * dt <= tol and np.abs(_equilibrium_step(net, Q, vin)).max() <= tol


def _constant_input_runs(vin: np.ndarray, v_stage: np.ndarray, rh_key: np.ndarray) -> np.ndarray:
    """For every sample n, the last sample m ≥ n such that the steps n → m have one constant
    input (Vin at both ends and at the stage) and one RH."""
    const = (vin[1:] == vin[:-1]) & (np.abs(v_stage - vin[:-1]) <= 1e-12 * (np.abs(vin[:-1]) + 1e-300)) \
        & (rh_key[1:] == rh_key[:-1])
    N = vin.size
    stop = np.where(const, N - 1, np.arange(N - 1))          # a non-constant step stops the run
    return np.append(np.minimum.accumulate(stop[::-1])[::-1], N - 1)


class _Newton:
    """Newton's method for the SDIRK stages Z = base + hg f(Z), absolute tolerance ``tol``
    [C/m²].  After the k-th update (k ≥ 2) it stops when the estimated remaining error
    θ/(1−θ)·|ΔZ_k| is below tol, θ = |ΔZ_k|/|ΔZ_k−1| being the observed contraction (Hairer &
    Wanner, Solving ODEs II, §IV.8).  After the first update it uses quadratic convergence,
    |ΔZ_2| ≈ K |ΔZ_1|², with K the largest recently observed ratio |ΔZ_2|/|ΔZ_1|² (decaying by
    ``_K_DECAY`` per observation) and a safety factor of 10: it stops if K |ΔZ_1|² ≤ tol/10."""

    _K_DECAY = 0.9

    def __init__(self):
        self.k = np.inf      # no observation yet: always check with a second update

    def solve(self, net, base, hg, vin, Z, tol, state=True):
        """Returns (Z, (f, U) at Z if ``state``) or (None, None).  f = (Z − base)/hg is the
        stage equation's own derivative; U = U_eq + R_b f with U_eq linearised from the last
        evaluation."""
        prev = np.inf
        for it in range(20):
            f, _, Ueq, dU = net.evaluate(Z, vin)
            dZ = dgesv(net.newton_matrix(dU, hg), base + hg * f - Z, overwrite_a=1, overwrite_b=1)[2]
            Z = Z + dZ
            size = np.abs(dZ).max()
            if it == 0:
                done = size <= tol or self.k * size * size <= 0.1 * tol
            else:
                theta = size / prev
                if it == 1:
                    self.k = max(size / (prev * prev), self._K_DECAY * self.k if self.k < np.inf else 0.0)
                done = size <= tol or (theta < 0.5 and theta / (1.0 - theta) * size <= tol)
            if done:
                if not state:
                    return Z, None
                f = (Z - base) / hg
                return Z, (f, Ueq + dU * dZ + net.Rb * f)
            prev = size
        return None, None


def _step(net, newton, Q, h, v3, diffs, depth=0):
    """One SDIRK2 step of length ``h`` from Q with the :class:`_Newton` solver ``newton``.
    ``v3`` = Vin at the start, at gamma·h and at the end; ``diffs`` = the backward
    differences (∇Q, ∇²Q) of the previous samples, for the Newton predictors (quadratic
    extrapolation).  Returns (Q_end, (f, U) at the end); halves the step if Newton fails."""
    v0, vg, v1 = v3
    d1, d2 = diffs
    hg = h * _GAMMA
    tol = _tolerance(net, Q)
    Y1, _ = newton.solve(net, Q, hg, vg, Q + _GAMMA * d1 + _CURVE_1 * d2, tol, state=False)
    if Y1 is not None:
        dY = Y1 - Q
        # quadratic through Q(t − h), Q(t), Y1(t + γh), at t + h
        Y2, ev = newton.solve(net, Q + (1.0 - _GAMMA) / _GAMMA * dY, hg, v1,
                              Q - _PRED_PREV * d1 + _PRED_STAGE * dY, tol)
        if Y2 is not None:
            return Y2, ev
    if depth >= 6:
        raise ModelError("the implicit step did not converge even after halving the step 6 times")
    quad = _quadratic(v0, vg, v1)
    Qm, _ = _step(net, newton, Q, 0.5 * h, (v0, quad(0.5 * _GAMMA), quad(0.5)), (0.5 * d1, 0.25 * d2),
                  depth + 1)
    return _step(net, newton, Qm, 0.5 * h, (quad(0.5), quad(0.5 + 0.5 * _GAMMA), v1),
                 (Qm - Q, Qm - Q - 0.5 * d1), depth + 1)


def _quadratic(v0: float, vg: float, v1: float):
    """Quadratic through Vin at sigma = 0, gamma, 1 of a sample interval."""
    g = _GAMMA
    return lambda x: (v0 * (x - g) * (x - 1) / g + vg * x * (x - 1) / (g * (g - 1))
                      + v1 * x * (x - g) / (1 - g))

