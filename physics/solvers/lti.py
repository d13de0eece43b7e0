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
from scipy.signal import lfilter


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


def simulate(ss: StateSpace, u: np.ndarray, dt: float, x0: np.ndarray | None = None,
             hold: str = "cubic", chunk: int = 16, periodic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Simulate ``ss`` for input samples ``u`` (spacing ``dt`` s).

    ``u`` is (n_in, N), or (n_in, B, N) for a batch of B independent input records run
    through the same system.  Returns (y, x_final): y is (n_out, N) or (n_out, B, N);
    y[..., 0] uses the initial state x0 (zeros by default; (n,) or (n, B)).  Exact for
    inputs that are polynomial (linear or cubic Lagrange) between samples.  Falls back
    to a matrix-exponential recursion when A is not safely diagonalisable.  A record
    given in pieces: :class:`Stream` (the same recursion).

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
    if n == 0 or N < 2:
        y = np.einsum("oi,ibn->obn", ss.D, u)
        if N:
            y[:, :, :1] += (ss.C @ x0)[:, :, None]
        return (y[:, 0] if single else y), (x0[:, 0] if single else x0)
    if N < 3 and hold == "cubic":
        hold = "linear"
    if periodic:
        lo, hi = -min(_HOLD_NODES[hold]), max(_HOLD_NODES[hold]) - 1
        s = Stream(ss, dt, None, hold, batch=B, chunk=chunk, head=u[..., N - lo:], mark=N - 1)
        if not s.modal:
            raise ValueError("periodic steady state needs a diagonalisable system")
        y = s.run(np.concatenate([u, u[..., :1]], axis=-1), tail=u[..., 1:1 + hi])[..., :N]
        xf = s.close_period(y)
    else:
        s = Stream(ss, dt, x0, hold, batch=B, chunk=chunk)
        y = s.run(u)
        xf = s.x
    return (y[:, 0] if single else y), (xf[:, 0] if single else xf)


class Stream:
    """:func:`simulate` for a record given in pieces: ``push`` the next input samples
    ((n_in, B, m), or (n_in, m) for B = 1) and get the outputs determined so far, then
    ``finish`` for the rest; ``x`` is then the final state.  The concatenated outputs are
    those of :func:`simulate` on the whole record (the same recursion, with the filter
    states carried over), so memory stays at one piece whatever the record length.

    The hold's interpolation looks ahead: with cubic hold an output waits for the next
    input sample, so each ``push`` returns one sample fewer than it took (``finish``
    extrapolates the input past its end as :func:`simulate` does, or uses ``tail``).
    ``head``: input samples before sample 0 (default: linear extrapolation, as
    :func:`simulate`); ``mark``: a sample whose modal state is kept (``z_mark``)."""

    def __init__(self, ss: StateSpace, dt: float, x0=None, hold: str = "cubic", batch: int = 1,
                 chunk: int = 16, head: np.ndarray | None = None, mark: int | None = None):
        if hold not in _HOLD_NODES:
            raise ValueError(f"hold must be one of {sorted(_HOLD_NODES)}")
        self.ss, self.dt, self.B, self.chunk, self.mark = ss, float(dt), int(batch), int(chunk), mark
        self.nodes = _HOLD_NODES[hold]
        self.lo, self.hi = -min(self.nodes), max(self.nodes) - 1
        n = ss.n_states
        self.x = np.zeros((n, self.B)) if x0 is None else \
            np.asarray(x0, dtype=float).reshape(n, -1) * np.ones((1, self.B))
        self.head = head
        self._raw = np.zeros((ss.n_inputs, self.B, 0))      # received samples n_out.. not yet emitted
        self._last2 = self._raw                              # the last two samples received
        self.n_out = 0
        self.z_mark = None
        self.modal = True
        if n:
            lam, V = linalg.eig(ss.A)
            self.modal = bool(np.linalg.cond(V) <= 1e8)
            if self.modal:
                self.lam, self.V = lam, V
            else:
                self._expm_setup()

    # -- public ---------------------------------------------------------------------------
    def push(self, u: np.ndarray) -> np.ndarray:
        """Outputs (n_out, B, k) [or (n_out, k)] for the input samples now determined."""
        u = np.asarray(u, dtype=float)
        single = u.ndim <= 2
        u = np.atleast_2d(u)[:, None, :] if single else u
        self._raw = np.concatenate([self._raw, u], axis=-1)
        self._last2 = np.concatenate([self._last2, u], axis=-1)[..., -2:]
        y = self._advance()
        return y[:, 0] if single else y

    def finish(self, tail: np.ndarray | None = None) -> np.ndarray:
        """The outputs still owed (the last ``hi`` samples); the final state is ``x``."""
        if self.n_out == 0:                     # short records, as simulate() treats them
            k = self._raw.shape[-1]
            if k == 0:
                raise ValueError("a streamed record needs at least one sample")
            if k == 1:                          # the initial state alone
                self.n_out = 1
                return (self.ss.D @ self._raw[:, :, 0] + self.ss.C @ self.x)[:, :, None]
            if k == 2 and self.hi and tail is None:   # too short for cubic hold: linear
                self.nodes, self.lo, self.hi = _HOLD_NODES["linear"], 0, 0
                if self.ss.n_states and not self.modal:
                    self._expm_setup()
        if tail is None:
            last, prev = self._last2[..., -1:], self._last2[..., -2:-1]
            tail = last + (last - prev) * np.arange(1, self.hi + 1)
        y = self._advance(np.asarray(tail, dtype=float).reshape(self.ss.n_inputs, self.B, self.hi))
        if self.ss.n_states and self.modal:
            self.x = self._state(self.z)
        return y

    def run(self, u: np.ndarray, tail: np.ndarray | None = None) -> np.ndarray:
        """The whole record (n_in, B, N) at once, in blocks: outputs (n_out, B, N)."""
        y = np.empty((self.ss.n_outputs, self.B, u.shape[-1]))
        k = 0
        for a in range(0, u.shape[-1], _BLOCK):
            out = self.push(u[..., a:a + _BLOCK])
            y[..., k:k + out.shape[-1]] = out
            k += out.shape[-1]
        out = self.finish(tail)
        y[..., k:k + out.shape[-1]] = out
        return y

    def close_period(self, y: np.ndarray) -> np.ndarray:
        """Periodic steady state: ``y`` (the first N outputs of a record of N + 1 samples,
        sample N = sample 0, started from rest) += the homogeneous solution that makes
        z(N) = z(0); returns the state at sample N − 1."""
        N = y.shape[-1]
        a = np.exp(self.lam * self.dt)
        keep, wgt, Ct = self._kept()
        den = 1.0 - a[keep] ** N
        ok = np.abs(den) > 1e-13
        zp = np.where(ok[:, None], self.z[keep] / np.where(ok, den, 1.0)[:, None], 0.0)
        for t0 in range(0, N, _BLOCK):
            t1 = min(t0 + _BLOCK, N)
            _add_modes(y[:, :, t0:t1], Ct[:, keep] * wgt, zp[:, :, None] * a[keep][:, None, None] ** np.arange(t0, t1))
        z = np.array(self.z_mark, dtype=complex)
        z[keep] += zp * a[keep][:, None] ** (N - 1)
        return self._state(z)

    # -- the recursion --------------------------------------------------------------------
    def _advance(self, tail: np.ndarray | None = None) -> np.ndarray:
        """Emit the outputs whose look-ahead samples have arrived (all of them with ``tail``)."""
        n_out_ch = self.ss.n_outputs
        if self.n_out == 0:
            if self._raw.shape[-1] < (3 if self.hi else 2) and tail is None:
                return np.zeros((n_out_ch, self.B, 0))
            first = self._start()
        else:
            first = np.zeros((n_out_ch, self.B, 0))
        # newest sample of each step: raw samples from index n_out + hi on, then the tail
        new = self._raw[..., self.hi:]
        if tail is not None:
            new = np.concatenate([new, tail], axis=-1)
        m = new.shape[-1]
        y = np.einsum("oi,ibn->obn", self.ss.D, self._raw[..., :m])
        if self.ss.n_states:
            (self._modal_steps if self.modal else self._expm_steps)(new, y)
        self._raw = self._raw[..., m:]
        self.n_out += m
        return np.concatenate([first, y], axis=-1) if first.shape[-1] else y

    def _start(self) -> np.ndarray:
        """Initial filter states from x0 and the first samples; returns y[0]."""
        u = self._raw
        head = self.head if self.head is not None else \
            u[..., :1] - (u[..., 1:2] - u[..., :1]) * np.arange(self.lo, 0, -1)
        past = np.concatenate([head, u[..., :max(self.nodes)]], axis=-1)   # padded samples before step 1
        y0 = self.ss.D @ u[:, :, 0] + self.ss.C @ self.x
        n = self.ss.n_states
        if n and self.modal:
            self._modal_setup(past[..., ::-1], linalg.inv(self.V) @ self.x)
        elif n:
            self._hist = past
        self._raw = u[..., 1:]
        self.n_out = 1
        return y0[:, :, None]

    def _kept(self):
        """Conjugate pairs: one mode (Im > 0) with its real part doubled; real modes once."""
        lam = self.lam
        keep = np.where(lam.imag >= -1e-12 * np.maximum(1.0, np.abs(lam)))[0]
        wgt = np.where(np.abs(lam[keep].imag) > 1e-12 * np.maximum(1.0, np.abs(lam[keep])), 2.0, 1.0)
        return keep, wgt, self.ss.C @ self.V

    def _modal_setup(self, x_past: np.ndarray, z0: np.ndarray) -> None:
        lam, B = self.lam, self.B
        keep, wgt, Ct = self._kept()
        Bt = linalg.inv(self.V) @ self.ss.B
        mu = lam * self.dt
        W = self.dt * (_lagrange_coeffs(self.nodes) @ _moments(mu, len(self.nodes) - 1))
        taps = W[::-1]                           # FIR taps, newest sample first (nodes descending)
        self.a = a = np.exp(mu)
        self.z = np.array(z0, dtype=complex)     # modal state at the last emitted sample
        self.t = 1                               # index of the next modal sample
        self.groups = []
        for c0 in range(0, keep.size, self.chunk):
            idx = keep[c0:c0 + self.chunk]
            filters = []                         # per mode: (row, taps, denominator, channel, zi)
            for r, k in enumerate(idx):
                real = lam[k].imag == 0.0
                acc = np.array([1.0, -a[k].real]) if real else np.array([1.0, -a[k]])
                first = _first_input(Bt[k])
                for i in np.nonzero(np.abs(Bt[k]) > 1e-300)[0]:
                    b = taps[:, k] * Bt[k, i]
                    b = b.real if real else b
                    y0 = z0[k] if i == first else np.zeros(B)
                    filters.append([r, b, acc, i, _initial_state(b, a[k], y0, x_past[i], real)])
            free = [r for r, k in enumerate(idx) if _first_input(Bt[k]) < 0 and z0[k].any()]
            self.groups.append((idx, Ct[:, idx] * wgt[None, c0:c0 + idx.size], filters, free, z0[idx]))

    def _modal_steps(self, new: np.ndarray, y: np.ndarray) -> None:
        """y (n_out, B, m) += the modal response at samples t .. t + m − 1, from the newest
        input sample of each step ``new`` (n_in, B, m)."""
        m = new.shape[-1]
        for b0 in range(0, m, _BLOCK):          # time blocks keep the memory at modes × block
            b1 = min(b0 + _BLOCK, m)
            t0 = self.t + b0
            for idx, Cw, filters, free, z0 in self.groups:
                Z = np.zeros((idx.size, self.B, b1 - b0), dtype=complex)
                for f in filters:
                    out, f[4] = lfilter(f[1], f[2], new[f[3], :, b0:b1], axis=-1, zi=f[4])
                    Z[f[0]] += out
                for r in free:
                    Z[r] = z0[r][:, None] * self.a[idx[r]] ** np.arange(t0, t0 + b1 - b0)[None, :]
                self.z[idx] = Z[:, :, -1]
                if self.mark is not None and t0 <= self.mark < t0 + b1 - b0:
                    if self.z_mark is None:
                        self.z_mark = np.zeros_like(self.z)
                    self.z_mark[idx] = Z[:, :, self.mark - t0]
                _add_modes(y[:, :, b0:b1], Cw, Z)
        self.t += m

    def _state(self, z: np.ndarray) -> np.ndarray:
        """The state x from the kept modal states (conjugate partners filled in)."""
        keep = self._kept()[0]
        z = np.array(z, dtype=complex)
        conj = np.setdiff1d(np.arange(self.lam.size), keep)
        z[conj] = np.conj(z[_partner(self.lam, conj, keep)])
        return (self.V @ z).real

    # -- fallback: augmented matrix exponential --------------------------------------------
    def _expm_setup(self) -> None:
        """Exact discretisation by an augmented matrix exponential (Van Loan), stepped
        sample by sample: slower, but needs no eigenvector basis."""
        ss, dt = self.ss, self.dt
        n, m = ss.n_states, ss.n_inputs
        p = len(self.nodes) - 1
        # d/dsigma of [x; u_p; ...; u_0] with the input a polynomial in sigma = t/dt.
        size = n + (p + 1) * m
        Maug = np.zeros((size, size))
        Maug[:n, :n] = ss.A * dt
        Maug[:n, n:n + m] = ss.B * dt  # multiplies the sigma^0 coefficient block
        for k in range(p):  # block k holds coefficient of sigma^k; d/dsigma sigma^(k+1) = (k+1) sigma^k
            Maug[n + k * m:n + (k + 1) * m, n + (k + 1) * m:n + (k + 2) * m] = (k + 1) * np.eye(m)
        E = linalg.expm(Maug)
        self.Phi, Gam = E[:n, :n], E[:n, n:]
        coeff = _lagrange_coeffs(self.nodes)  # (node, power)
        # per node: the map of its sample to the step's drive
        self.G = np.stack([sum(Gam[:, k * m:(k + 1) * m] * coeff[j, k] for k in range(p + 1))
                           for j in range(len(self.nodes))])

    def _expm_steps(self, new: np.ndarray, y: np.ndarray) -> None:
        m, w = new.shape[-1], len(self.nodes)
        seq = np.concatenate([self._hist, new], axis=-1)      # the samples of every step's nodes
        drive = sum(np.einsum("ni,ibt->nbt", self.G[j], seq[..., j:j + m]) for j in range(w))
        X = np.empty((self.ss.n_states, self.B, m))
        x = self.x
        for i in range(m):
            x = self.Phi @ x + drive[:, :, i]
            X[:, :, i] = x
        self.x = x
        self._hist = seq[..., m:]
        y += np.einsum("on,nbt->obt", self.ss.C, X)


def _add_modes(y: np.ndarray, Cw: np.ndarray, Z: np.ndarray) -> None:
    """y (n_out, B, T) += Re(Cw Z) for complex modal states Z (modes, B, T)."""
    m, B, T = Z.shape
    Zf = Z.reshape(m, B * T)
    y += (Cw.real @ Zf.real - Cw.imag @ Zf.imag).reshape(-1, B, T)


def _initial_state(b: np.ndarray, a: complex, y0: np.ndarray, x_past: np.ndarray, real: bool) -> np.ndarray:
    """``scipy.signal.lfiltic(b, [1, −a], [y0], x_past)`` for the B records at once (B, max(M, 1)),
    M = len(b) − 1: the state of the transposed direct form II of y[n] = a y[n−1] + Σ_j b[j] u[n−j]
    after the inputs ``x_past`` (B, P; newest first, zeros beyond P) and the output ``y0`` (B,)."""
    m_taps = b.size - 1
    xp = x_past[:, :m_taps]
    if xp.shape[1] < m_taps:
        xp = np.pad(xp, ((0, 0), (0, m_taps - xp.shape[1])))
    zi = np.zeros((x_past.shape[0], max(m_taps, 1)), dtype=float if real else complex)
    for m in range(m_taps):
        zi[:, m] = xp[:, :m_taps - m] @ b[m + 1:]
    zi[:, 0] += (a.real * y0.real) if real else a * y0
    return zi


def _first_input(b: np.ndarray) -> int:
    """Index of the input channel that carries a mode's initial condition."""
    nz = np.nonzero(np.abs(b) > 1e-300)[0]
    return int(nz[0]) if nz.size else -1


def _partner(lam, conj, keep):
    return np.array([keep[np.argmin(np.abs(lam[keep] - np.conj(lam[c])))] for c in conj], dtype=int)
