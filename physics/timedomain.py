"""Time-domain solver: the same chain as :mod:`physics.frequency`, realised in time.

Stages (each small, so each is well conditioned):

1. electrochemistry along the strip (Vin → interface cation excess per segment, current):
   an LTI state space (double-layer branch realisation on the finite-volume ladder of
   the electrodes) simulated exactly, or — with ``nonlinear_charge``, ``thermal`` or
   RH-dependent electrochemistry — the implicit stepper of :mod:`physics.stepper`;
2. projection onto the beam: modal loads and the quasi-static residual (static matrix);
3. load filter: solvent factor B(s) × kf(s) as a real-pole realisation, then the
   humidity factor of kf sample by sample;
4. mechanics: modal cantilever with the Prony modulus and Rayleigh damping, plus the
   quasi-static residual, in blocks of constant RH when RH varies (state carried over).

The segment grid of the electrode line is refined until the discrete ladder reproduces
the closed-form transmission line to 0.2 % up to 100 Hz (or fs/4).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from . import lti
from .threads import single_threaded
from .errors import InputError, ModelError
from .lti import StateSpace
from .model import ActuatorModel, as_model
from .realize import fit_pole_residue
from .strip import projection, quadrature, segment_edges

FIELDS = {
    "voltage": "voltage across the polymer along the strip [V]",
    "charge": "electrode charge per area along the strip [C/m²]",
    "cation": "interface cation excess at the upper and lower faces along the strip [mol/m³]",
    "temperature": "temperature along the strip [K] (T_ext without the thermal effect)",
}

_W_LO = 2.0 * np.pi * 1e-5  # lowest frequency the realisations are accurate at [rad/s]


@dataclass
class SimulationResult:
    """Time series of a simulation (SI units).  ``fields`` hold (n_segments, N) arrays on
    the segment centres ``z`` [m] from the clamp; ``cation_upper``/``cation_lower`` (the
    cation excess at the faces) for the field ``cation``.  Cs_up/Cs_low: thesis eq. 8, the
    interface solvent excess averaged over the electrode length [mol/m³], as the
    first-moment-equivalent value that bends the strip (equal to the face value in the
    linear regime; with ``nonlinear_charge`` the face values are in the ``cation`` field)."""

    time: np.ndarray
    voltage: np.ndarray
    rh: np.ndarray
    deflection: np.ndarray
    current: np.ndarray
    cs_up: np.ndarray
    cs_low: np.ndarray
    device: str
    effects: tuple[str, ...]
    z: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fields: dict = field(default_factory=dict)

    @property
    def fs(self) -> float:
        return 1.0 / float(self.time[1] - self.time[0])

    def to_timeseries(self):
        """A :class:`physics.timeseries.TimeSeries` for writing in the common file format."""
        from .timeseries import TimeSeries
        temp = self.fields.get("temperature")
        meta = {"generator": "eap-model physics.simulate", "device": self.device, "effects": list(self.effects)}
        return TimeSeries(time=self.time, voltage=self.voltage, deflection=self.deflection, rh=self.rh,
                          current=self.current,
                          temperature=None if temp is None else temp.mean(axis=0) - 273.15, meta=meta)


@single_threaded
def simulate(device, effects=None, t=None, voltage=None, rh=None, *, fields=(), n_modes: int = 4,
             hold: str = "cubic", n_segments: int | None = None, periodic: bool = False,
             progress: bool = False) -> SimulationResult:
    """Simulate the tip deflection for a voltage record.

    ``device``: name, YAML path, Device or ActuatorModel; ``effects``: ids (see
    :func:`physics.model.resolve_effects`); ``t`` [s] uniformly sampled; ``voltage`` [V];
    ``rh`` [%] a constant or one value per sample (required when ``humidity`` is on);
    ``fields``: any of :data:`FIELDS`; ``hold``: input interpolation between samples
    (``cubic`` for smooth signals, ``linear`` for ones with jumps); ``periodic``: the record
    is one period of a periodic excitation and the response is the periodic steady state
    (no start-up transient; linear models at constant RH only).  Otherwise the device
    starts at rest in equilibrium with voltage[0].
    """
    model = as_model(device, effects, n_modes)
    t, v = _check_record(t, voltage)
    rh_t = model.check_rh(rh)
    rh_t = np.full(t.size, float(rh_t)) if np.ndim(rh_t) == 0 else np.asarray(rh_t, dtype=float)
    if rh_t.shape != t.shape:
        raise InputError(f"rh must be a constant or have one value per sample ({t.size}), got {rh_t.size}")
    unknown = set(fields) - set(FIELDS)
    if unknown:
        raise InputError(f"unknown field(s) {sorted(unknown)}; available: {', '.join(FIELDS)}")
    dt = float(t[1] - t[0])
    w_hi = np.pi / dt
    stepper_needed = (not model.is_linear) or (model.hook("electrochemistry_varies")() and np.ptp(rh_t) > 0)
    if periodic and (stepper_needed or (model.needs_rh and np.ptp(rh_t) > 0)):
        large = [e.label for e in model.effects if not type(e).linear]
        raise InputError("periodic steady state needs a linear model at constant RH "
                         f"({'/'.join(large) or 'a varying RH'} make{'s' if len(large) < 2 else ''} the response "
                         "aperiodic)")
    p_mid = model.params_at(float(np.median(rh_t)))
    distributed = _distributed(model, p_mid)
    edges = _line_grid(model, p_mid, w_hi, n_segments, distributed) if (distributed or fields) \
        else segment_edges(model.free_length, 1)
    base = dict(model.device.params)

    # 1. electrochemistry, reduced at once to what stages 2–4 need: the solvent excess and
    # the modal loads (rows of `reduce`, acting on the clamp branch and the segments), so a
    # long record never holds one row per segment unless a per-segment field is asked for
    lengths = np.concatenate([[base["L_clamp"]], np.diff(edges)])
    modal = _beam_projection(model, base, edges)
    reduce = np.vstack([base["n_solvation"] * lengths / base["L_total"],
                        np.hstack([np.zeros((modal.shape[0], 1)), modal])])
    flds = {}
    if stepper_needed:
        from . import stepper
        want = {"voltage": "U", "charge": "Q", "temperature": "T", "cation": "c"}
        out = stepper.run(model, model.params_at, t, v, rh_t, edges,
                          {want[f] for f in fields if f in want}, progress=progress)
        load, current = out["load"], out["current"]
        c_up, c_low = out.get("c_up"), out.get("c_low")
        if "voltage" in fields:
            flds["voltage"] = out["U"][1:]
        if "charge" in fields:
            flds["charge"] = out["Q"][1:]
        if "temperature" in fields:
            flds["temperature"] = out["T"][1:]
        reduced = reduce @ load
    else:
        p = model.params_at(float(rh_t[0]))
        per_segment = "cation" in fields
        reduced, current, flds = _electrochemistry_lti(model, p, edges, v, dt, hold, fields, periodic,
                                                       None if per_segment else reduce)
        if per_segment:
            load, reduced = reduced, reduce @ reduced
            c_up, c_low = load, -load
        if "temperature" in fields:
            flds["temperature"] = np.full((edges.size - 1, t.size), p["T_ext"])
    if "cation" in fields:
        flds["cation_upper"], flds["cation_lower"] = c_up[1:], c_low[1:]

    # 2.–4. load filter, mechanics
    load_filter, cs_filter = _load_filters(model, base, w_hi)
    cs = _apply_filter(cs_filter, reduced[:1], dt, hold, periodic)[0]
    loads = _modal_loads(model, reduced[1:], rh_t, load_filter, dt, hold, periodic)
    del reduced                                      # the electrochemistry rows are no longer needed
    tip = _mechanics(model, base, loads, model.hook("stiffness_factor")(rh_t), dt, hold, periodic)
    del loads
    tip = _output_effects(model, tip, rh_t, dt)
    return SimulationResult(time=t, voltage=v, rh=rh_t, deflection=tip, current=current, cs_up=cs,
                            cs_low=-cs, device=model.device.name, effects=model.effect_ids,
                            z=0.5 * (edges[1:] + edges[:-1]), fields=flds)


@single_threaded
def tip_from_interface_excess(model, t, ell, edges, rh=None, *, apply_solvent_factor: bool = True,
                              hold: str = "cubic", periodic: bool = False) -> np.ndarray:
    """Tip deflection [m] for a given load history, through the same load factors, beam and
    output effects as :func:`simulate`.

    ``ell`` (n_seg, N) is the first-moment-equivalent interface cation excess [mol/m³] (the
    face excess (C⁺(h) − C⁺(−h))/2 in the linear regime) on the free segments with ``edges`` [m] (from the clamp), sampled at ``t`` [s];
    the couple is mu = 2 h w n⁺ kf ℓ with kf(s) and the humidity factors of ``model`` at ``rh``
    [%].  ``apply_solvent_factor=False`` skips the solvent factor B(s), for loads that already
    contain the solvent's back-diffusion."""
    model = as_model(model)
    t, _ = _check_record(t, np.zeros(np.size(t)))
    ell = np.atleast_2d(np.asarray(ell, dtype=float))
    edges = np.asarray(edges, dtype=float)
    if ell.shape != (edges.size - 1, t.size):
        raise InputError(f"ell must have shape (segments, samples) = ({edges.size - 1}, {t.size}), got {ell.shape}")
    rh_t = model.check_rh(rh)
    rh_t = np.full(t.size, float(rh_t)) if np.ndim(rh_t) == 0 else np.asarray(rh_t, dtype=float)
    base = dict(model.device.params)
    dt = float(t[1] - t[0])
    load_filter, _ = _load_filters(model, base, np.pi / dt, solvent=apply_solvent_factor)
    return _tip(model, base, ell, edges, rh_t, load_filter, dt, hold, periodic)


def _tip(model, base, ell, edges, rh_t, load_filter, dt, hold, periodic):
    """Stages 2–4 for per-segment loads ``ell`` (n_seg, N): projection onto the modes,
    load filter and humidity (:func:`_modal_loads`), mechanics, then the output effects."""
    loads = _modal_loads(model, _beam_projection(model, base, edges) @ ell, rh_t, load_filter, dt, hold, periodic)
    tip = _mechanics(model, base, loads, model.hook("stiffness_factor")(rh_t), dt, hold, periodic)
    return _output_effects(model, tip, rh_t, dt)


def _output_effects(model, tip, rh_t, dt) -> np.ndarray:
    """The tip deflection through the model's added output effects (at the mean RH)."""
    if not model.outputs:
        return tip
    return model.filter_output(tip, 1.0 / dt, model.params_at(float(np.mean(rh_t))))


def _beam_projection(model, base, edges) -> np.ndarray:
    """(n_modes + 1, n_seg): modal loads [N] and the quasi-static residual [N m²] per unit
    first-moment-equivalent interface excess [mol/m³] on each free segment."""
    coef = 2.0 * 0.5 * base["t_polymer"] * base["width"] * base["n_solvation"]
    proj = projection(model.modes(), edges, coef)
    return np.vstack([proj.modal, proj.residual])


def _modal_loads(model, pre, rh_t, load_filter, dt, hold, periodic) -> np.ndarray:
    """Stage 3: projected loads ``pre`` (n_modes + 1, N) through the load filter kf(s)(·B(s))
    and the humidity factor of the coupling, row by row in place (``pre`` is overwritten and
    returned, so a long record needs one extra row, not a second array)."""
    factor = model.hook("coupling_factor")(rh_t)
    for k in range(pre.shape[0]):
        pre[k] = _apply_filter(load_filter, pre[k:k + 1], dt, hold, periodic)[0] * factor
    return pre


def _check_record(t, voltage):
    if t is None or voltage is None:
        raise InputError("simulate needs the time vector t [s] and the voltage record [V]")
    t = np.asarray(t, dtype=float).ravel()
    v = np.asarray(voltage, dtype=float).ravel()
    if t.size < 3:
        raise InputError("a record needs at least 3 samples")
    if v.shape != t.shape:
        raise InputError(f"voltage has {v.size} samples but t has {t.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise InputError("t and voltage must be finite (no NaN or inf)")
    dtv = np.diff(t)
    if np.any(dtv <= 0):
        raise InputError("t must be strictly increasing")
    if np.max(np.abs(dtv - dtv.mean())) > 1e-6 * dtv.mean():
        raise InputError("t must be uniformly sampled (resample the record first)")
    return t, v


# ----------------------------------------------------------------------------------------
# Stage 1: electrochemistry as an LTI system
# ----------------------------------------------------------------------------------------
def _electrochemistry_lti(model: ActuatorModel, p: dict, edges, v, dt, hold, fields, periodic=False,
                          reduce: np.ndarray | None = None):
    """Linear electrochemistry.  Returns (interface cation excess per branch, clamp branch
    first (n_seg+1, N) [mol/m³] — or ``reduce`` (k, n_seg+1) applied to it, (k, N) —,
    current (N) [A], fields)."""
    d = model.double_layer_props(p)
    branch = model.hook("realize")(d, np.pi / dt)
    nc = branch.n_states
    area = p["width"] * np.diff(edges)
    n = area.size
    g = model.hook("series_conductances")(p, edges)
    Ab, Bb = branch.A, branch.B
    Cj, Cc, Cq = branch.C[0:1], branch.C[1:2], branch.C[2:3]
    Dj, Dc, Dq = branch.D[0, 0], branch.D[1, 0], branch.D[2, 0]
    Ac_clamp = p["width"] * p["L_clamp"]
    if g is None:
        # every segment sees Vin: one branch stands for all of them
        Ufrom_x, Ufrom_v = np.zeros((n, nc)), np.ones((n, 1))
        A, B = Ab, Bb
        seg_state = np.tile(np.eye(nc), (n, 1))              # maps the branch state to every segment
        I_x = (area.sum() + Ac_clamp) * Cj
        I_v = (area.sum() + Ac_clamp) * Dj
        clamp_x, clamp_v = Cc, Dc
    else:
        L = np.zeros((n, n))
        i = np.arange(n)
        L[i, i] = g + np.append(g[1:], 0.0)
        L[i[:-1], i[1:]] = L[i[1:], i[:-1]] = -g[1:]
        M = L + Dj * np.diag(area)
        Cj_blk = np.kron(np.diag(area), Cj)                   # current of every segment from its states
        Minv = linalg.inv(M)
        Ufrom_x = -Minv @ Cj_blk                                # U = Ufrom_x x + Ufrom_v Vin
        Ufrom_v = (Minv[:, 0] * g[0])[:, None]
        Bblk = np.kron(np.eye(n), Bb)
        A_seg = np.kron(np.eye(n), Ab) + Bblk @ Ufrom_x
        B_seg = Bblk @ Ufrom_v
        # clamp branch (driven by Vin) appended after the segments
        A = linalg.block_diag(A_seg, Ab)
        B = np.vstack([B_seg, Bb])
        seg_state = np.hstack([np.eye(n * nc), np.zeros((n * nc, nc))])
        Ufrom_x = np.hstack([Ufrom_x, np.zeros((n, nc))])
        I_x = np.hstack([-g[0] * Ufrom_x[0:1, :n * nc], Ac_clamp * Cj])
        I_v = g[0] * (1.0 - Ufrom_v[0, 0]) + Ac_clamp * Dj
        clamp_x = np.hstack([np.zeros((1, n * nc)), Cc])
        clamp_v = Dc
    # per-segment outputs: y_k = C_row x_k + D U_k with x_k = seg_state-block rows
    Cc_blk = np.kron(np.eye(n), Cc) @ seg_state
    c_x = Cc_blk + Dc * Ufrom_x
    c_v = Dc * Ufrom_v
    exc_C, exc_D = np.vstack([clamp_x, c_x]), np.vstack([[[clamp_v]], c_v])
    if reduce is not None:
        exc_C, exc_D = reduce @ exc_C, reduce @ exc_D
    n_exc = exc_C.shape[0]
    rows_C = [exc_C, I_x]
    rows_D = [exc_D, np.array([[I_v]])]
    if "voltage" in fields:
        rows_C.append(Ufrom_x)
        rows_D.append(Ufrom_v)
    if "charge" in fields:
        rows_C.append(np.kron(np.eye(n), Cq) @ seg_state + Dq * Ufrom_x)
        rows_D.append(Dq * Ufrom_v)
    ss = StateSpace(A, B, np.vstack(rows_C), np.vstack(rows_D))
    y, _ = lti.simulate(ss, v[None, :], dt, x0=_steady_state(ss, v[0]), hold=hold, periodic=periodic)
    excess, current = y[:n_exc], y[n_exc].copy()     # a copy, so the excess rows can be freed alone
    flds, k = {}, n_exc + 1
    if "voltage" in fields:
        flds["voltage"], k = y[k:k + n], k + n
    if "charge" in fields:
        flds["charge"] = y[k:k + n]
    return excess, current, flds


def _steady_state(ss: StateSpace, u0: float) -> np.ndarray:
    """State in equilibrium with a constant input (records start from rest at Vin(0))."""
    if ss.n_states == 0 or u0 == 0.0:
        return np.zeros(ss.n_states)
    return linalg.solve(ss.A, -ss.B[:, 0] * u0)


def _distributed(model: ActuatorModel, p: dict) -> bool:
    """True when the electrode line has a resistance, so the voltage varies along the strip."""
    return model.hook("series_conductances")(p, segment_edges(model.free_length, 2)) is not None


def _line_grid(model: ActuatorModel, p: dict, w_hi: float, n_segments: int | None,
               distributed: bool | None = None) -> np.ndarray:
    """Segment edges for the electrode ladder: refined until the discrete line matches the
    closed-form transmission line (modal loads and current) to 0.2 % from 0.05 Hz up to
    min(w_hi/2, 100 Hz) — twice the 50 Hz top of the actuator's band."""
    L = model.free_length
    distributed = _distributed(model, p) if distributed is None else distributed
    if n_segments is not None:
        return segment_edges(L, int(n_segments), 1.5 if distributed else 1.0)
    if not distributed:
        return segment_edges(L, 16)
    s = 1j * np.logspace(np.log10(2 * np.pi * 0.05), np.log10(max(min(w_hi / 2, 2 * np.pi * 100.0), 2 * np.pi)), 6)
    d = model.double_layer_props(p)
    q, c = model.hook("small_signal")(s, d, p)
    Yp = s * q + d.G_leak
    modes = model.modes()
    zq, wq = quadrature(L)
    U = model.hook("distribution")(s, Yp, p, zq)
    exact_Q = (U * wq) @ modes.dphi(zq).T
    exact_I = Yp * (U @ wq)
    for n in (8, 12, 16, 24, 32, 48, 64, 96, 128):
        edges = segment_edges(L, n, 1.5)
        Ud = _ladder_voltage(model, p, edges, Yp)
        dQ = (Ud @ modes.couple_modal_loads(edges).T)
        dI = Yp * (Ud @ np.diff(edges))
        err = max(np.max(np.abs(dQ - exact_Q)) / np.max(np.abs(exact_Q)),
                  np.max(np.abs(dI - exact_I) / np.abs(exact_I)))
        if err < 2e-3:
            return edges
    raise ModelError(f"the electrode line needs more than 128 segments at this sampling rate (error {err:.1e}); "
                     "lower the sampling rate or give n_segments")


def _ladder_voltage(model, p, edges, Yp) -> np.ndarray:
    """Per-volt segment voltages of the discrete ladder at each frequency (len(Yp), n)."""
    g = model.hook("series_conductances")(p, edges)
    area = p["width"] * np.diff(edges)
    n = area.size
    out = np.empty((Yp.size, n), dtype=complex)
    for k, y in enumerate(Yp):
        M = np.zeros((n, n), dtype=complex)
        i = np.arange(n)
        M[i, i] = g + np.append(g[1:], 0.0) + area * y
        M[i[:-1], i[1:]] = M[i[1:], i[:-1]] = -g[1:]
        rhs = np.zeros(n, dtype=complex)
        rhs[0] = g[0]
        out[k] = linalg.solve(M, rhs)
    return out


# ----------------------------------------------------------------------------------------
# Stage 3: load filters
# ----------------------------------------------------------------------------------------
def _load_filters(model: ActuatorModel, p: dict, w_hi: float, solvent: bool = True):
    """(load response kf(s)·B(s)·added load factors, B(s)) as state spaces, or plain gains
    where they are constant over the band (:meth:`physics.model.ActuatorModel.load_response`);
    ``solvent=False`` leaves B(s) out of both."""
    band = (_W_LO, w_hi)
    sf = model.hook("solvent_factor")
    B = _realize(lambda s: sf(s, p), band, "solvent factor B(s)") if solvent else 1.0
    rest = _realize(lambda s: model.load_response(s, p, solvent=False), band, "load response kf(s)", fit=False)
    if rest is not None:          # a constant gain times B: scale B's realisation exactly
        return (B.scaled_output(rest) if isinstance(B, StateSpace) else rest * B), B
    return _realize(lambda s: model.load_response(s, p, solvent=solvent), band, "load filter kf(s)·B(s)"), B


def _realize(fn, band, what: str, fit: bool = True):
    """``fn(s)`` as a real gain when it is constant over ``band`` [rad/s] (relative 1e-12), else
    its real-pole realisation (None when ``fit`` is False)."""
    s = 1j * np.geomspace(band[0], band[1], 16)
    v = np.asarray(fn(s), dtype=complex) * np.ones(s.shape)
    if np.all(np.abs(v - v[0]) <= 1e-12 * np.abs(v[0])) and abs(v[0].imag) <= 1e-12 * abs(v[0]):
        return float(v[0].real)
    return fit_pole_residue(fn, band, what=what).statespace() if fit else None


def _apply_filter(f, u: np.ndarray, dt: float, hold: str, periodic: bool = False) -> np.ndarray:
    """Run every row of ``u`` through the SISO filter ``f`` (a StateSpace or a gain)."""
    if not isinstance(f, StateSpace):
        return f * u
    x0 = _steady_state(f, 1.0)[:, None] * u[None, :, 0]
    y, _ = lti.simulate(f, u[None], dt, x0=x0, hold=hold, periodic=periodic)
    return y[0]


# ----------------------------------------------------------------------------------------
# Stage 4: mechanics
# ----------------------------------------------------------------------------------------
def beam_statespace(model: ActuatorModel, p: dict, stiffness_factor: float) -> StateSpace:
    """Inputs: modal loads Q_1..Q_n [N] and the residual numerator R [N m²]; output: tip
    deflection [m].  Each mode: m q'' + beta⁴L EI*(s)(1 + s beta_f) q = Q with the Prony
    internal variables; residual: R / (EI*(s)(1 + s beta_f)) (quasi-static higher modes)."""
    EI, rhoA = model.section(p, stiffness_factor)
    modes = model.modes()
    L, bf = modes.L, p["beta_f"]
    tau = np.asarray(EI.tau_k, dtype=float)
    a = np.asarray(EI.E_k, dtype=float) / tau if tau.size else np.zeros(0)
    EI0 = EI.E_inf + float(np.sum(EI.E_k))
    m, nk = rhoA * L, tau.size
    blocks = []
    for i in range(modes.n_modes):
        c = modes.beta[i] ** 4 * L
        A = np.zeros((2 + nk, 2 + nk))
        A[0, 1] = 1.0
        A[1, 0], A[1, 1] = -c * EI0 / m, -c * EI0 * bf / m
        A[1, 2:] = c * a / m
        A[2:, 0], A[2:, 1] = 1.0, bf
        A[2:, 2:] = -np.diag(1.0 / tau) if nk else A[2:, 2:]
        Bm = np.zeros((2 + nk, 1))
        Bm[1, 0] = 1.0 / m
        Cm = np.zeros((1, 2 + nk))
        Cm[0, 0] = modes.tip[i]
        blocks.append(StateSpace(A, Bm, Cm, [[0.0]]))
    # residual: w = (R + Σ a_k ζ_k)/EI0, ζ' = −ζ/τ + w, then ξ = w/(1 + s beta_f)
    Ar = -np.diag(1.0 / tau) + np.outer(np.ones(nk), a) / EI0 if nk else np.zeros((0, 0))
    res = StateSpace(Ar, np.ones((nk, 1)) / EI0, a[None, :] / EI0, [[1.0 / EI0]])
    blocks.append(res.series(lti.first_order_lag(bf)))
    sys = lti.block_diag(*blocks)
    return StateSpace(sys.A, sys.B, np.ones((1, sys.n_outputs)) @ sys.C, np.ones((1, sys.n_outputs)) @ sys.D)


def _mechanics(model: ActuatorModel, p: dict, loads: np.ndarray, stiffness: np.ndarray, dt: float,
               hold: str, periodic: bool = False) -> np.ndarray:
    """Tip deflection, in blocks over which the humidity stiffness factor is constant
    (within 0.2 %); the mechanical state is carried across blocks."""
    N = loads.shape[1]
    logk = np.log(stiffness)
    starts = [0]
    ref = logk[0]
    for i in range(1, N if np.ptp(logk) > 2e-3 else 0):
        if abs(logk[i] - ref) > 2e-3:
            starts.append(i)
            ref = logk[i]
    starts.append(N)
    if len(starts) > 2 + N // 50:   # many short blocks: warn if they come from noise, not a drift
        levels = np.array([np.mean(logk[a:b]) for a, b in zip(starts[:-1], starts[1:])])
        steps = np.sign(np.diff(levels))
        if np.mean(steps[1:] != steps[:-1]) > 0.3:
            import warnings
            warnings.warn(f"the RH record looks noisy: the stiffness jumps back and forth every "
                          f"{N / (len(starts) - 1):.0f} samples on average and each jump restarts the mechanics; "
                          "pass a smoothed RH (e.g. physics.compare.model_rh)", stacklevel=3)
    tip = np.empty(N)
    x = None
    for b0, b1 in zip(starts[:-1], starts[1:]):
        seg = slice(max(b0 - 1, 0), b1)                  # overlap one sample to carry the state
        ss = beam_statespace(model, p, float(np.exp(np.mean(logk[b0:b1]))))
        if x is None:
            x = _steady_state_multi(ss, loads[:, 0])
        y, x = lti.simulate(ss, loads[:, seg], dt, x0=x, hold=hold, periodic=periodic)
        tip[b0:b1] = y[0, (1 if b0 > 0 else 0):]
    return tip


def _steady_state_multi(ss: StateSpace, u0: np.ndarray) -> np.ndarray:
    if ss.n_states == 0 or not np.any(u0):
        return np.zeros(ss.n_states)
    return linalg.solve(ss.A, -ss.B @ u0)
