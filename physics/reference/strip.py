"""The reference strip: PNP + solvent slabs along the cantilever, the reduced model's beam.

Along the strip (z from the clamp, free length L) the polymer is cut into slices, each a full
through-thickness solve of :mod:`physics.reference.pnp`: slice 0 is the clamped part (area
w·L_clamp, at Vin, it does not bend), slices 1..n the free segments.  When the model's line
stage has series conductances (electrode sheet resistance: link conductance w/(2 Rs Δz)
between consecutive slice centres), the slices hang on that resistive ladder of the two
electrodes, so the voltage across the polymer falls along the strip; otherwise every slice
sees Vin and one free slice stands for all.  The solvent diffuses back with the solvent
stage's ``solvent_diffusivity``.  Which effects the reference supports each effect says itself
(``reference``: :data:`physics.effects.REFERENCE`); the reference refuses the others.

Load (how the reference is compared with the reduced model).  The reference solves the
solvent (eq. 7) explicitly.  The strip bends with the first moment of the solvent excess
through the thickness, m_s = ∫ x (Cs − Cs0) dx [mol/m].  Its load in the reduced model's units
(interface cation excess [mol/m³], to which the reduced model applies n⁺·B(s)) is

    ℓ_ref = m_s / (n⁺ Λ),   Λ = 2(hλ coth(h/λ) − λ²)   (SlabParams.Lambda),

Λ being the linear (Debye–Hückel) ratio of the cation first moment to the antisymmetric
interface excess.  In the small-signal limit m_s = n⁺ B(s) ∫ x ΔC⁺ dx up to O(λ/h), hence
ℓ_ref = ℓ·B(s) of the reduced model; at large signal ℓ_ref follows the solvent actually
moved (∝ the charge), not the interface concentration.  ℓ_ref is pushed through the reduced
model's kf(s), humidity factors, modes and Prony modulus by
:func:`physics.solvers.timedomain.tip_from_interface_excess` (without the solvent factor, which the
reference contains).  Cs_up/Cs_low are reported as first-moment-equivalent interface values,
2∫₀ʰ x ΔCs dx/Λ and 2∫₋ₕ⁰ |x| ΔCs dx/Λ averaged over L_total (clamp included), as the
reduced model does.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..model import ActuatorModel, as_model
from ..solvers.discretisation import projection, segment_edges
from ..solvers.timedomain import _check_record, beam_statespace, tip_from_interface_excess
from .pnp import Integrator, Ladder, Slab, SlabParams, Tolerances, graded_mesh



@dataclass
class ReferenceResult:
    """Time series of the reference solver (SI units), sampled like the input record.

    deflection [m], current [A], cs_up/cs_low [mol/m³] (first-moment-equivalent, averaged over
    L_total), and per slice (row 0 = clamp, then the free segments at ``z`` [m]): charge Q
    [C/m²], interface cation excess c_up/c_low [mol/m³], load ℓ_ref [mol/m³], voltage U [V].
    ``profiles``: {time [s]: {"x" [m], "C+" [mol/m³], "Cs" [mol/m³], "phi" [V]}} of slice 0
    (the clamp region, at Vin) and of the first free slice.  ``conservation``: relative drift
    of ∫C⁺ and ∫Cs over the run.  ``stats``: steps, rejected, Newton iterations, wall time."""

    time: np.ndarray
    voltage: np.ndarray
    deflection: np.ndarray
    current: np.ndarray
    cs_up: np.ndarray
    cs_low: np.ndarray
    charge: np.ndarray
    c_up: np.ndarray
    c_low: np.ndarray
    load: np.ndarray
    U: np.ndarray
    z: np.ndarray
    profiles: dict = field(default_factory=dict)
    conservation: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


class ReferenceStrip:
    """Reference model of ``device``/``effects`` at ``rh`` [%] (parameters as the reduced model's).

    ``n_segments``: free slices when the electrode resistance is on (default 8, graded towards
    the clamp; 1 otherwise); ``mesh``: keyword arguments of :func:`graded_mesh`; ``T`` [K]: slab
    temperature (default T_ext; the mobility follows eq. 6); ``tol``: :class:`Tolerances`."""

    def __init__(self, device, effects=None, rh=None, *, n_modes: int = 4, n_segments: int | None = None,
                 mesh: dict | None = None, T: float | None = None, tol: Tolerances | None = None):
        self.model: ActuatorModel = as_model(device, effects, n_modes)
        bad = [e for e in self.model.effects if type(e).reference_support() == "unsupported"]
        if bad:
            raise InputError("the reference solver cannot run " + "; ".join(
                f"{e.label} ({type(e).reference_note or 'it does not declare reference support'})" for e in bad)
                + f": drop {'it' if len(bad) == 1 else 'them'} from its effects")
        self.rh = float(self.model.check_rh(rh))
        p = self.model.params_at(self.rh)
        self.p = p
        self.prm = SlabParams.from_params(p, T, D_solvent=self.model.hook("solvent_diffusivity")(p),
                                          props=self.model.double_layer_props)
        self.slab = Slab(self.prm, graded_mesh(self.prm.h, self.prm.lam, **(mesh or {})))
        L = self.model.free_length
        self.line = self.model.hook("series_conductances")(p, segment_edges(L, 2)) is not None
        n = (8 if n_segments is None else int(n_segments)) if self.line else 1
        self.edges = segment_edges(L, n, 1.5 if self.line else 1.0)
        self.area = p["width"] * np.concatenate([[p["L_clamp"]], np.diff(self.edges)])
        self.tol = tol or Tolerances()

    # --- small signal -----------------------------------------------------------------------
    def slab_response(self, s) -> dict:
        """Per-volt small-signal response of one slab at ``s`` [rad/s]: admittance per area Y
        [S/m²], ionic charge Q [C/m²], interface excess c_up [mol/m³], load ℓ_ref [mol/m³] and
        the solvent factor B_ref = m_s/(n⁺ ∫x ΔC⁺ dx)."""
        r = self.slab.small_signal(np.atleast_1d(s))
        n = self.prm.n_solv
        return {"Y": r["j"], "Q": r["Q"], "c_up": r["c_up"], "ell": 2.0 * r["m_up"] / (n * self.prm.Lambda),
                "B": 2.0 * r["m_up"] / (n * r["m_cat"])}

    def frequency_response(self, freqs, n_segments: int = 256) -> dict:
        """Small-signal reference FRF at ``freqs`` [Hz]: the linearised slab (same discretisation
        as the time stepper) on a ladder of ``n_segments`` free slices (when the electrode
        resistance is on), through kf(s) × the load factors, the reduced model's beam and its
        output effects.  Returns deflection [m/V], current [A/V] and cs_up [mol/m³/V] (complex
        arrays) and the slab response."""
        f = np.atleast_1d(np.asarray(freqs, dtype=float))
        s = 2j * np.pi * f
        slab = self.slab_response(s)
        m, p = self.model, dict(self.model.device.params)
        L = m.free_length
        edges = segment_edges(L, n_segments, 1.5) if self.line else self.edges
        area = p["width"] * np.diff(edges)
        U = _ladder(self._conductances(edges), area, slab["Y"]) if self.line else np.ones((s.size, 1), dtype=complex)
        kf = m.load_response(s, p, solvent=False) * float(m.hook("coupling_factor")(self.rh))   # kf(s) × load factors
        coef = 2.0 * 0.5 * p["t_polymer"] * p["width"] * p["n_solvation"]
        proj = projection(m.modes(), edges, coef)
        ell = slab["ell"][:, None] * U                                   # (n_s, n_seg)
        pre = np.hstack([ell @ proj.modal.T, (ell @ proj.residual)[:, None]])
        beam = beam_statespace(m, p, float(m.hook("stiffness_factor")(self.rh))).freqresp(s)[0]   # (inputs, n_s)
        tip = kf * np.einsum("ki,ik->k", pre, beam) * m.output_response(s, self.p)
        Lc, Lt = p["L_clamp"], p["L_total"]
        current = slab["Y"] * (p["width"] * Lc + U @ area)
        cs = p["n_solvation"] * slab["ell"] * (Lc + U @ np.diff(edges)) / Lt
        return {"freq": f, "deflection": tip, "current": current, "cs_up": cs, "slab": slab}

    def _conductances(self, edges) -> np.ndarray:
        """Links of the electrode ladder [S]: clamp → first slice centre, then centre to centre."""
        return self.model.hook("series_conductances")(self.p, edges)

    # --- time domain --------------------------------------------------------------------------
    def simulate(self, t, voltage, *, snapshots=(), progress=None) -> ReferenceResult:
        """Time response to the record (``t`` [s] uniformly sampled, ``voltage`` [V], linear
        between samples), from equilibrium with voltage[0]; ``snapshots``: times [s] at which
        the through-thickness profiles are stored."""
        t, v = _check_record(t, voltage)
        S = self.edges.size                       # clamp + free slices
        ladder = None
        if self.line:
            ladder = Ladder(g=self._conductances(self.edges), area=self.area)
        else:
            S = 1                                 # clamp and free part are identical, both at Vin
        integ = Integrator(self.slab, S, ladder, self.tol)
        y0 = integ.equilibrium(float(v[0]))
        tot0 = self.slab.totals(y0[0])
        wall = time.perf_counter()
        out, shots, (yN, _) = integ.run(t, v, y0=y0, snapshots=snapshots, progress=progress)
        wall = time.perf_counter() - wall
        if ladder is None:                        # the one slice stands for the clamp and the free part
            out = {k: np.repeat(a, 2, axis=0) for k, a in out.items()}
            shots = [(ts, np.repeat(y, 2, axis=0), U) for ts, y, U in shots]
        tot1 = self.slab.totals(yN)
        prm, p = self.prm, self.p
        if ladder is None:
            current = out["j"][0] * self.area.sum()
        else:
            current = out["current"]
        ell = (out["m_up"] - out["m_low"]) / (prm.n_solv * prm.Lambda)
        lengths = self.area / p["width"]
        cs_up = 2.0 * (lengths @ out["m_up"]) / prm.Lambda / p["L_total"]
        cs_low = 2.0 * (lengths @ out["m_low"]) / prm.Lambda / p["L_total"]
        tip = tip_from_interface_excess(self.model, t, ell[1:], self.edges, self.rh,
                                        apply_solvent_factor=False, hold="linear")
        profiles = {}
        for ts, y, U in shots:
            profiles[float(ts)] = {"x": self.slab.x.copy(), "C+": prm.C_anion * y[:, 1::3],
                                   "Cs": prm.C_solvent0 + prm.C_anion * y[:, 2::3],
                                   "phi": prm.V_T * y[:, 0::3]}
        cons = {"cation": float(np.max(np.abs(tot1[0] / tot0[0] - 1.0))),
                "solvent": float(np.max(np.abs(tot1[1] / tot0[1] - 1.0)))}
        stats = dict(integ.stats, wall_s=wall)
        return ReferenceResult(time=t, voltage=v, deflection=tip, current=current, cs_up=cs_up, cs_low=cs_low,
                               charge=out["Q"], c_up=out["c_up"], c_low=out["c_low"], load=ell, U=out["U"],
                               z=np.concatenate([[np.nan], 0.5 * (self.edges[1:] + self.edges[:-1])]),
                               profiles=profiles, conservation=cons, stats=stats)


def _ladder(g, area, Y) -> np.ndarray:
    """Per-volt slice voltages of the electrode ladder with link conductances ``g`` [S] for
    polymer admittances Y(s) per area, shape (len(Y), n_seg)."""
    from scipy.linalg import solve_banded
    n = area.size
    gr = np.append(g[1:], 0.0)
    out = np.empty((Y.size, n), dtype=complex)
    for k, y in enumerate(Y):
        band = np.zeros((3, n), dtype=complex)
        band[1] = g + gr + area * y
        band[0, 1:] = -gr[:-1]
        band[2, :-1] = -gr[:-1]
        rhs = np.zeros(n, dtype=complex)
        rhs[0] = g[0]
        out[k] = solve_banded((1, 1), band, rhs)
    return out
