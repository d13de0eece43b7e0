"""``nonlinear_charge``: the large-signal double layer.

The linearisation of ``double_layer`` holds for |U| ≪ V_T = RT/F ≈ 26 mV, far below the
thesis's 4 Vpp.  Following Porfiri (J. Appl. Phys. 104, 104915, 2008) the nonlinear PNP
system is reduced to the bulk resistance in series with a nonlinear capacitor: the two
diffuse layers in equilibrium (Poisson–Boltzmann), sharing the electrode charge Q.
With fixed anions C⁻ and one mobile cation, in the dimensionless potential x = zFψ/RT,
the cation concentration is C⁺ = C⁻ e^{−x} / (1 − ν + ν e^{−x}), ν = C⁻/C_max (Bikerman
lattice-gas steric limit C_max; ν = 0 is the plain PNP of the thesis), and the first
integral of Poisson's equation gives the diffuse charge

    q(x) = sign(x) sqrt(2 κe R T C⁻ G(x)),   G(x) = x + ln(1 − ν + ν e^{−x}) / ν.

The cathode (accumulation, x < 0) stores charge easily; the anode (depletion, x > 0) needs
q ≈ sqrt(2 κe F C⁻ ψ): the capacitance falls with voltage, the charge saturates, and the
interface concentrations are asymmetric (depletion bounded by −C⁻, accumulation by
C_max − C⁻).  The bending load follows the first moment of the solvent excess through
the thickness: for layers much thinner than h it is (moved charge Q) × lever arm, so the
load is the linear model's first-moment-equivalent interface excess (c0/C0)·Q with the
large-signal Q(U) — not the face concentration, which for plain Poisson–Boltzmann layers
stays exactly linear in U (checked against the full PNP reference: deflection within
0.05 % up to 2 V with C_max = ∞).  Small-signal limit: capacitance κe sqrt(1−ν)/(2λ)
(equal to ``double_layer`` when C_max → ∞).  The default
C_max ≈ 5000 mol/m³ corresponds to a ≈ 0.7 nm solvated cation (Kilic, Bazant & Ajdari,
Phys. Rev. E 75, 021502, 2007), the scale of the thesis's Fig. 13/30 cation peaks.

**Compact (Stern) layers.**  Bare Poisson–Boltzmann layers compress at a few tenths of a
volt, while strips saturate at volts: between the electrode and each diffuse layer sits a
charge-free compact layer in series (Bazant, Thornton & Ajdari, Phys. Rev. E 70, 021506,
2004, §II C), which takes part of the voltage.  The device's double-layer capacitance is
taken as the measured total: ``diffuse_share`` d is the share of the small-signal voltage
across the diffuse layers, the compact layers take 1 − d, and the diffuse layers behind them
are correspondingly denser (capacitance C0/d), so

    U(Q) = (1 − d) Q/C0 + U_PB(d Q),

with the same small-signal capacitance C0 for every d (the electrode line, the RC corner and
every linear fit unchanged) and the onset of saturation moved from U_PB's to d^(−3/2) times
it (the pair's law is odd in Q, so its first departure from the line is cubic,
U_PB(q) ≈ q/C0 + a q³, and a d³Q³ reaches a given share of Q/C0 at Q ∝ d^(−3/2)).  d = 1 (the
default) is the plain law above; d → 0 the linear law.
Off: the linear law Q = C0 U (time domain) and the exact linear PNP (frequency domain).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import InputError, arg
from ..parameters import ParamSpec
from .base import Effect
from .double_layer import DoubleLayer, DoubleLayerProps


class LinearCharge(Effect):
    stage = "charge_law"
    reference = "reproduced"          # the reference solves the charge of its PNP slabs itself
    summary = "linear double layer at any amplitude"

    def small_signal(self, s, d: DoubleLayerProps, p):
        """(Q/U, load/U) small-signal functions used by the frequency solver; the load is the
        first-moment-equivalent interface cation excess [mol/m³] (= ΔC⁺(h) in the linear model)."""
        return DoubleLayer.charge_per_volt(s, d)

    def realized_charge(self, d: DoubleLayerProps, p):
        """What the time solver's linear branch realises: None for the double layer's own charge
        (:meth:`DoubleLayer.realize`), else (s -> (Q/U, load/U), lowest frequency it must hold to
        [rad/s]) for a law whose small-signal functions differ from it."""
        return None

    def nu(self, p) -> float:
        return 0.0

    def potential(self, Q, d: DoubleLayerProps, p):
        """Equilibrium voltage U_eq(Q) [V] of the two double layers, and the state needed by
        :meth:`slope` and :meth:`excess` (here nothing)."""
        return np.asarray(Q, dtype=float) / d.C0, None

    def slope(self, Q, d: DoubleLayerProps, p, state=None):
        """dU_eq/dQ [V m²/C]."""
        return np.broadcast_to(1.0 / d.C0, np.shape(Q)).astype(float)

    def excess(self, Q, d: DoubleLayerProps, p, state=None):
        """Interface cation excess at the upper and lower faces [mol/m³]."""
        c = d.c0 / d.C0 * np.asarray(Q, dtype=float)
        return c, -c

    def equilibrium(self, Q, d: DoubleLayerProps, p):
        """Branch law for the time stepper: (U_eq(Q) [V], dU_eq/dQ [V m²/C],
        interface excess at the upper and lower faces [mol/m³])."""
        U, st = self.potential(Q, d, p)
        return (U, self.slope(Q, d, p, st)) + tuple(self.excess(Q, d, p, st))

    def compiled(self, d: DoubleLayerProps, p) -> "_LinearLaw":
        """The law with its constants evaluated once (for the stepper's inner loop)."""
        return _LinearLaw(1.0 / d.C0, d.c0 / d.C0)


class NonlinearCharge(LinearCharge):
    id = "nonlinear_charge"
    linear = False
    reference = "unsupported"
    reference_note = "the reference solver is the full nonlinear PNP itself"
    reference_limit = {"C_max": np.inf, "diffuse_share": 1.0}   # plain Poisson–Boltzmann layers, as in the reference
    summary = "large-signal double layer: voltage-dependent capacitance, asymmetric/saturating charge"
    explanation = __doc__
    params = (ParamSpec("C_max", "mol/m^3", 1.0, np.inf,
                        "steric maximum cation concentration (.inf: plain Poisson–Boltzmann)", optional=True,
                        default=5000.0),
              ParamSpec("diffuse_share", "1", 1e-3, 1.0,
                        "share of the small-signal voltage across the diffuse layers (1: no compact layer)",
                        optional=True, default=1.0))
    # the saturation voltage through the compact layers: diffuse_share from 1/30 to 1 (fitted where
    # the describing function shows it matters); C_max held at the device value
    diagnosis = {
        "free": ("diffuse_share",), "bounds": {"diffuse_share": (1 / 30, 1.0)},
        "starts": [{"diffuse_share": 0.6}, {"diffuse_share": 0.25}, {"diffuse_share": 0.08}],
        "nested": False, "describing_function": True,
        "excitation": "the same excitation at two or more amplitudes (ratio at least 1.25) at one RH level",
        "reveal": {"amplitude_levels": 2},
        "signature": [("amplitude_dependence", 1.0), ("harmonics", 0.5)],
        # a charge that grows slower than the voltage shows as a saturation of the drive
        "shows_as": ("input_saturation",),
    }

    @classmethod
    def draw_truth(cls, device, rng):
        """A hidden truth for test beds and demos: C_max log-uniform 1500–8000 mol/m³."""
        c = float(np.exp(rng.uniform(np.log(1500.0), np.log(8000.0))))
        return device.with_params(C_max=c), {"C_max": c}

    #: Identification hints: why a parameter may have no effect ({name: sentence}).
    hints = {"C_max": "C_max acts only in the large-signal (time-domain) response of nonlinear_charge"}
    #: Grid of 1/diffuse_share on which the describing function is tabulated: from 1 (no compact
    #: layer, the diffuse layers compress at a few tenths of a volt) to 30 (onset ~160× later).
    SHARE_GRID = (1.0, 1.3, 1.7, 2.2, 3.0, 4.0, 5.5, 7.5, 10.0, 14.0, 20.0, 30.0)

    @classmethod
    def describing_grid(cls, device) -> tuple[str, tuple[float, ...], float]:
        """The describing-function hook (:mod:`physics.diagnose.describing`): (the large-signal
        parameter, its grid of coordinates c, scale) with c = scale/parameter = 1/diffuse_share."""
        return "diffuse_share", cls.SHARE_GRID, 1.0

    def nu(self, p) -> float:
        """ν = C⁻/C_max, the lattice's share taken by the fixed anions; below 1 for any law."""
        nu = float(p["C_anion"] / p.get("C_max", np.inf))
        if not nu < 1.0:
            raise InputError(f"C_max = {p.get('C_max'):.4g} mol/m^3 of nonlinear_charge is not above the fixed-anion "
                             f"concentration C_anion = {p['C_anion']:.4g} mol/m^3 (the lattice must hold the anions); "
                             f"raise C_max in the device file, or the low end of its search range where it is fitted "
                             f"({arg('bounds')})")
        return nu

    @staticmethod
    def share(p) -> float:
        """d, the diffuse layers' share of the small-signal voltage (module doc)."""
        return float(p.get("diffuse_share", 1.0))

    def _compact(self, d: DoubleLayerProps, p):
        """(1 − d)/C0 [V m²/C]: the compact layers' part of dU/dQ, C0 the small-signal capacitance."""
        return (1.0 - self.share(p)) / (d.C0 * np.sqrt(1.0 - self.nu(p)))

    def small_signal(self, s, d: DoubleLayerProps, p):
        nu = self.nu(p)
        C0 = d.C0 * np.sqrt(1.0 - nu)
        tau = d.R_bulk * C0
        q = C0 / (1.0 + np.asarray(s, dtype=complex) * tau)
        return q, q * d.c0 / d.C0

    def _scale(self, d: DoubleLayerProps) -> np.ndarray:
        return np.sqrt(2.0 * d.kappa * d.V_T * d.z * 96485.33212 * d.C_anion)  # sqrt(2 κe R T C⁻)

    def potential(self, Q, d: DoubleLayerProps, p):
        """U_eq(Q) and the dimensionless interface potentials (x_up, x_low): the upper face is
        the cathode for Q > 0 (accumulation, x < 0), the lower face the anode (x > 0)."""
        tab = _pb_table(round(self.nu(p), 12))
        qh = self.share(p) * np.asarray(Q, dtype=float) / self._scale(d)
        x = np.interp(np.concatenate([-qh, qh]), tab.q, tab.x)
        x_up, x_low = x[:qh.size].reshape(qh.shape), x[qh.size:].reshape(qh.shape)
        return d.V_T * (x_low - x_up) + self._compact(d, p) * np.asarray(Q, dtype=float), (x_up, x_low)

    def slope(self, Q, d: DoubleLayerProps, p, state=None):
        tab = _pb_table(round(self.nu(p), 12))
        scale = self._scale(d) / self.share(p)
        qh = np.asarray(Q, dtype=float) / scale
        g = np.interp(np.concatenate([-qh, qh]), tab.q, tab.dxdq)
        return d.V_T / scale * (g[:qh.size] + g[qh.size:]).reshape(qh.shape) + self._compact(d, p)

    def excess(self, Q, d: DoubleLayerProps, p, state=None):
        x_up, x_low = self.potential(Q, d, p)[1] if state is None else state
        nu = self.nu(p)
        return d.C_anion * _excess_ratio(x_up, nu), d.C_anion * _excess_ratio(x_low, nu)

    def compiled(self, d: DoubleLayerProps, p) -> "_PBLaw":
        return _PBLaw(round(self.nu(p), 12), d.V_T, self._scale(d) / self.share(p), d.C_anion, self._compact(d, p))


class _LinearLaw:
    """U_eq = Q/C0 with precomputed constants (the stepper's inner loop)."""

    def __init__(self, inv_c0, ratio):
        self.inv_c0, self.ratio = inv_c0, ratio

    def evaluate(self, Q):
        """(U_eq [V], dU_eq/dQ [V m²/C]) at the charge per area Q [C/m²] of each branch."""
        return Q * self.inv_c0, np.broadcast_to(self.inv_c0, Q.shape)

    def excess(self, Q):
        """Cation excess at the upper and lower faces [mol/m³]; Q is (..., branches)."""
        c = self.ratio * Q
        return c, -c


class _PBLaw:
    """Poisson–Boltzmann law with the table and scales bound (arrays per branch allowed)."""

    def __init__(self, nu, V_T, scale, C_anion, compact=0.0):
        self.nu, self.V_T, self.inv_scale, self.C = nu, V_T, 1.0 / scale, C_anion
        self.slope_scale = V_T / scale
        self.compact = compact                   # the compact layers' part of dU/dQ [V m²/C]
        branch = _pb_branch_table(nu)
        self.tq, self.tug = branch.q, branch.ug

    def evaluate(self, Q):
        """(U_eq [V], dU_eq/dQ [V m²/C]): one complex interpolation in the branch table, plus
        the compact layers' linear drop."""
        ug = np.interp(Q * self.inv_scale, self.tq, self.tug)
        return self.V_T * ug.real + self.compact * Q, self.slope_scale * ug.imag + self.compact

    def excess(self, Q):
        """Cation excess at the upper (cathode for Q > 0) and lower faces [mol/m³]; Q is
        (..., branches)."""
        tab = _pb_table(self.nu)
        qh = Q * self.inv_scale
        x_up, x_low = np.interp(-qh, tab.q, tab.x), np.interp(qh, tab.q, tab.x)
        return self.C * _excess_ratio(x_up, self.nu), self.C * _excess_ratio(x_low, self.nu)


def _excess_ratio(x, nu):
    """ΔC⁺/C⁻ = e^{−x}/(1 − ν + ν e^{−x}) − 1, evaluated without overflow."""
    x = np.asarray(x, dtype=float)
    if nu <= 0.0:
        return np.expm1(-x)
    log_c = -x - np.logaddexp(np.log1p(-nu), np.log(nu) - x)
    return np.expm1(log_c)


class _Table:
    def __init__(self, q, x=None, dxdq=None, ug=None):
        self.q, self.x, self.dxdq, self.ug = q, x, dxdq, ug


@lru_cache(maxsize=16)
def _pb_table(nu: float) -> _Table:
    """Dimensionless charge–potential relation q̂(x) = sign(x) sqrt(G(x)) and dx/dq̂."""
    x = np.sinh(np.linspace(-np.arcsinh(200.0 / 0.05), np.arcsinh(200.0 / 0.05), 40001)) * 0.05
    if nu <= 0.0:
        G = x + np.expm1(-x)
        Gp = -np.expm1(-x)
    else:
        G = x + np.logaddexp(np.log1p(-nu), np.log(nu) - x) / nu
        Gp = -_excess_ratio(x, nu)
    G = np.maximum(G, 0.0)
    q = np.sign(x) * np.sqrt(G)
    with np.errstate(divide="ignore", invalid="ignore"):
        dxdq = np.where(np.abs(x) > 1e-6, 2.0 * np.abs(q) / np.abs(Gp), np.sqrt(2.0 / (1.0 - nu)))
    return _Table(q, x=x, dxdq=dxdq)


@lru_cache(maxsize=16)
def _pb_branch_table(nu: float) -> _Table:
    """The branch law on its own grid: U_eq/V_T = x(q̂) − x(−q̂) (real part) and its slope
    dx/dq̂(q̂) + dx/dq̂(−q̂) (imaginary part).  The grid joins ±q̂ of :func:`_pb_table`, so the
    piecewise-linear interpolant equals the difference of the two face interpolants exactly."""
    tab = _pb_table(nu)
    q = np.union1d(tab.q, -tab.q)
    u = np.interp(q, tab.q, tab.x) - np.interp(-q, tab.q, tab.x)
    g = np.interp(q, tab.q, tab.dxdq) + np.interp(-q, tab.q, tab.dxdq)
    return _Table(q, ug=u + 1j * g)
