"""Nonlinear Poisson–Nernst–Planck + solvent transport through the thickness (thesis eq. 1–8).

Through-thickness coordinate x ∈ [−h, h] [m] (h = t_polymer/2); the lower face x = −h sits at
+U/2, the upper face x = +h at −U/2, so U > 0 drives the cations to the upper face (the
cathode), as in the reduced model.  One mobile cation (charge z, diffusivity D), fixed
anions C⁻ [mol/m³], solvent dragged by the cations (n⁺ per cation) and diffusing (Ds):

    Poisson (eq. 1 without the leakage, which is a parallel conductance σ/(2h)):
        −κe ∂²φ/∂x² = z F (C⁺ − C⁻)
    Nernst–Planck (eq. 3–6), mobility µ = D/(RT) (eq. 6):
        ∂C⁺/∂t = −∂f/∂x,   f = −D (∂C⁺/∂x + (zF/RT) C⁺ ∂φ/∂x)
    solvent (eq. 7):   ∂Cs/∂t = −∂(n⁺ f − Ds ∂Cs/∂x)/∂x
    blocking, impermeable faces: f = 0 and n⁺f − Ds ∂Cs/∂x = 0 at x = ±h.

Discretisation: vertex-centred finite volumes (box method) on a mesh graded geometrically
from both faces (first cell ≪ Debye length λ), Scharfetter–Gummel fluxes for the cation
(exact for a constant field between two nodes, so the Boltzmann equilibrium is a discrete
steady state), central fluxes for the solvent diffusion.  Scaled unknowns per node
(ψ = zFφ/RT, ĉ = C⁺/C⁻, ŝ = (Cs − Cs0)/C⁻), interleaved so that the Jacobian is banded
(5 sub- and 3 super-diagonals) and factorised by LAPACK ``gbtrf``.

Time stepping: TR-BDF2 (γ = 2 − √2; Bank et al. 1985, Hosea & Shampine 1996), L-stable and
second order, with the embedded third-order error estimate filtered through the iteration
matrix, adaptive steps, full Newton per stage, and steps that land on the input's kinks.
The cation and solvent rows are written in conservative form (the totals change only by
the linear solver's round-off) and each stage ends with a projection onto the initial totals,
so ∫C⁺ dx and ∫Cs dx are constant to round-off however long the run.

Several identical slabs ("slices") can be integrated together; they are either all driven
by the same voltage or coupled along the strip through the electrode resistance (a
resistive ladder whose node voltages are extra algebraic unknowns; see
:mod:`physics.reference.strip`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import solve_banded
from scipy.linalg.lapack import dgbtrf, dgbtrs, zgbtrf, zgbtrs

from ..constants import FARADAY, GAS_CONSTANT
from ..errors import InputError, ModelError

KL, KU = 5, 3                    # band widths of the interleaved (ψ, ĉ, ŝ) Jacobian
_GAMMA = 2.0 - np.sqrt(2.0)      # TR-BDF2 stage fraction
_D = _GAMMA / 2.0                # implicit weight of both stages
_W = np.sqrt(2.0) / 4.0          # TR-BDF2 weights of f_n and f_γ
_E = ((1.0 - _W) / 3.0 - _W, (3.0 * _W + 1.0) / 3.0 - _W, _D / 3.0 - _D)  # embedded 3rd order − TR-BDF2
#: the outputs of :meth:`Integrator.run` at the sample times (see :meth:`Slab.outputs`)
_OUTPUTS = ("Q", "j", "c_up", "c_low", "m_up", "m_low", "m_cat", "U")


@dataclass(frozen=True)
class SlabParams:
    """Parameters of one slab (SI units)."""

    h: float            # half thickness [m]
    kappa: float        # permittivity κe = ε0 εr [F/m]
    C_anion: float      # fixed anions C⁻ = initial cations C⁺0 [mol/m³]
    z: float            # cation charge number
    D: float            # cation diffusivity at T [m²/s]
    T: float            # temperature [K]
    n_solv: float       # solvent molecules dragged per cation n⁺
    D_solvent: float    # solvent diffusivity Ds [m²/s] (0: no back-diffusion)
    C_solvent0: float   # initial solvent concentration Cs0 [mol/m³]
    sigma_leak: float   # electronic conductivity of the polymer σ (eq. 1) [S/m]

    @classmethod
    def from_params(cls, p: dict, T: float | None = None, D_solvent: float | None = None,
                    props=None) -> "SlabParams":
        """From a device parameter dict (SI).  ``T`` [K] defaults to ``T_ext``; the permittivity,
        thickness and D at T come from the double layer's ``props(p, T)`` (default
        :meth:`physics.effects.double_layer.DoubleLayer.props`; a model's own stage:
        :meth:`physics.model.ActuatorModel.double_layer_props`), so the mobility follows eq. 6
        through V_T = RT/(zF) as there.  ``D_solvent`` [m²/s]: the solvent's back-diffusion
        (default the device's value; 0: none)."""
        from ..effects.double_layer import DoubleLayer
        T = float(p["T_ext"] if T is None else T)
        d = (props or DoubleLayer.props)(p, T)
        return cls(h=d.h, kappa=d.kappa, C_anion=d.C_anion, z=d.z, D=float(d.D), T=T, n_solv=p["n_solvation"],
                   D_solvent=float(p["D_solvent"] if D_solvent is None else D_solvent),
                   C_solvent0=p["C_solvent0"], sigma_leak=p["sigma_polymer"])

    @property
    def V_T(self) -> float:
        """Thermal voltage RT/(zF) [V]."""
        return GAS_CONSTANT * self.T / (self.z * FARADAY)

    @property
    def lam(self) -> float:
        """Debye length λ = sqrt(κe RT/(z² F² C⁻)) [m]."""
        return float(np.sqrt(self.kappa * self.V_T / (self.z * FARADAY * self.C_anion)))

    @property
    def Lambda(self) -> float:
        """Λ = 2(hλ coth(h/λ) − λ²) [m²]: first moment ∫x ΔC⁺ dx of the linearised (Debye–Hückel)
        cation excess per unit of its antisymmetric interface value (ΔC⁺ ∝ sinh(x/λ)).  It maps a
        first moment [mol/m] to the reduced model's interface-equivalent load [mol/m³]."""
        lam, h = self.lam, self.h
        return 2.0 * (h * lam / np.tanh(h / lam) - lam ** 2)

    @property
    def G_leak(self) -> float:
        """Electronic leakage conductance per area σ/(2h) [S/m²]."""
        return self.sigma_leak / (2.0 * self.h)


def graded_mesh(h: float, lam: float, first: float | None = None, growth: float = 1.08,
                max_cell: float | None = None) -> np.ndarray:
    """Nodes on [−h, h] [m], symmetric, with a node at 0: cells grow geometrically by ``growth``
    from ``first`` (default λ/100) at both faces up to ``max_cell`` (default h/100), uniform in
    between."""
    first = lam / 100.0 if first is None else float(first)
    max_cell = h / 100.0 if max_cell is None else float(max_cell)
    if not (0 < first <= max_cell < h) or growth < 1.0:
        raise InputError("mesh: need 0 < first cell <= max cell < h and growth >= 1")
    inc = []
    d, a = 0.0, first
    while a < max_cell and d + a < h:
        inc.append(a)
        d += a
        a *= growth
    rest = h - d
    n_u = max(1, int(np.ceil(rest / max_cell - 1e-9)))
    inc += [rest / n_u] * n_u
    half = np.concatenate([[0.0], np.cumsum(inc)])
    half[-1] = h
    left = -h + half
    left[-1] = 0.0
    return np.concatenate([left, -left[-2::-1]])


def bernoulli(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """B(x) = x/(eˣ − 1) and B'(x), without overflow or cancellation."""
    x = np.asarray(x, dtype=float)
    B = np.empty_like(x)
    dB = np.empty_like(x)
    small = np.abs(x) < 1e-3
    xs = x[small]
    B[small] = 1.0 - xs / 2.0 + xs * xs / 12.0
    dB[small] = -0.5 + xs / 6.0
    xb = x[~small]
    with np.errstate(over="ignore"):
        Bb = xb / np.expm1(xb)
    B[~small] = Bb
    dB[~small] = Bb * (1.0 - Bb - xb) / xb
    return B, dB


class Slab:
    """The discretised slab: S slices sharing one mesh and one parameter set.

    State ``y`` (S, 3 N) with N nodes, interleaved (ψ_i, ĉ_i, ŝ_i).  Rows 3i+1, 3i+2 are the
    (conservative) cation and solvent balances of the control volume of node i; rows 3i are
    Poisson's equation (Dirichlet at the two face nodes)."""

    def __init__(self, prm: SlabParams, x: np.ndarray):
        self.prm = prm
        self.x = np.asarray(x, dtype=float)
        self.N = self.x.size
        self.n = 3 * self.N
        self.dx = np.diff(self.x)
        V = np.zeros(self.N)
        V[:-1] += 0.5 * self.dx
        V[1:] += 0.5 * self.dx
        self.V = V                                      # control-volume lengths [m]
        self.lam2 = prm.lam ** 2
        i = np.arange(self.N)
        self.ip, self.ic, self.isv = 3 * i, 3 * i + 1, 3 * i + 2
        self.diff_rows = np.sort(np.concatenate([self.ic, self.isv]))
        self.db = np.zeros(self.n)                      # ∂(BC rows)/∂U [1/V]
        self.db[0] = -0.5 / prm.V_T
        self.db[3 * (self.N - 1)] = 0.5 / prm.V_T
        self.upper = self.x > 0                         # nodes of the upper half (x = 0 weighs 0)

    # --- state helpers ------------------------------------------------------------------
    def rest_state(self, S: int = 1) -> np.ndarray:
        y = np.zeros((S, self.n))
        y[:, 1::3] = 1.0
        return y

    def fluxes(self, y):
        """Scaled face fluxes: cation Ĵ = f/C⁻ and solvent Ĝ = (n⁺f − Ds ∂Cs/∂x)/C⁻ [m/s],
        shape (S, N−1), plus the Bernoulli factors for the Jacobian."""
        psi, c, s = y[:, 0::3], y[:, 1::3], y[:, 2::3]
        dpsi = psi[:, 1:] - psi[:, :-1]
        Bp, dBp = bernoulli(dpsi)
        Bm = Bp + dpsi                                  # B(−x) = B(x) + x
        dBm = dBp + 1.0                                 # d/dx B(−x) = B'(x) + 1
        Dd = self.prm.D / self.dx
        J = Dd * (Bp * c[:, :-1] - Bm * c[:, 1:])
        G = self.prm.n_solv * J - self.prm.D_solvent / self.dx * (s[:, 1:] - s[:, :-1])
        return J, G, (Bp, Bm, dBp, dBm, c)

    def rates(self, y):
        """(Time derivative of the balance rows, zeros on the Poisson rows, (S, 3N) [1/s]; the
        cation fluxes Ĵ, (S, N−1) [m/s])."""
        J, G, _ = self.fluxes(y)
        f = np.zeros_like(y)
        f[:, 1::3] = -self._div(J)
        f[:, 2::3] = -self._div(G)
        return f, J

    def _div(self, F):
        out = np.zeros((F.shape[0], self.N), dtype=F.dtype)
        out[:, :-1] += F
        out[:, 1:] -= F
        return out / self.V

    def poisson(self, y, U):
        """Poisson/BC residual rows, (S, N)."""
        psi, c = y[:, 0::3], y[:, 1::3]
        gr = (psi[:, 1:] - psi[:, :-1]) / self.dx
        r = np.empty_like(psi)
        r[:, 1:-1] = self.lam2 * (gr[:, :-1] - gr[:, 1:]) / self.V[1:-1] - (c[:, 1:-1] - 1.0)
        u = np.asarray(U, dtype=float) / self.prm.V_T
        r[:, 0] = psi[:, 0] - 0.5 * u
        r[:, -1] = psi[:, -1] + 0.5 * u
        return r

    # --- Newton system ------------------------------------------------------------------
    def system(self, y, U, a, dh):
        """Residual R = [Poisson/BC; y − a − dh·f(y)] (S, 3N) and its banded Jacobian
        (LAPACK gbtrf layout, (S, 2KL+KU+1, 3N)).  ``dh`` may be complex (frequency domain)."""
        S = y.shape[0]
        J, G, (Bp, Bm, dBp, dBm, c) = self.fluxes(y)
        dtype = np.result_type(float, dh)
        R = np.zeros((S, self.n), dtype=dtype)
        R[:, 0::3] = self.poisson(y, U)
        R[:, 1::3] = y[:, 1::3] - a[:, 1::3] + dh * self._div(J)
        R[:, 2::3] = y[:, 2::3] - a[:, 2::3] + dh * self._div(G)
        ab = np.zeros((S, 2 * KL + KU + 1, self.n), dtype=dtype)

        def put(rows, cols, vals):
            ab[:, KL + KU + rows - cols, cols] += vals

        N, dx, V = self.N, self.dx, self.V
        i, j = np.arange(N - 1), np.arange(1, N)
        Dd = self.prm.D / dx
        g = Dd * (dBp * c[:, :-1] - dBm * c[:, 1:])                 # ∂J/∂(ψ_j − ψ_i)
        dJ = ((3 * i + 1, Dd * Bp), (3 * j + 1, -Dd * Bm), (3 * j, g), (3 * i, -g))
        n_s = self.prm.n_solv
        for col, v in dJ:
            put(3 * i + 1, col, dh * v / V[:-1])                    # row ĉ_i: + dh J/V_i
            put(3 * j + 1, col, -dh * v / V[1:])                    # row ĉ_j: − dh J/V_j
            put(3 * i + 2, col, dh * n_s * v / V[:-1])
            put(3 * j + 2, col, -dh * n_s * v / V[1:])
        Ds = self.prm.D_solvent / dx
        put(3 * i + 2, 3 * i + 2, dh * Ds / V[:-1])
        put(3 * i + 2, 3 * j + 2, -dh * Ds / V[:-1])
        put(3 * j + 2, 3 * i + 2, -dh * Ds / V[1:])
        put(3 * j + 2, 3 * j + 2, dh * Ds / V[1:])
        put(self.ic, self.ic, 1.0)
        put(self.isv, self.isv, 1.0)
        k = np.arange(1, N - 1)
        w = self.lam2 / V[k]
        put(3 * k, 3 * k, w * (1.0 / dx[k - 1] + 1.0 / dx[k]))
        put(3 * k, 3 * (k - 1), -w / dx[k - 1])
        put(3 * k, 3 * (k + 1), -w / dx[k])
        put(3 * k, 3 * k + 1, -1.0)
        put(np.array([0, 3 * (N - 1)]), np.array([0, 3 * (N - 1)]), 1.0)
        return R, ab, J

    # --- outputs --------------------------------------------------------------------------
    def current_density(self, J, U):
        """Input current density [A/m²]: ionic part zF⟨f⟩ = dQ_ion/dt (the flux averaged over
        the thickness equals the rate of the first moment of the cation excess / 2h) plus the
        electronic leakage σU/(2h).  The displacement current of the geometric capacitance
        κe/(2h) (a fraction λ/h ≈ 3e-6 of the double layer's) is left out, as in the reduced model."""
        p = self.prm
        return p.z * FARADAY * p.C_anion * (J @ self.dx) / (2.0 * p.h) + p.G_leak * np.asarray(U)

    def current_gradient(self, J, aux):
        """∂(current density)/∂y, (S, 3N) [A/m² per unit of the scaled unknowns]."""
        Bp, Bm, dBp, dBm, c = aux
        p = self.prm
        k = p.z * FARADAY * p.C_anion / (2.0 * p.h) * p.D
        out = np.zeros((c.shape[0], self.n))
        g = k * (dBp * c[:, :-1] - dBm * c[:, 1:])
        out[:, 3:-2:3] += g
        out[:, 0:-3:3] -= g
        out[:, 1:-3:3] += k * Bp
        out[:, 4::3] -= k * Bm
        return out

    def outputs(self, y, U, J=None):
        """Per-slice physical outputs of a state: dict of (S,) arrays.

        Q: ionic electrode charge per area zF∫x ΔC⁺ dx/(2h) [C/m²]; j: current density [A/m²];
        c_up, c_low: interface cation excess C⁺(±h) − C⁻ [mol/m³]; m_up, m_low: first moments of
        the solvent excess of the upper and lower halves, ∫₀ʰ x ΔCs dx and ∫₋ₕ⁰ (−x) ΔCs dx [mol/m];
        m_cat: ∫ x ΔC⁺ dx [mol/m].  ``J``: the state's cation fluxes (default: evaluated)."""
        p = self.prm
        J = self.fluxes(y)[0] if J is None else J
        c, s = y[:, 1::3], y[:, 2::3]
        xv = self.x * self.V
        m_cat = p.C_anion * ((c - 1.0) @ xv)
        ms = p.C_anion * s * xv
        return {"Q": p.z * FARADAY * m_cat / (2.0 * p.h), "j": self.current_density(J, U),
                "c_up": p.C_anion * (c[:, -1] - 1.0), "c_low": p.C_anion * (c[:, 0] - 1.0),
                "m_up": ms[:, self.upper].sum(axis=1), "m_low": -ms[:, ~self.upper].sum(axis=1),
                "m_cat": m_cat, "U": np.asarray(U, dtype=float) * np.ones(y.shape[0])}

    def totals(self, y):
        """(∫C⁺ dx [mol/m²], ∫Cs dx [mol/m²]) per slice."""
        p = self.prm
        return p.C_anion * (y[:, 1::3] @ self.V), p.C_anion * (y[:, 2::3] @ self.V) + p.C_solvent0 * self.V.sum()

    # --- small signal ------------------------------------------------------------------------
    def small_signal(self, s):
        """Linearised response about the rest state (U = 0) per volt at complex frequencies
        ``s`` [rad/s]: dict of arrays Q (ionic charge/area), j (current density incl. leakage),
        c_up (interface cation excess), m_up (upper solvent first moment), m_cat (∫x ΔC⁺ dx).
        Solves (s M − ∂F/∂y) δy = ∂F/∂U on the same discretisation as the time stepper."""
        y0 = self.rest_state()
        p = self.prm
        out = {k: np.empty(np.size(s), dtype=complex) for k in ("Q", "j", "c_up", "m_up", "m_cat")}
        xv = self.x * self.V
        for k, sk in enumerate(np.atleast_1d(s)):
            _, ab, _ = self.system(y0, 0.0, y0, 1.0 / sk)
            lu, piv, info = zgbtrf(ab[0], KL, KU)
            if info != 0:
                raise ModelError(f"singular linearised system at s = {sk}")
            dy, _ = zgbtrs(lu, KL, KU, -self.db.astype(complex), piv)
            m_cat = p.C_anion * (dy[1::3] @ xv)
            out["m_cat"][k] = m_cat
            out["Q"][k] = p.z * FARADAY * m_cat / (2.0 * p.h)
            out["j"][k] = sk * out["Q"][k] + p.G_leak
            out["c_up"][k] = p.C_anion * dy[-2]
            out["m_up"][k] = p.C_anion * (dy[2::3] * xv)[self.upper].sum()
        return out


@dataclass
class Ladder:
    """Slices coupled by the electrode resistance: slice 0 (the clamped part) sits at Vin;
    ``g[k]`` [S] links node k to node k+1 (g[0]: clamp → first free slice); ``area`` [m²]."""

    g: np.ndarray
    area: np.ndarray


@dataclass
class Tolerances:
    rtol: float = 1e-4          # relative local error per step
    atol: float = 1e-4          # absolute local error of ĉ and ŝ (units of C⁻)
    h_max: float = np.inf       # largest step [s]
    h_restart: float = 1e-6     # step after a kink of the input [s]
    newton_tol: float = 1e-3    # Newton increment, relative to the error weights
    input_tol: float = 1e-5     # largest error of a quadratic through Vin over one step, relative to max|Vin|
    max_newton: int = 10


class Integrator:
    """TR-BDF2 integration of a :class:`Slab` of S slices, driven by Vin(t) (piecewise linear
    between the samples of the record) either directly (every slice at Vin) or through a
    :class:`Ladder`."""

    def __init__(self, slab: Slab, S: int = 1, ladder: Ladder | None = None, tol: Tolerances | None = None):
        self.slab, self.S, self.ladder = slab, S, ladder
        self.tol = tol or Tolerances()
        if ladder is not None and (ladder.g.size != S - 1 or ladder.area.size != S):
            raise InputError("ladder: need S−1 link conductances and S areas")
        self.stats = {"steps": 0, "rejected": 0, "newton_iterations": 0, "newton_failures": 0}

    # --- linear algebra ---------------------------------------------------------------------
    def _factor(self, ab):
        lus = []
        for k in range(self.S):
            lu, piv, info = dgbtrf(ab[k], KL, KU)
            if info != 0:
                return None
            lus.append((lu, piv))
        return lus

    def _solve(self, lus, rhs, rhs_K=None, grad=None):
        """Solve the stage's linear system.  Without a ladder the slices are independent; with
        one, the node voltages δU (slices 1..S−1) follow from the tridiagonal Schur complement
        of Kirchhoff's law: returns (δy, δU)."""
        dy = np.empty_like(rhs)
        if self.ladder is None:
            for k, (lu, piv) in enumerate(lus):
                dy[k] = dgbtrs(lu, KL, KU, rhs[k], piv)[0]
            return dy, np.zeros(self.S)
        wv = np.empty_like(rhs)
        for k, (lu, piv) in enumerate(lus):
            dy[k] = dgbtrs(lu, KL, KU, rhs[k], piv)[0]
            wv[k] = dgbtrs(lu, KL, KU, -self.slab.db, piv)[0] if k else 0.0
        g, A = self.ladder.g, self.ladder.area
        alpha = np.einsum("kn,kn->k", grad, dy)
        beta = np.einsum("kn,kn->k", grad, wv) + self.slab.prm.G_leak
        gl = g                                    # link to the previous node (k−1 → k)
        gr = np.append(g[1:], 0.0)                # link to the next node
        m = self.S - 1
        band = np.zeros((3, m))
        band[1] = -gl - gr - A[1:] * beta[1:]
        band[0, 1:] = gr[:-1]
        band[2, :-1] = gr[:-1]
        dU = np.zeros(self.S)
        dU[1:] = solve_banded((1, 1), band, rhs_K + A[1:] * alpha[1:])
        dy += wv * dU[:, None]
        return dy, dU

    def _kirchhoff(self, j, U, vin):
        """K_k = g_{k−1,k}(U_{k−1} − U_k) − g_{k,k+1}(U_k − U_{k+1}) − A_k j_k, k = 1..S−1."""
        g, A = self.ladder.g, self.ladder.area
        Un = np.append(U[1:], 0.0)
        gr = np.append(g[1:], 0.0)
        Uprev = np.concatenate([[vin], U[1:-1]])
        return g * (Uprev - U[1:]) - gr * (U[1:] - Un[1:]) - A[1:] * j[1:]

    def _newton(self, y, U, a, dh, vin):
        tol = self.tol
        U = U.copy()
        if self.ladder is None:
            U[:] = vin
        else:
            U[0] = vin
        for _ in range(tol.max_newton):
            R, ab, J = self.slab.system(y, U, a, dh)
            lus = self._factor(ab)
            if lus is None or not np.all(np.isfinite(R)):
                return None
            if self.ladder is None:
                dy, dU = self._solve(lus, -R)
            else:
                _, _, aux = self.slab.fluxes(y)
                grad = self.slab.current_gradient(J, aux)
                j = self.slab.current_density(J, U)
                dy, dU = self._solve(lus, -R, -self._kirchhoff(j, U, vin), grad)
            y = y + dy
            U = U + dU
            self.stats["newton_iterations"] += 1
            if not np.all(np.isfinite(y)):
                return None
            if self._norm(dy, y, psi=True) <= tol.newton_tol:
                return y, U, lus
        return None

    def _weights(self, y):
        return self.tol.atol + self.tol.rtol * np.abs(y)

    def _norm(self, e, y, psi=False):
        w = self._weights(y)
        if psi:
            w[:, 0::3] = 1e-3 * self.tol.atol + self.tol.rtol * np.abs(y[:, 0::3])
            return float(np.max(np.abs(e) / w))
        r = self.slab.diff_rows
        return float(np.max(np.abs(e[:, r]) / w[:, r]))

    def _conservative(self, y):
        """Restore the cation and solvent totals of the record's start exactly (to round-off):
        ĉ is scaled by (1 + ε), ŝ shifted uniformly, with ε and the shift of the order of the
        linear solver's round-off.  The conservative form already conserves them up to that
        round-off, which grows with h·D/Δx² (~1e15 at the largest steps near the faces); the
        projection keeps it from accumulating without disturbing the Boltzmann layers.  Returns
        the state, its rates f and cation fluxes J (those of the Newton state, consistent with
        its potential: re-evaluating them after the projection would amplify it by the double
        layer's stiffness K = D/λ² ≈ 1e10 1/s)."""
        f, J = self.slab.rates(y)
        y = y.copy()
        V = self.slab.V
        y[:, 1::3] *= (self._tc / (y[:, 1::3] @ V))[:, None]
        y[:, 2::3] += ((self._ts - y[:, 2::3] @ V) / V.sum())[:, None]
        return y, f, J

    def _input_step(self, vin, t, h, v_scale):
        """Shrink ``h`` until Vin is resolved by the quadratic through the stage times (the
        double layer follows Vin quasi-statically, so outputs interpolated between the stage
        times are then as accurate as the input's representation)."""
        sig = np.array([0.15, 0.4, 0.7, 0.85])
        l0 = (sig - _GAMMA) * (sig - 1.0) / _GAMMA
        lg = sig * (sig - 1.0) / (_GAMMA * (_GAMMA - 1.0))
        l1 = sig * (sig - _GAMMA) / (1.0 - _GAMMA)
        for _ in range(60):
            v0, vg, v1 = vin(t), vin(t + _GAMMA * h), vin(t + h)
            vs = np.array([vin(t + x * h) for x in sig])
            if np.max(np.abs(vs - (v0 * l0 + vg * lg + v1 * l1))) <= self.tol.input_tol * v_scale:
                break
            h *= 0.5
        return h

    # --- driver -----------------------------------------------------------------------------
    def equilibrium(self, U0: float):
        """(state, node voltages) in equilibrium with a constant Vin = U0: the cations in
        Poisson–Boltzmann equilibrium, the solvent uniform at Cs0 (its equilibrium for
        blocking faces).  Found by integrating a ramp to U0 with the solvent frozen."""
        slab = self.slab
        y = slab.rest_state(self.S)
        if U0 == 0.0:
            return y, np.zeros(self.S)
        frozen = Slab(replace(slab.prm, n_solv=0.0, D_solvent=0.0), slab.x)
        aux = Integrator(frozen, self.S, self.ladder, replace(self.tol, h_max=np.inf))
        tau = slab.prm.lam * slab.prm.h / slab.prm.D        # double-layer charging time
        _, _, (y, U) = aux.run(np.array([0.0, 10 * tau, 1e3]), np.array([0.0, U0, U0]),
                               y0=(y, np.zeros(self.S)))
        return y, U

    def run(self, t_in, v_in, y0=None, snapshots=(), progress=None):
        """Integrate over the record (``t_in`` [s] increasing, ``v_in`` [V], linear between
        samples), from ``y0`` = (state, node voltages) or the equilibrium at ``v_in[0]``.
        Returns (outputs at ``t_in``: dict of (S, N) arrays, plus ``current`` [A] when a ladder
        is given; snapshots: list of (t, state, node voltages); final (state, node voltages))."""
        t_in, v_in = np.asarray(t_in, dtype=float), np.asarray(v_in, dtype=float)
        slab, S, tol, keys = self.slab, self.S, self.tol, _OUTPUTS
        y, U, out = self._start(t_in, v_in, y0)
        kinks, stops, snaps = _stops(t_in, v_in, snapshots)
        shots = []
        vin = lambda tt: float(np.interp(tt, t_in, v_in))  # noqa: E731
        t = float(t_in[0])
        v_scale = max(float(np.max(np.abs(v_in))), 1e-12)
        f, Jn = slab.rates(y)
        h, i_out, y_prev, h_last = tol.h_restart, 1, None, None
        while t < t_in[-1] - 1e-12 * max(1.0, abs(t_in[-1])):
            stop = stops[np.searchsorted(stops, t + 1e-12 * max(1.0, abs(t)), side="right")]
            h = min(h, tol.h_max, stop - t)
            if stop - t - h < 1e-3 * h:
                h = stop - t
            h = self._input_step(vin, t, h, v_scale)
            # stage 1: trapezoidal rule to t + γh
            a1 = y + _D * h * f
            guess = y if y_prev is None else y + _GAMMA * h / h_last * (y - y_prev)
            r1 = self._newton(guess, U, a1, _D * h, vin(t + _GAMMA * h))
            r2 = None
            if r1 is not None:
                yg, Ug, _ = r1
                yg, fg, Jg = self._conservative(yg)
                # stage 2: BDF2 through t, t + γh, t + h
                a2 = (yg - (1.0 - _GAMMA) ** 2 * y) / (_GAMMA * (2.0 - _GAMMA))
                guess = y + (yg - y) / _GAMMA
                r2 = self._newton(guess, Ug, a2, _D * h, vin(t + h))
            if r2 is None:
                self.stats["newton_failures"] += 1
                h *= 0.25
                if h < 1e-14 * max(1.0, abs(t)):
                    raise ModelError(f"reference solver: Newton fails at t = {t:g} s even with tiny steps")
                continue
            y1, U1, lus = r2
            y1, f1, J1 = self._conservative(y1)
            est = h * (_E[0] * f + _E[1] * fg + _E[2] * f1)
            if self.ladder is None:
                est, _ = self._solve(lus, est)
            else:
                J, _, aux = slab.fluxes(y1)
                est, _ = self._solve(lus, est, np.zeros(S - 1), slab.current_gradient(J, aux))
            err = self._norm(est, y1)
            if err > 1.0:
                self.stats["rejected"] += 1
                h *= max(0.2, 0.9 * err ** (-1.0 / 3.0))
                continue
            # accepted: outputs at the sample times inside (t, t + h], quadratic in time
            t1 = t + h
            i_end = np.searchsorted(t_in, t1 + 1e-9 * h, side="right")
            if i_end > i_out:
                og, o1 = slab.outputs(yg, Ug, Jg), slab.outputs(y1, U1, J1)
                sig = (t_in[i_out:i_end] - t) / h
                l0 = (sig - _GAMMA) * (sig - 1.0) / _GAMMA
                lg = sig * (sig - 1.0) / (_GAMMA * (_GAMMA - 1.0))
                l1 = sig * (sig - _GAMMA) / (1.0 - _GAMMA)
                on = slab.outputs(y, U, Jn)
                for k in keys:
                    out[k][:, i_out:i_end] = (np.outer(on[k], l0) + np.outer(og[k], lg) + np.outer(o1[k], l1))
                i_out = i_end
            y_prev, h_last = y, h
            y, U, f, Jn, t = y1, U1, f1, J1, t1
            self.stats["steps"] += 1
            if progress is not None:
                progress(t)
            if any(abs(t - s_) <= 1e-9 * max(1.0, abs(s_)) for s_ in snaps):
                shots.append((t, y.copy(), U.copy()))
            h *= min(5.0, 0.9 * max(err, 1e-10) ** (-1.0 / 3.0))
            if np.any(np.abs(kinks - t) <= 1e-12 * max(1.0, abs(t))):
                h = min(h, tol.h_restart)
                y_prev = None
        if self.ladder is not None:
            out["current"] = self.ladder.area[0] * out["j"][0] + self.ladder.g[0] * (v_in - out["U"][1])
        return out, shots, (y, U)

    def _start(self, t_in, v_in, y0):
        """(state, node voltages) at ``t_in[0]`` (``y0`` or the equilibrium at ``v_in[0]``),
        and the output arrays, (S, N) each, their first column filled; sets the totals that
        :meth:`_conservative` keeps."""
        if y0 is None:
            y, U = self.equilibrium(float(v_in[0]))
        else:
            y, U = np.array(y0[0], dtype=float), np.array(y0[1], dtype=float)
        out = {k: np.empty((self.S, t_in.size)) for k in _OUTPUTS}
        o0 = self.slab.outputs(y, U)
        for k in _OUTPUTS:
            out[k][:, 0] = o0[k]
        self._tc, self._ts = y[:, 1::3] @ self.slab.V, y[:, 2::3] @ self.slab.V
        return y, U, out


def _stops(t_in, v_in, snapshots):
    """(kinks of the input, times a step must end at: kinks, snapshots and the end of the
    record, the snapshot times as a set)."""
    kinks = _kinks(t_in, v_in)
    stops = np.unique(np.concatenate([kinks, np.asarray(snapshots, dtype=float), t_in[-1:]]))
    return kinks, stops, set(np.asarray(snapshots, dtype=float).tolist())


def _kinks(t, v, rel: float = 1e-3) -> np.ndarray:
    """Sample times where the piecewise-linear input bends noticeably (steps land on them)."""
    if t.size < 3:
        return np.zeros(0)
    scale = max(float(np.max(np.abs(v))), 1e-12)
    d2 = np.abs(np.diff(v, 2))
    return t[1:-1][d2 > rel * scale]

