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
convergence, so a small Newton step means a small error) started from a time
extrapolation of the previous samples, halving the step when Newton fails.  (A
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

from .effects.double_layer import DoubleLayer
from .errors import ModelError
from .progress import Progress

_GAMMA = 1.0 - 1.0 / np.sqrt(2.0)
#: Temperature change [K] after which the electrochemical properties are re-derived
#: (the mobility changes by 1/T, eq. 6: 0.02 K is a 7e-5 relative change).
_T_REFRESH = 0.02


class BranchNetwork:
    """The clamp branch (index 0) plus the free branches, at given parameters and temperatures.

    ``lumped``: all free segments see Vin and the same temperature, so one free branch
    (of their total area) stands for all of them."""

    def __init__(self, model, p: dict, edges: np.ndarray, lumped: bool = False):
        self.model, self.p = model, p
        self.law_effect = model.components["charge_law"]
        areas = p["width"] * np.diff(edges)
        if lumped:
            areas = np.array([areas.sum()])
        self.area = np.concatenate([[p["width"] * p["L_clamp"]], areas])
        self.g = None if lumped else model.components["line"].series_conductances(p, edges)
        self.n = self.area.size
        self.set_temperature(np.full(self.n, p["T_ext"]))

    def set_temperature(self, T: np.ndarray):
        self.T = np.array(T, dtype=float)
        self.d = DoubleLayer.props(self.p, self.T)
        self.law = self.law_effect.compiled(self.d, self.p)
        self.Rb = np.broadcast_to(self.d.R_bulk, (self.n,)).astype(float)
        self.inv_Rb = 1.0 / self.Rb
        self.G = float(self.d.G_leak)
        self.load_ratio = self.d.c0 / self.d.C0   # first-moment-equivalent excess per charge
        self.q_scale = float(np.max(self.d.C0) * np.max(self.d.V_T))  # charge of a thermal voltage
        if self.g is not None:
            g = self.g
            nf = self.n - 1
            M = np.zeros((nf, nf))
            idx = np.arange(nf)
            M[idx, idx] = g + np.append(g[1:], 0.0) + self.area[1:] * (self.inv_Rb[1:] + self.G)
            M[idx[:-1], idx[1:]] = M[idx[1:], idx[:-1]] = -g[1:]
            Minv = linalg.inv(M)
            self.Mg0 = Minv[:, 0] * g[0]
            self.MA = Minv * (self.area[1:] * self.inv_Rb[1:])[None, :]
            self.RMA = self.MA * self.inv_Rb[1:, None]

    def _voltages(self, Ueq: np.ndarray, vin: float) -> np.ndarray:
        U = np.empty(self.n)
        U[0] = vin
        if self.g is None:
            U[1:] = vin
        else:
            U[1:] = self.Mg0 * vin + self.MA @ Ueq[1:]
        return U

    def rhs(self, Q, vin):
        """(dQ/dt, U, U_eq, law state) at charge Q and input vin."""
        Ueq, st = self.law.potential(Q)
        U = self._voltages(Ueq, vin)
        return (U - Ueq) * self.inv_Rb, U, Ueq, st

    def rhs_jacobian(self, Q, vin):
        """(dQ/dt, ∂(dQ/dt)/∂Q, U, U_eq, law state)."""
        Ueq, dU, st = self.law.evaluate(Q)
        U = self._voltages(Ueq, vin)
        J = np.zeros((self.n, self.n))
        if self.g is not None:
            np.multiply(self.RMA, dU[1:], out=J[1:, 1:])
        J.flat[::self.n + 1] -= dU * self.inv_Rb
        return (U - Ueq) * self.inv_Rb, J, U, Ueq, st

    def current(self, U, Ueq, vin) -> float:
        """Input current [A]: the clamp branch plus what enters the electrode ladder."""
        if self.g is None:
            return float(np.sum(self.area * ((vin - Ueq) * self.inv_Rb + self.G * vin)))
        Ic = self.area[0] * ((vin - Ueq[0]) * self.inv_Rb[0] + self.G * vin)
        return Ic + self.g[0] * (vin - U[1])

    def joule(self, U, Ueq, vin) -> np.ndarray:
        """Joule power of every branch and of the electrode links [W] (links split half/half)."""
        P = self.area * ((U - Ueq) ** 2 * self.inv_Rb + self.G * U ** 2)
        if self.g is not None:
            drop = np.diff(np.concatenate([[vin], U[1:]]))
            Pl = self.g * drop ** 2
            P[:-1] += 0.5 * Pl
            P[1:] += 0.5 * Pl
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

    Returns per-sample arrays: ``current`` (A), ``load`` (first-moment-equivalent interface
    cation excess (c0/C0)·Q, mol/m³), ``c_up``/``c_low`` (cation excess at the faces, mol/m³),
    all per branch (branch 0 = clamp), and, if requested in ``want``, ``U`` (V), ``Q``
    (C/m²) and ``T`` (K) per branch."""
    N = t.size
    dt = float(t[1] - t[0])
    rh_key = np.round(rh / 0.25) * 0.25
    thermal = model.components["temperature"].enabled
    lumped = not thermal and not model.components["line"].enabled
    net = BranchNetwork(model, params_at(float(rh_key[0])), edges, lumped)
    nb = net.n
    out = {"current": np.empty(N), "load": np.empty((nb, N)), "c_up": np.empty((nb, N)),
           "c_low": np.empty((nb, N))}
    for k in ("U", "Q", "T"):
        if k in want:
            out[k] = np.empty((nb, N))
    if thermal:
        tn = model.components["temperature"].network(net.p, edges)
        Kt = np.diag(tn.convection)
        i = np.arange(nb - 1)
        Kt[i, i] += tn.links
        Kt[i + 1, i + 1] += tn.links
        Kt[i, i + 1] -= tn.links
        Kt[i + 1, i] -= tn.links
        heat_inv = linalg.inv(np.diag(tn.capacity / dt) + Kt)   # constant: one inverse, then matvecs
        T = np.full(nb, tn.T_ext)
        T_props = T.copy()
    v_stage = _vin_stage(vin)
    Q = _equilibrium_charge(net, vin[0])
    Q_prev = Q
    last = net.rhs(Q, vin[0])
    _record(out, 0, net, Q, vin[0], last, T if thermal else None)
    key = rh_key[0]
    with Progress(N - 1, "electrochemistry", enabled=progress) as bar:
        for n in range(N - 1):
            if rh_key[n + 1] != key:
                key = rh_key[n + 1]
                Tcur = net.T
                net = BranchNetwork(model, params_at(float(key)), edges, lumped)
                net.set_temperature(Tcur)
            trend = Q - Q_prev
            Q_prev = Q
            Q, last = _step(net, Q, dt, (vin[n], v_stage[n], vin[n + 1]), trend)
            if thermal:
                _, U, Ueq, _ = last
                P = net.joule(U, Ueq, vin[n + 1])
                T = heat_inv @ (tn.capacity / dt * T + P + tn.convection * tn.T_ext)
                if np.abs(T - T_props).max() > _T_REFRESH:
                    net.set_temperature(T)
                    T_props = T.copy()
                    last = net.rhs(Q, vin[n + 1])
            _record(out, n + 1, net, Q, vin[n + 1], last, T if thermal else None)
            if n % 1000 == 0:
                bar.update(min(1000, N - 1 - n))
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
        f, J, *_ = net.rhs_jacobian(Q, vin)
        dQ = dgesv(J, -f)[2]
        Q = Q + dQ
        if np.max(np.abs(dQ)) <= 1e-12 * (np.max(np.abs(Q)) + net.q_scale):
            return Q
    raise ModelError(f"no equilibrium double-layer charge found for Vin = {vin:g} V")


def _newton(net, base, hg, vin, Z, tol):
    """Solve Z = base + hg f(Z) by Newton's method (absolute tolerance ``tol``, C/m²).
    Stops when the estimated remaining error θ/(1−θ)·|ΔZ| is below ``tol``, θ being the
    observed contraction |ΔZ_k|/|ΔZ_k−1| (Hairer & Wanner, Solving ODEs II, §IV.8).
    Returns (Z, evaluation at the last iterate) or (None, None)."""
    n1 = net.n + 1
    prev = np.inf
    for _ in range(20):
        ev = net.rhs_jacobian(Z, vin)
        J = ev[1]
        J *= -hg
        J.flat[::n1] += 1.0
        dZ = dgesv(J, base + hg * ev[0] - Z, overwrite_a=1, overwrite_b=1)[2]
        Z = Z + dZ
        size = np.abs(dZ).max()
        theta = size / prev
        if size <= tol or (prev < np.inf and theta < 0.5 and theta / (1.0 - theta) * size <= tol):
            return Z, (ev[0],) + ev[2:]
        prev = size
    return None, None


def _step(net, Q, h, v3, trend, depth=0):
    """One SDIRK2 step of length ``h`` from Q.  ``v3`` = Vin at the start, at gamma·h and at
    the end; ``trend`` = the change of Q over the previous step (predictor).  Returns
    (Q_end, evaluation at the end); halves the step if Newton fails."""
    v0, vg, v1 = v3
    hg = h * _GAMMA
    tol = 1e-7 * (np.abs(Q).max() + net.q_scale)
    Y1, _ = _newton(net, Q, hg, vg, Q + _GAMMA * trend, tol)
    if Y1 is not None:
        k1 = (Y1 - Q) / hg
        Y2, ev = _newton(net, Q + h * (1.0 - _GAMMA) * k1, hg, v1, Y1 + (1.0 - _GAMMA) * trend, tol)
        if Y2 is not None:
            return Y2, ev
    if depth >= 6:
        raise ModelError("the implicit step did not converge even after halving the step 6 times")
    quad = _quadratic(v0, vg, v1)
    Qm, _ = _step(net, Q, 0.5 * h, (v0, quad(0.5 * _GAMMA), quad(0.5)), 0.5 * trend, depth + 1)
    return _step(net, Qm, 0.5 * h, (quad(0.5), quad(0.5 + 0.5 * _GAMMA), v1), Qm - Q, depth + 1)


def _quadratic(v0: float, vg: float, v1: float):
    """Quadratic through Vin at sigma = 0, gamma, 1 of a sample interval."""
    g = _GAMMA
    return lambda x: (v0 * (x - g) * (x - 1) / g + vg * x * (x - 1) / (g * (g - 1))
                      + v1 * x * (x - g) / (1 - g))


def _record(out, i, net, Q, vin, ev, T):
    _, U, Ueq, st = ev
    out["current"][i] = net.current(U, Ueq, vin)
    out["load"][:, i] = net.load_ratio * Q
    out["c_up"][:, i], out["c_low"][:, i] = net.law.excess(st)
    if "U" in out:
        out["U"][:, i] = U
    if "Q" in out:
        out["Q"][:, i] = Q
    if "T" in out:
        out["T"][:, i] = T if T is not None else net.p["T_ext"]
