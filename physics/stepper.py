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
Alexander (1977) with Newton iterations, halving the step when Newton fails.  The
temperature of each segment follows a backward-Euler heat balance with the Joule power
of the step.  Everything is per segment, so the cost is a few small dense solves per
sample.
"""
from __future__ import annotations

import numpy as np
from scipy import linalg

from .effects.double_layer import DoubleLayer
from .errors import ModelError
from .progress import Progress

_GAMMA = 1.0 - 1.0 / np.sqrt(2.0)


class BranchNetwork:
    """The clamp branch (index 0) plus the free segments, at given parameters and temperatures."""

    def __init__(self, model, p: dict, edges: np.ndarray):
        self.model, self.p = model, p
        self.law = model.components["charge_law"]
        self.area = p["width"] * np.concatenate([[p["L_clamp"]], np.diff(edges)])
        self.g = model.components["line"].series_conductances(p, edges)
        self.n = self.area.size
        self.set_temperature(np.full(self.n, p["T_ext"]))

    def set_temperature(self, T: np.ndarray):
        self.T = np.array(T, dtype=float)
        self.d = DoubleLayer.props(self.p, self.T)
        self.Rb = np.broadcast_to(self.d.R_bulk, (self.n,)).astype(float)
        self.G = float(self.d.G_leak)
        if self.g is not None:
            g = self.g
            nf = self.n - 1
            M = np.zeros((nf, nf))
            idx = np.arange(nf)
            M[idx, idx] = g + np.append(g[1:], 0.0) + self.area[1:] * (1.0 / self.Rb[1:] + self.G)
            M[idx[:-1], idx[1:]] = M[idx[1:], idx[:-1]] = -g[1:]
            self.Minv = linalg.inv(M)
            self.Mg0 = self.Minv[:, 0] * g[0]
            self.MA = self.Minv * (self.area[1:] / self.Rb[1:])[None, :]

    def voltages(self, Ueq: np.ndarray, vin: float) -> np.ndarray:
        """Voltage across the polymer of every branch."""
        if self.g is None:
            return np.full(self.n, vin)
        return np.concatenate([[vin], self.Mg0 * vin + self.MA @ Ueq[1:]])

    def rhs(self, Q, vin):
        Ueq, dU, cu, cl = self.law.equilibrium(Q, self.d, self.p)
        U = self.voltages(Ueq, vin)
        return (U - Ueq) / self.Rb, U, Ueq, dU, cu, cl

    def jacobian(self, dU: np.ndarray) -> np.ndarray:
        J = np.diag(-dU / self.Rb)
        if self.g is not None:
            J[1:, 1:] += (self.MA * dU[None, 1:]) / self.Rb[1:, None]
        return J

    def current(self, U, Ueq, vin) -> float:
        """Input current [A]: the clamp branch plus what enters the electrode ladder."""
        Ic = self.area[0] * ((vin - Ueq[0]) / self.Rb[0] + self.G * vin)
        if self.g is None:
            return Ic + float(np.sum(self.area[1:] * ((vin - Ueq[1:]) / self.Rb[1:] + self.G * vin)))
        return Ic + self.g[0] * (vin - U[1])

    def joule(self, U, Ueq, vin) -> np.ndarray:
        """Joule power of every branch and of the electrode links [W] (links split half/half)."""
        P = self.area * ((U - Ueq) ** 2 / self.Rb + self.G * U ** 2)
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
    l = [-x * (x - 1) * (x - 2) / 6, (x + 1) * (x - 1) * (x - 2) / 2, -(x + 1) * x * (x - 2) / 2,
         (x + 1) * x * (x - 1) / 6]
    n = v.size - 1
    return sum(lj * vp[j:j + n] for j, lj in enumerate(l))


def run(model, params_at, t: np.ndarray, vin: np.ndarray, rh: np.ndarray, edges: np.ndarray,
        want: set[str], progress: bool = False) -> dict[str, np.ndarray]:
    """Integrate the branch network.  ``params_at(rh)`` gives the parameters at an RH.

    Returns per-sample arrays: ``current`` (A), ``c_up``/``c_low`` (interface cation
    excess of every branch, mol/m³, branch 0 = clamp) and, if requested in ``want``,
    ``U`` (V), ``Q`` (C/m²) and ``T`` (K) per branch."""
    N = t.size
    dt = float(t[1] - t[0])
    rh_key = np.round(rh / 0.25) * 0.25
    thermal = model.components["temperature"].enabled
    net = BranchNetwork(model, params_at(float(rh_key[0])), edges)
    nb = net.n
    out = {"current": np.empty(N), "c_up": np.empty((nb, N)), "c_low": np.empty((nb, N))}
    for k in ("U", "Q", "T"):
        if k in want:
            out[k] = np.empty((nb, N))
    if thermal:
        tn = model.components["temperature"].network(net.p, edges)
        Kt = np.diag(tn.convection)
        Kt[np.arange(nb - 1), np.arange(nb - 1)] += tn.links
        Kt[np.arange(1, nb), np.arange(1, nb)] += tn.links
        Kt[np.arange(nb - 1), np.arange(1, nb)] -= tn.links
        Kt[np.arange(1, nb), np.arange(nb - 1)] -= tn.links
        heat_lu = linalg.lu_factor(np.diag(tn.capacity / dt) + Kt)
        T = np.full(nb, tn.T_ext)
        T_props = T.copy()
    v_stage = _vin_stage(vin) if N > 1 else vin[:0]
    Q = _equilibrium_charge(net, vin[0])
    _record(out, 0, net, Q, vin[0], want, T if thermal else None)
    key = rh_key[0]
    with Progress(N - 1, "electrochemistry", enabled=progress) as bar:
        for n in range(N - 1):
            if rh_key[n + 1] != key:
                key = rh_key[n + 1]
                Tcur = net.T
                net = BranchNetwork(model, params_at(float(key)), edges)
                net.set_temperature(Tcur)
            Q = _step(net, Q, dt, _interval_input(vin[n], v_stage[n], vin[n + 1]))
            if thermal:
                f, U, Ueq, *_ = net.rhs(Q, vin[n + 1])
                P = net.joule(U, Ueq, vin[n + 1])
                rhs_T = tn.capacity / dt * T + P + tn.convection * tn.T_ext
                T = linalg.lu_solve(heat_lu, rhs_T)
                if np.max(np.abs(T - T_props)) > 5e-3:
                    net.set_temperature(T)
                    T_props = T.copy()
            _record(out, n + 1, net, Q, vin[n + 1], want, T if thermal else None)
            if n % 1000 == 0:
                bar.update(min(1000, N - 1 - n))
    return out


def _equilibrium_charge(net: BranchNetwork, vin: float) -> np.ndarray:
    """Charge in equilibrium with a constant Vin (the state before the record starts)."""
    Q = np.zeros(net.n)
    for _ in range(100):
        f, U, Ueq, dU, *_ = net.rhs(Q, vin)
        J = net.jacobian(dU)
        dQ = linalg.solve(J, -f)
        Q = Q + dQ
        if np.max(np.abs(dQ)) <= 1e-12 * (np.max(np.abs(Q)) + 1e-30):
            return Q
    raise ModelError(f"no equilibrium double-layer charge found for Vin = {vin:g} V")


def _newton(net, base, hg, vin, Z):
    for it in range(12):
        f, U, Ueq, dU, *_ = net.rhs(Z, vin)
        F = Z - base - hg * f
        J = np.eye(net.n) - hg * net.jacobian(dU)
        dZ = linalg.solve(J, -F)
        Z = Z + dZ
        if np.max(np.abs(dZ)) <= 1e-10 * (np.max(np.abs(Z)) + 1e-12):
            return Z
    return None


def _step(net, Q, h, vin, s0=0.0, s1=1.0, depth=0):
    """One SDIRK2 step over the fraction [s0, s1] of the sample interval of length ``h``;
    ``vin(sigma)`` is the input inside the interval.  Halves the step if Newton fails."""
    hs = h * (s1 - s0)
    hg = hs * _GAMMA
    Y1 = _newton(net, Q, hg, vin(s0 + _GAMMA * (s1 - s0)), Q.copy())
    if Y1 is not None:
        k1 = (Y1 - Q) / hg
        Y2 = _newton(net, Q + hs * (1.0 - _GAMMA) * k1, hg, vin(s1), Y1 + hs * (1 - 2 * _GAMMA) * k1)
        if Y2 is not None:
            return Y2
    if depth >= 6:
        raise ModelError("the implicit step did not converge even after halving the step 6 times")
    sm = 0.5 * (s0 + s1)
    return _step(net, _step(net, Q, h, vin, s0, sm, depth + 1), h, vin, sm, s1, depth + 1)


def _interval_input(v0: float, vg: float, v1: float):
    """Quadratic through Vin at sigma = 0, gamma, 1 of a sample interval."""
    g = _GAMMA
    return lambda x: (v0 * (x - g) * (x - 1) / g + vg * x * (x - 1) / (g * (g - 1))
                      + v1 * x * (x - g) / (1 - g))


def _record(out, i, net, Q, vin, want, T):
    f, U, Ueq, dU, cu, cl = net.rhs(Q, vin)
    out["current"][i] = net.current(U, Ueq, vin)
    out["c_up"][:, i] = cu
    out["c_low"][:, i] = cl
    if "U" in out:
        out["U"][:, i] = U
    if "Q" in out:
        out["Q"][:, i] = Q
    if "T" in out:
        out["T"][:, i] = T if T is not None else net.p["T_ext"]
