"""Continuous-time linear state-space models and their exact-exponential simulation.

:class:`StateSpace` holds (A, B, C, D) with a few composition rules.  :func:`simulate`
integrates it exactly for an input that is interpolated between samples (linear or
cubic Lagrange "hold"), mode by mode after diagonalising A: each mode is a first-order
recursion run by :func:`scipy.signal.lfilter` in C, so stiff modes (e.g. the µs
double-layer charging) cost nothing and are unconditionally stable.  With cubic hold
the error for a sinusoid at 5 % of the sampling rate is ~1e-5 (linear hold: ~0.8 %
magnitude droop), which is what lets the time-domain FRF meet 1 % / 1°.
"""
from __future__ import annotations

from dataclasses import dataclass
from math import factorial

import numpy as np
from scipy import linalg
from scipy.signal import lfilter, lfiltic


@dataclass
class StateSpace:
    """dx/dt = A x + B u, y = C x + D u (real matrices)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray

    def __post_init__(self):
        self.A = np.atleast_2d(np.asarray(self.A, dtype=float))
        n = self.A.shape[0]
        self.B = np.asarray(self.B, dtype=float).reshape(n, -1) if n else np.zeros((0, np.atleast_2d(self.D).shape[1]))
        self.C = np.asarray(self.C, dtype=float).reshape(-1, n) if n else np.zeros((np.atleast_2d(self.D).shape[0], 0))
        self.D = np.atleast_2d(np.asarray(self.D, dtype=float))

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.D.shape[1]

    @property
    def n_outputs(self) -> int:
        return self.D.shape[0]

    def freqresp(self, s) -> np.ndarray:
        """Transfer matrix at complex frequencies ``s`` (rad/s): shape (n_out, n_in, len(s))."""
        s = np.atleast_1d(s)
        out = np.empty((self.n_outputs, self.n_inputs, s.size), dtype=complex)
        if self.n_states == 0:
            out[:] = self.D[:, :, None]
            return out
        lam, V = linalg.eig(self.A)
        Bt = linalg.solve(V, self.B)
        Ct = self.C @ V
        for k, sk in enumerate(s):
            out[:, :, k] = (Ct / (sk - lam)) @ Bt + self.D
        return out

    def poles(self) -> np.ndarray:
        return linalg.eigvals(self.A) if self.n_states else np.zeros(0)

    def series(self, other: "StateSpace") -> "StateSpace":
        """``other`` after ``self``: y = other(self(u))."""
        n1, n2 = self.n_states, other.n_states
        A = np.block([[self.A, np.zeros((n1, n2))], [other.B @ self.C, other.A]])
        B = np.vstack([self.B, other.B @ self.D])
        C = np.hstack([other.D @ self.C, other.C])
        return StateSpace(A, B, C, other.D @ self.D)

    def inverse(self) -> "StateSpace":
        """Inverse system of a square biproper system (D invertible)."""
        Di = linalg.inv(self.D)
        return StateSpace(self.A - self.B @ Di @ self.C, self.B @ Di, -Di @ self.C, Di)

    def scaled_output(self, g) -> "StateSpace":
        g = np.atleast_2d(g) if np.ndim(g) == 2 else np.diag(np.atleast_1d(g) * np.ones(self.n_outputs))
        return StateSpace(self.A, self.B, g @ self.C, g @ self.D)


def block_diag(*systems: StateSpace) -> StateSpace:
    """Independent systems side by side: inputs and outputs stacked."""
    return StateSpace(linalg.block_diag(*[s.A for s in systems]), linalg.block_diag(*[s.B for s in systems]),
                      linalg.block_diag(*[s.C for s in systems]), linalg.block_diag(*[s.D for s in systems]))


def first_order_lag(tau: float) -> StateSpace:
    """1/(1 + s tau); tau = 0 gives the identity."""
    if tau <= 0:
        return StateSpace(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])
    return StateSpace([[-1.0 / tau]], [[1.0 / tau]], [[1.0]], [[0.0]])


# ----------------------------------------------------------------------------------------
# Exact integration for interpolated inputs
# ----------------------------------------------------------------------------------------
_BLOCK = 1 << 16   # time samples per block of the modal recursion (memory ∝ modes × block)
_HOLD_NODES = {"linear": (0, 1), "cubic": (-1, 0, 1, 2)}


def _lagrange_coeffs(nodes) -> np.ndarray:
    """Monomial coefficients (rows: node, cols: power) of the Lagrange basis on ``nodes``."""
    nodes = np.asarray(nodes, dtype=float)
    V = np.vander(nodes, increasing=True)
    return linalg.inv(V).T  # row j: coefficients of l_j(sigma)


def _moments(mu: np.ndarray, order: int) -> np.ndarray:
    """M_m(mu) = ∫_0^1 exp(mu (1 − sigma)) sigma^m d sigma for m = 0..order, shape (order+1, n)."""
    mu = np.asarray(mu, dtype=complex)
    M = np.empty((order + 1, mu.size), dtype=complex)
    small = np.abs(mu) < 1.0
    if np.any(small):  # series: sum_k mu^k m! / (k + m + 1)!
        ms = mu[small]
        for m in range(order + 1):
            acc = np.zeros(ms.size, dtype=complex)
            term = np.ones(ms.size, dtype=complex)
            for k in range(30):
                acc += term * factorial(m) / factorial(k + m + 1)
                term = term * ms
            M[m, small] = acc
    big = ~small
    if np.any(big):  # recursion M_0 = (e^mu − 1)/mu, M_m = (m M_{m−1} − 1)/mu
        mb = mu[big]
        M[0, big] = np.expm1(mb) / mb
        for m in range(1, order + 1):
            M[m, big] = (m * M[m - 1, big] - 1.0) / mb
    return M


class _PaddedInput:
    """The input with ghost samples before and after (time on the last axis), read by
    column ranges without copying the whole record: ``window(a, b)`` are columns a:b of
    concat(head, u, tail).  ``offset`` is the padded index of sample 0.

    Not periodic: ghosts extrapolate linearly so every step sees all its nodes.  Periodic:
    one period plus sample N (= sample 0), with the ghosts wrapped around."""

    def __init__(self, u: np.ndarray, nodes, periodic: bool = False):
        lo, hi = -min(nodes), max(nodes) - 1
        self.u, self.offset = u, lo
        if periodic:
            self.head = u[..., u.shape[-1] - lo:]
            self.tail = np.concatenate([u[..., :1], u[..., 1:1 + hi]], axis=-1)
        else:
            self.head = u[..., :1] - (u[..., 1:2] - u[..., :1]) * np.arange(lo, 0, -1)
            self.tail = u[..., -1:] + (u[..., -1:] - u[..., -2:-1]) * np.arange(1, hi + 1)

    def full(self) -> np.ndarray:
        return np.concatenate([self.head, self.u, self.tail], axis=-1)

    def window(self, a: int, b: int) -> np.ndarray:
        nh, N = self.head.shape[-1], self.u.shape[-1]
        parts = []
        if a < nh:
            parts.append(self.head[..., a:min(b, nh)])
        if min(b - nh, N) > max(a - nh, 0):
            parts.append(self.u[..., max(a - nh, 0):min(b - nh, N)])
        if b > nh + N:
            parts.append(self.tail[..., max(a - nh - N, 0):b - nh - N])
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)


def simulate(ss: StateSpace, u: np.ndarray, dt: float, x0: np.ndarray | None = None,
             hold: str = "cubic", chunk: int = 16, periodic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Simulate ``ss`` for input samples ``u`` (spacing ``dt`` s).

    ``u`` is (n_in, N), or (n_in, B, N) for a batch of B independent input records run
    through the same system.  Returns (y, x_final): y is (n_out, N) or (n_out, B, N);
    y[..., 0] uses the initial state x0 (zeros by default; (n,) or (n, B)).  Exact for
    inputs that are polynomial (linear or cubic Lagrange) between samples.  Falls back
    to a matrix-exponential recursion when A is not safely diagonalisable.

    ``periodic=True`` treats the record as one period of a periodic input (sample N is
    sample 0 again) and starts from the exact periodic steady state instead of x0: the
    response contains no start-up transient, however slow the system.
    """
    u = np.asarray(u, dtype=float)
    single = u.ndim <= 2
    u = np.atleast_2d(u)[:, None, :] if single else u
    n_in, B, N = u.shape
    if n_in != ss.n_inputs:
        raise ValueError(f"input has {n_in} channels, system expects {ss.n_inputs}")
    if hold not in _HOLD_NODES:
        raise ValueError(f"hold must be one of {sorted(_HOLD_NODES)}")
    n = ss.n_states
    x0 = np.zeros((n, B)) if x0 is None else np.asarray(x0, dtype=float).reshape(n, -1) * np.ones((1, B))
    y = np.einsum("oi,ibn->obn", ss.D, u)
    if n == 0 or N == 0:
        return (y[:, 0] if single else y), (x0[:, 0] if single else x0)
    if N < 3 and hold == "cubic":
        hold = "linear"
    if N < 2:
        y += (ss.C @ x0)[:, :, None]
        return (y[:, 0] if single else y), (x0[:, 0] if single else x0)
    nodes = _HOLD_NODES[hold]
    lam, V = linalg.eig(ss.A)
    if periodic:
        x0 = np.zeros_like(x0)
        N_run = N + 1
    else:
        N_run = N
    if np.linalg.cond(V) > 1e8:
        if periodic:
            raise ValueError("periodic steady state needs a diagonalisable system")
        Y, X = zip(*(_simulate_expm(ss, u[:, b], dt, x0[:, b], nodes) for b in range(B)))
        y, xf = np.stack(Y, axis=1), np.stack(X, axis=1)
        return (y[:, 0] if single else y), (xf[:, 0] if single else xf)
    Vinv = linalg.inv(V)
    Bt, Ct, z0 = Vinv @ ss.B, ss.C @ V, Vinv @ x0
    mu = lam * dt
    M = _moments(mu, len(nodes) - 1)
    W = dt * (_lagrange_coeffs(nodes) @ M)  # (n_nodes, n_modes): weight of u[n + node]
    up = _PaddedInput(u, nodes, periodic)
    lead = max(nodes)
    k0 = up.offset + lead                    # padded index of the newest sample used for z[1]
    x_past = up.window(k0 - len(nodes) + 1, k0)[:, :, ::-1]  # older samples, newest first
    # Conjugate pairs: keep one (Im > 0) and double its real part; real modes count once.
    keep = np.where(lam.imag >= -1e-12 * np.maximum(1.0, np.abs(lam)))[0]
    wgt = np.where(np.abs(lam[keep].imag) > 1e-12 * np.maximum(1.0, np.abs(lam[keep])), 2.0, 1.0)
    a = np.exp(mu)
    z_final = np.array(z0, dtype=complex)
    taps = W[::-1]                           # FIR taps, newest sample first (nodes descending)
    for c0 in range(0, keep.size, chunk):
        idx = keep[c0:c0 + chunk]
        Cw = Ct[:, idx] * wgt[None, c0:c0 + idx.size]
        _add_modes(y[:, :, :1], Cw, z0[idx][:, :, None])     # sample 0: the initial state
        filters = []                                         # per mode: (row, taps, denominator, channel, zi)
        for r, k in enumerate(idx):
            real = lam[k].imag == 0.0
            acc = np.array([1.0, -a[k].real]) if real else np.array([1.0, -a[k]])
            first = _first_input(Bt[k])
            for i in np.nonzero(np.abs(Bt[k]) > 1e-300)[0]:
                b = taps[:, k] * Bt[k, i]
                b = b.real if real else b
                y0 = z0[k] if i == first else np.zeros(B)
                zi = np.stack([lfiltic(b, acc, [y0[bb].real if real else y0[bb]], x_past[i, bb])
                               for bb in range(B)])
                filters.append([r, b, acc, i, zi])
        free = [r for r, k in enumerate(idx) if _first_input(Bt[k]) < 0 and z0[k].any()]
        z_last = np.zeros((idx.size, B), dtype=complex)      # Z at sample N_run - 1
        z_end = np.zeros((idx.size, B), dtype=complex)       # Z at sample N - 1
        # time blocks keep the memory at (modes × block) whatever the record length
        for t0 in range(1, N_run, _BLOCK):
            t1 = min(t0 + _BLOCK, N_run)
            Z = np.zeros((idx.size, B, t1 - t0), dtype=complex)
            x_new = up.window(k0 + t0 - 1, k0 + t1 - 1)      # (n_in, B, t1 - t0): newest sample per step
            for f in filters:
                out, f[4] = lfilter(f[1], f[2], x_new[f[3]], axis=-1, zi=f[4])
                Z[f[0]] += out
            for r in free:
                Z[r] = z0[idx[r]][:, None] * a[idx[r]] ** np.arange(t0, t1)[None, :]
            z_last = Z[:, :, -1]
            if t0 <= N - 1 < t1:
                z_end = Z[:, :, N - 1 - t0]
            _add_modes(y[:, :, t0:min(t1, N)], Cw, Z[:, :, :min(t1, N) - t0])
        if periodic:  # add the homogeneous solution that makes z(N) = z(0)
            den = 1.0 - a[idx] ** N
            ok = np.abs(den) > 1e-13
            zp = np.where(ok[:, None], z_last / np.where(ok, den, 1.0)[:, None], 0.0)
            for t0 in range(0, N, _BLOCK):
                t1 = min(t0 + _BLOCK, N)
                _add_modes(y[:, :, t0:t1], Cw, zp[:, :, None] * a[idx][:, None, None] ** np.arange(t0, t1))
            z_end = z_end + zp * a[idx][:, None] ** (N - 1)
        z_final[idx] = z_end
    conj = np.setdiff1d(np.arange(n), keep)
    z_final[conj] = np.conj(z_final[_partner(lam, conj, keep)])
    xf = (V @ z_final).real
    return (y[:, 0] if single else y), (xf[:, 0] if single else xf)


def _add_modes(y: np.ndarray, Cw: np.ndarray, Z: np.ndarray) -> None:
    """y (n_out, B, T) += Re(Cw Z) for complex modal states Z (modes, B, T)."""
    m, B, T = Z.shape
    Zf = Z.reshape(m, B * T)
    y += (Cw.real @ Zf.real - Cw.imag @ Zf.imag).reshape(-1, B, T)


def _first_input(b: np.ndarray) -> int:
    """Index of the input channel that carries a mode's initial condition."""
    nz = np.nonzero(np.abs(b) > 1e-300)[0]
    return int(nz[0]) if nz.size else -1


def _partner(lam, conj, keep):
    return np.array([keep[np.argmin(np.abs(lam[keep] - np.conj(lam[c])))] for c in conj], dtype=int)


def _simulate_expm(ss: StateSpace, u, dt, x0, nodes):
    """Fallback: exact discretisation by an augmented matrix exponential (Van Loan), then a
    step-by-step recursion.  Slower, but needs no eigenvector basis."""
    n, m = ss.n_states, ss.n_inputs
    p = len(nodes) - 1
    # d/dsigma of [x; u_p; ...; u_0] with the input a polynomial in sigma = t/dt.
    size = n + (p + 1) * m
    Maug = np.zeros((size, size))
    Maug[:n, :n] = ss.A * dt
    Maug[:n, n:n + m] = ss.B * dt  # multiplies the sigma^0 coefficient block
    for k in range(p):  # block k holds coefficient of sigma^k; d/dsigma sigma^(k+1) = (k+1) sigma^k
        Maug[n + k * m:n + (k + 1) * m, n + (k + 1) * m:n + (k + 2) * m] = (k + 1) * np.eye(m)
    E = linalg.expm(Maug)
    Phi, Gam = E[:n, :n], E[:n, n:]
    coeff = _lagrange_coeffs(nodes)  # (node, power)
    pad = _PaddedInput(u, nodes)
    off, up = pad.offset, pad.full()
    N = u.shape[1]
    X = np.empty((n, N))
    X[:, 0] = x0
    # polynomial coefficients (power-major) per step, as a linear map of the node samples
    G = [sum(Gam[:, k * m:(k + 1) * m] * coeff[j, k] for k in range(p + 1)) for j in range(len(nodes))]
    drive = sum(G[j] @ up[:, off + nd: off + nd + N - 1] for j, nd in enumerate(nodes))
    x = x0.copy()
    for i in range(N - 1):
        x = Phi @ x + drive[:, i]
        X[:, i + 1] = x
    return ss.C @ X + ss.D @ u, x
