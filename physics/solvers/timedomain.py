"""Time-domain solver: the same chain as :mod:`physics.solvers.frequency`, realised in time.

Stages (each small, so each is well conditioned):

1. electrochemistry along the strip (Vin → interface cation excess per segment, current):
   an LTI state space (double-layer branch realisation on the finite-volume ladder of
   the electrodes) simulated exactly, or — with ``nonlinear_charge``, ``thermal`` or
   RH-dependent electrochemistry — the implicit stepper of :mod:`physics.solvers.stepper`;
2. projection onto the beam: modal loads and the quasi-static residual (static matrix);
3. load filter: solvent factor B(s) × kf(s) as a real-pole realisation, then the
   humidity factor of kf sample by sample;
4. mechanics: modal cantilever with the Prony modulus and Rayleigh damping, plus the
   quasi-static residual, in blocks of constant RH when RH varies (state carried over).

The segment grid of the electrode line is refined until the discrete ladder reproduces
the closed-form transmission line to 0.2 % up to 100 Hz (or fs/4).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from . import lti
from ..execution.threads import single_threaded
from ..errors import InputError, ModelError
from .lti import StateSpace
from ..model import ActuatorModel, as_model
from .realize import fit_pole_residue
from .discretisation import line_functionals, projection, quadrature, segment_edges

FIELDS = {
    "voltage": "voltage across the polymer along the strip [V]",
    "charge": "electrode charge per area along the strip [C/m²]",
    "cation": "interface cation excess at the upper and lower faces along the strip [mol/m³]",
    "temperature": "temperature along the strip [K] (T_ext without the thermal effect)",
}

_W_LO = 2.0 * np.pi * 1e-5  # lowest frequency the realisations are accurate at [rad/s]
#: Samples per piece in which a record runs through the stages (state carried from piece to
#: piece, the result that of the whole record at once): memory grows with the outputs kept,
#: not with the stages' intermediate signals.
PIECE_SAMPLES = 1 << 18


@dataclass
class SimulationResult:
    """The result of :func:`simulate`: time series in SI units.

    Attributes
    ----------
    time, voltage, rh : ndarray
        The inputs: time [s], voltage at the clamp [V], relative humidity [%].
    deflection : ndarray
        Tip deflection [m], positive towards the anode.
    current : ndarray
        Current drawn at the clamp [A].
    cs_up, cs_low : ndarray
        Interface solvent excess at the upper and lower faces, averaged over the electrode
        length [mol/m³] (thesis eq. 8): the first-moment-equivalent value that bends the
        strip (the face value in the linear regime; with ``nonlinear_charge`` the face values
        are in the field ``cation``).
    device : str
        The device's name.
    effects : tuple of str
        The effects that were on.
    z : ndarray
        Segment centres along the strip from the clamp [m] (for the fields).
    fields : dict
        The fields asked for, each an (n_segments, n_samples) array;
        ``cation_upper``/``cation_lower`` for the field ``cation``.

    Examples
    --------
    >>> import numpy as np, physics
    >>> t = np.arange(0, 2, 1e-3)
    >>> res = physics.simulate("ipmc_pt_eg", "none", t, np.sin(2 * np.pi * t), fields=("voltage",))
    >>> res.fs, res.deflection.shape, res.fields["voltage"].shape[1]
    (1000.0, (2000,), 2000)
    """

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
        """The result as a ``physics.io.timeseries.TimeSeries``, for writing in the common file
        format (``docs/reference/file-formats.md``)."""
        from ..io.timeseries import TimeSeries
        temp = self.fields.get("temperature")
        meta = {"generator": "eap-model physics.simulate", "device": self.device, "effects": list(self.effects)}
        return TimeSeries(time=self.time, voltage=self.voltage, deflection=self.deflection, rh=self.rh,
                          current=self.current,
                          temperature=None if temp is None else temp.mean(axis=0) - 273.15, meta=meta)


@single_threaded
def simulate(device, effects=None, t=None, voltage=None, rh=None, *, fields=(), n_modes: int = 4,
             hold: str = "cubic", n_segments: int | None = None, periodic: bool = False,
             progress: bool = False) -> SimulationResult:
    """Simulate the tip deflection of a strip driven by a voltage record.

    Parameters
    ----------
    device : str, path or Device
        A device name (``"ipmc_pt_eg"``, ``"ip2c_pedot_water"``), a device YAML file, a
        :class:`~physics.Device`, or a model already built with its effects (then ``effects``
        may be left out).
    effects : str or list of str, optional
        Effect ids, comma-separated or as a list, and the groups ``default`` (the device's own
        list, the default), ``linear``, ``all``, ``none``, with ``+id``/``-id`` to add or
        remove one: ``"default,+creep,-thermal"``.  The double layer is always included.
    t : array_like
        Sample times [s], uniformly spaced, at least 3.
    voltage : array_like
        Voltage at the clamp [V], one value per sample.
    rh : float or array_like, optional
        Relative humidity [%], a constant or one value per sample; required when the
        ``humidity`` effect is on.
    fields : tuple of str, optional
        Internal fields to return along the strip: any of ``"voltage"`` (across the polymer,
        V), ``"charge"`` (electrode charge per area, C/m²), ``"cation"`` (interface cation
        excess at both faces, mol/m³), ``"temperature"`` (K).
    n_modes : int, optional
        Bending modes resolved dynamically (default 4; the rest are quasi-static).
    hold : {"cubic", "linear"}, optional
        How the input is interpolated between samples: ``cubic`` for smooth signals,
        ``linear`` for signals with jumps (steps, pulses).
    n_segments : int, optional
        Segments of the electrode line along the strip (default: chosen from the bandwidth).
    periodic : bool, optional
        The record is one period of a periodic excitation: return the periodic steady state
        (no start-up transient; linear models at a constant RH only).  Otherwise the strip
        starts at rest, in equilibrium with ``voltage[0]``.
    progress : bool, optional
        Print progress of the nonlinear stepper.

    Returns
    -------
    SimulationResult
        ``deflection`` [m] (positive towards the anode), ``current`` [A], ``cs_up`` and
        ``cs_low`` [mol/m³], the inputs, and the requested ``fields`` on the segment
        centres ``z`` [m].

    Raises
    ------
    InputError
        A bad record (non-uniform time, a NaN, a missing RH), an unknown effect or field.
    ModelError
        A result that is not finite or bends the tip beyond the strip's free length.

    Examples
    --------
    A 2 V, 1 Hz tone on the thesis IPMC at 60 % RH; after the start-up transient the
    amplitude is 2 V times the gain of :func:`frequency_response` at 1 Hz:

    >>> import numpy as np, physics
    >>> t = np.arange(0, 10, 1e-3)
    >>> res = physics.simulate("ipmc_pt_eg", "default", t, 2 * np.sin(2 * np.pi * t), rh=60)
    >>> amplitude = 0.5 * np.ptp(res.deflection[t >= 5])
    >>> gain = physics.frequency_response("ipmc_pt_eg", "default", [1.0], rh=60).magnitude[0]
    >>> round(1e6 * amplitude), round(1e6 * 2 * gain)
    (1511, 1511)
    """
    model = as_model(device, effects, n_modes)
    rec = _prepare(model, t, voltage, rh, fields, n_segments, periodic)
    reduce, chain = _stages(model, rec, hold, periodic)
    if rec.stepper_needed:
        current, flds = _stage1_stepper(model, rec, fields, reduce, chain, progress)
    else:
        current, flds = _stage1_linear(model, rec, fields, reduce, chain, hold, periodic)
    cs, tip = chain.finish()
    tip = _output_effects(model, tip, rec.rh, rec.dt)
    return SimulationResult(time=rec.t, voltage=rec.v, rh=rec.rh, deflection=tip, current=current, cs_up=cs,
                            cs_low=-cs, device=model.device.name, effects=model.effect_ids,
                            z=0.5 * (rec.edges[1:] + rec.edges[:-1]), fields=flds)


@dataclass(frozen=True)
class _Record:
    """A checked record of :func:`simulate`: time ``t`` [s], voltage ``v`` [V] and the ``drive``
    the strip sees (``v`` through the model's input effects) [V], RH ``rh`` [%] per sample, step
    ``dt`` [s], segment ``edges`` [m], and whether the stepper runs."""

    t: np.ndarray
    v: np.ndarray
    drive: np.ndarray
    rh: np.ndarray
    dt: float
    edges: np.ndarray
    stepper_needed: bool


def _prepare(model, t, voltage, rh, fields, n_segments, periodic) -> _Record:
    """Check the record, the RH and the fields; choose the solver and the segment grid."""
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
    drive = _input_effects(model, v, p_mid, dt)
    return _Record(t, v, drive, rh_t, dt, edges, bool(stepper_needed))


def _stages(model, rec: _Record, hold, periodic):
    """(``reduce``, stages 2–4 as a :class:`_Chain`).  ``reduce`` is stage 1's output map:
    the electrochemistry reduced at once to what stages 2–4 need (the solvent excess and the
    modal loads: rows acting on the clamp branch and the segments), so a long record never
    holds one row per segment unless a per-segment field is asked for."""
    base = model.chain_params(rec.rh)
    lengths = np.concatenate([[base["L_clamp"]], np.diff(rec.edges)])
    modal = _beam_projection(model, base, rec.edges)
    reduce = np.vstack([base["n_solvation"] * lengths / base["L_total"],
                        np.hstack([np.zeros((modal.shape[0], 1)), modal])])
    load_filter, cs_filter = _load_filters(model, base, np.pi / rec.dt)
    return reduce, _Chain(model, base, load_filter, cs_filter, rec.rh, rec.dt, hold, periodic)


def _stage1_stepper(model, rec: _Record, fields, reduce, chain, progress):
    """Stage 1 by the implicit stepper, its loads pushed through ``chain``: (current, fields)."""
    from . import stepper
    t, rh_t, flds = rec.t, rec.rh, {}
    want = {"voltage": "U", "charge": "Q", "temperature": "T", "cation": "c"}
    out = stepper.run(model, model.params_at, t, rec.drive, rh_t, rec.edges,
                      {want[f] for f in fields if f in want}, progress=progress)
    load, current = out["load"], out["current"]
    c_up, c_low = out.get("c_up"), out.get("c_low")
    if "voltage" in fields:
        flds["voltage"] = out["U"][1:]
    if "charge" in fields:
        flds["charge"] = out["Q"][1:]
    if "temperature" in fields:
        flds["temperature"] = out["T"][1:]
    del out
    for a in range(0, t.size, PIECE_SAMPLES):
        chain.push(reduce @ load[:, a:a + PIECE_SAMPLES])
    if "cation" in fields:
        flds["cation_upper"], flds["cation_lower"] = c_up[1:], c_low[1:]
    return current, flds


def _stage1_linear(model, rec: _Record, fields, reduce, chain, hold, periodic):
    """Stage 1 as one LTI system (:class:`_Electrochemistry`), fed through ``chain`` in
    pieces: (current, fields)."""
    v, edges = rec.drive, rec.edges
    p = model.params_at(float(rec.rh[0]))
    per_segment = "cation" in fields
    stage1 = _Electrochemistry(model, p, edges, v.size, rec.dt, hold, fields, periodic, reduce, per_segment)
    for a in range(0, v.size, PIECE_SAMPLES):
        chain.push(stage1.push(v[a:a + PIECE_SAMPLES]))
    chain.push(stage1.finish())
    current, flds = stage1.current, stage1.fields
    if "temperature" in fields:
        flds["temperature"] = np.full((edges.size - 1, rec.t.size), p["T_ext"])
    if per_segment:
        excess = stage1.excess
        flds["cation_upper"], flds["cation_lower"] = excess[1:], -excess[1:]
    return current, flds


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
    base = model.chain_params(rh_t)
    dt = float(t[1] - t[0])
    load_filter, _ = _load_filters(model, base, np.pi / dt, solvent=apply_solvent_factor)
    return _tip(model, base, ell, edges, rh_t, load_filter, dt, hold, periodic)


def _tip(model, base, ell, edges, rh_t, load_filter, dt, hold, periodic):
    """Stages 2–4 for per-segment loads ``ell`` (n_seg, N): projection onto the modes,
    load filter and humidity, mechanics (:class:`_Chain`), then the output effects."""
    chain = _Chain(model, base, load_filter, None, rh_t, dt, hold, periodic)
    proj = _beam_projection(model, base, edges)
    for a in range(0, rh_t.size, PIECE_SAMPLES):
        chain.push(proj @ ell[:, a:a + PIECE_SAMPLES])
    return _output_effects(model, chain.finish()[1], rh_t, dt)


def _input_effects(model, v, p, dt) -> np.ndarray:
    """The voltage ``v`` [V] through the model's added input effects (parameters ``p``, at the
    record's median RH), checked: one finite value per sample."""
    if not model.inputs:
        return v
    drive = model.filter_input(v, 1.0 / dt, p)
    if drive.shape != v.shape or not np.all(np.isfinite(drive)):
        who = ", ".join(e.label for e in model.inputs)
        got = f"shape {drive.shape}" if drive.shape != v.shape else "non-finite values"
        raise ModelError(f"input effect {who}: filter_input must return one finite voltage per sample ({v.size}), "
                         f"got {got}")
    return drive


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
    step = (t[-1] - t[0]) / (t.size - 1)                 # the mean step [s]
    for a in range(0, t.size - 1, PIECE_SAMPLES):        # in pieces: no step array of a long record
        dtv = np.diff(t[a:a + PIECE_SAMPLES + 1])
        if np.any(dtv <= 0):
            raise InputError("t must be strictly increasing")
        if np.max(np.abs(dtv - step)) > 1e-6 * step:
            raise InputError("t must be uniformly sampled (resample the record first)")
    return t, v


# ----------------------------------------------------------------------------------------
# Stage 1: electrochemistry as an LTI system
# ----------------------------------------------------------------------------------------
class _Electrochemistry:
    """Stage 1, linear: the electrochemistry as one LTI system fed with the voltage in
    pieces.  ``push``/``finish`` return ``reduce`` (k, n_seg+1) applied to the interface
    cation excess per branch (clamp branch first, [mol/m³]), (k, m), and fill ``current``
    (N) [A], ``fields`` and, ``per_segment``, the excess itself ``excess`` (n_seg+1, N)."""

    def __init__(self, model: ActuatorModel, p: dict, edges, N: int, dt, hold, fields, periodic,
                 reduce: np.ndarray, per_segment: bool):
        d = model.double_layer_props(p)
        branch = model.hook("realize")(d, np.pi / dt, model.hook("realized_charge")(d, p))
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
        if not per_segment:
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
        self.stage = _Stage(ss, dt, hold, periodic, lambda u0: _steady_state(ss, float(u0[0, 0])))
        self.n_exc, self.n, self.k = n_exc, n, 0
        self.current = np.empty(N)
        self.fields = {f: np.empty((n, N)) for f in ("voltage", "charge") if f in fields}
        self.reduce = reduce
        self.excess = np.empty((n_exc, N)) if per_segment else None

    def push(self, v: np.ndarray) -> np.ndarray:
        return self._emit(self.stage.push(v[None, None, :])[:, 0])

    def finish(self) -> np.ndarray:
        return self._emit(self.stage.finish()[:, 0])

    def _emit(self, y: np.ndarray) -> np.ndarray:
        """Store the rows of a piece of outputs; return what stages 2–4 need."""
        a, b, n_exc = self.k, self.k + y.shape[1], self.n_exc
        self.current[a:b] = y[n_exc]
        k = n_exc + 1
        for f in self.fields:
            self.fields[f][:, a:b], k = y[k:k + self.n], k + self.n
        self.k = b
        if self.excess is None:
            return y[:n_exc]
        self.excess[:, a:b] = y[:n_exc]
        return self.reduce @ y[:n_exc]


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
    zq, _ = quadrature(L)
    ints = model.hook("distribution")(s, Yp, p, zq) @ line_functionals(L, modes.n_modes)
    exact_Q = ints[:, 1:-1]
    exact_I = Yp * ints[:, 0]
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


class _Stage:
    """A linear stage (a :class:`~physics.solvers.lti.StateSpace`, or a plain gain) fed in pieces
    (:class:`physics.solvers.lti.Stream`: (n_in, 1, m) in, (n_out, 1, k) out), started in equilibrium
    with its first input sample (``x0_of(u[..., 0])``); ``periodic``: the whole record is run
    at ``finish`` as one period of a periodic input (:func:`physics.solvers.lti.simulate`)."""

    def __init__(self, f, dt: float, hold: str, periodic: bool, x0_of=None):
        self.f, self.dt, self.hold, self.periodic = f, dt, hold, periodic
        self.x0_of = x0_of or (lambda u0: _steady_state(f, 1.0)[:, None] * u0[0][None, :])
        self.stream, self.held = None, []

    def push(self, u: np.ndarray) -> np.ndarray:
        if not isinstance(self.f, StateSpace):
            return self.f * u
        if self.periodic or not u.shape[-1]:
            self.held += [u] if self.periodic else []
            return np.zeros((self.f.n_outputs, 1, 0))
        if self.stream is None:
            self.stream = lti.Stream(self.f, self.dt, self.x0_of(u[..., 0]), self.hold)
        return self.stream.push(u)

    def finish(self) -> np.ndarray:
        if not isinstance(self.f, StateSpace):
            return np.zeros((1, 1, 0))
        if self.periodic:
            u = np.concatenate(self.held, axis=-1)
            self.held = []
            return lti.simulate(self.f, u, self.dt, hold=self.hold, periodic=True)[0]
        return self.stream.finish()

    @property
    def x(self) -> np.ndarray:
        """The final state (after ``finish``)."""
        return self.stream.x


class _Chain:
    """Stages 2–4 fed with the electrochemistry reduced to rows, in pieces (``push`` (k, m),
    then ``finish`` → (cs (N) [mol/m³], tip (N) [m])): with a solvent filter ``cs_filter``,
    row 0 is the solvent excess (→ cs) and the rest the projected loads, else all rows are
    the projected loads (n_modes + 1): load filter kf(s)(·B(s)) and the humidity factor of
    the coupling (stage 3), then the mechanics (stage 4, :class:`_Mechanics`)."""

    def __init__(self, model, base, load_filter, cs_filter, rh_t, dt, hold, periodic):
        self.rh_t, self.coupling = rh_t, model.hook("coupling_factor")
        self.coupling(np.array([np.min(rh_t), np.max(rh_t)]))   # its warnings once, for the whole record's range
        n_loads = model.n_modes + 1
        self.cs_stage = None if cs_filter is None else _Stage(cs_filter, dt, hold, periodic)
        # one stage per row: a batch of rows would multiply the recursion's working memory
        self.load_stages = [_Stage(load_filter, dt, hold, periodic) for _ in range(n_loads)]
        self.mechanics = _Mechanics(model, base, model.hook("stiffness_factor")(rh_t), dt, hold, periodic)
        self.cs = np.empty(rh_t.size) if cs_filter is not None else None
        self.tip = np.empty(rh_t.size)
        self.k_cs = self.k_load = self.k_tip = 0

    def push(self, rows: np.ndarray | None, last: bool = False) -> None:
        """The next piece of rows (``last``: none, the end of the record)."""
        if self.cs_stage is not None:
            self._cs(self.cs_stage.finish() if last else self.cs_stage.push(rows[None, :1]))
            rows = None if last else rows[1:]
        loads = np.vstack([(s.finish() if last else s.push(rows[None, k:k + 1]))[0]
                           for k, s in enumerate(self.load_stages)])
        a, b = self.k_load, self.k_load + loads.shape[1]
        with warnings.catch_warnings():                     # given once, in __init__
            warnings.simplefilter("ignore")
            loads *= self.coupling(self.rh_t[a:b])
        self.k_load = b
        self._tip(self.mechanics.push(loads))
        if last:
            self._tip(self.mechanics.finish())

    def finish(self) -> tuple[np.ndarray | None, np.ndarray]:
        self.push(None, last=True)
        return self.cs, self.tip

    def _cs(self, y):
        self.cs[self.k_cs:self.k_cs + y.shape[-1]] = y[0, 0]
        self.k_cs += y.shape[-1]

    def _tip(self, y):
        self.tip[self.k_tip:self.k_tip + y.size] = y
        self.k_tip += y.size


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


class _Mechanics:
    """Stage 4: tip deflection [m] for the modal loads fed in pieces (``push`` (n_modes + 1, m)
    → tip (k)), in blocks over which the humidity stiffness factor ``stiffness`` (N) is
    constant (within 0.2 %); each block starts where the previous one ended (one sample of
    overlap, its mechanical state carried over)."""

    def __init__(self, model: ActuatorModel, p: dict, stiffness, dt: float, hold: str, periodic: bool):
        self.model, self.p, self.dt, self.hold, self.periodic = model, p, dt, hold, periodic
        logk = np.log(stiffness)
        N = logk.size
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
                warnings.warn(f"the RH record looks noisy: the stiffness jumps back and forth every "
                              f"{N / (len(starts) - 1):.0f} samples on average and each jump restarts the mechanics; "
                              "pass a smoothed RH (e.g. physics.compare.model_rh)", stacklevel=4)
        self.blocks = [(b0, b1, float(np.exp(np.mean(logk[b0:b1])))) for b0, b1 in zip(starts[:-1], starts[1:])]
        self.block, self.k, self.stage, self.last, self.drop = -1, 0, None, None, 0

    def push(self, loads: np.ndarray) -> np.ndarray:
        out, m, i = [], loads.shape[1], 0
        while i < m:
            if self.stage is None:
                self._next_block()
            b1 = self.blocks[self.block][1]
            j = min(m, i + b1 - self.k)
            out.append(self._emit(self.stage.push(loads[:, None, i:j])))
            self.k += j - i
            self.last = loads[:, j - 1]
            i = j
            if self.k == b1 and self.block + 1 < len(self.blocks):
                out.append(self._emit(self.stage.finish()))
                self.x, self.stage = self.stage.x, None
        return np.concatenate(out) if out else np.zeros(0)

    def finish(self) -> np.ndarray:
        return self._emit(self.stage.finish())

    def _next_block(self) -> None:
        """Start the next block; after the first, it begins one sample early (the last
        sample of the previous block, whose output is dropped) with the state there."""
        self.block += 1
        b0, _, stiffness = self.blocks[self.block]
        ss = beam_statespace(self.model, self.p, stiffness)
        if b0 == 0:
            self.stage = _Stage(ss, self.dt, self.hold, self.periodic, lambda u0: _steady_state_multi(ss, u0[:, 0]))
            return
        x = self.x
        self.stage = _Stage(ss, self.dt, self.hold, self.periodic, lambda u0: x)
        self.drop = 1
        self.stage.push(self.last[:, None, None])

    def _emit(self, y: np.ndarray) -> np.ndarray:
        """The tip samples of a stage output (1, 1, k), without the overlap sample."""
        y = y[0, 0]
        k = min(self.drop, y.size)
        self.drop -= k
        return y[k:]


def _steady_state_multi(ss: StateSpace, u0: np.ndarray) -> np.ndarray:
    if ss.n_states == 0 or not np.any(u0):
        return np.zeros(ss.n_states)
    return linalg.solve(ss.A, -ss.B @ u0)
