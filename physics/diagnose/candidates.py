"""Candidate models: switch an effect on (or off), refit, score on the time records.

**Which parameters are fitted.**  A model's free parameters are the *base's* — by default
its coupling gain (``kf``, or ``kf0`` with ``fractional_coupling``), its stiffness
(``Y``; ``dma_scale`` with ``viscoelastic``; ``Y_polymer`` with ``layered_beam``) and the
Rayleigh damping ``beta_f`` — plus the parameters of the effect switched on.  All of it is
read from the effect's ``diagnosis`` spec in its own module (:mod:`.specs`); for the
built-in effects:

==========================  =====================================================  ==========
effect                      extra free parameters (bounds)                         nested?
==========================  =====================================================  ==========
``electrode_resistance``    ``Rs`` (0.1–10⁴ Ω/□)                                    yes (Rs→0)
``fractional_coupling``     ``frac_a`` (0–0.95), its DC corner ``frac_f_lo``         yes (a→0)
                            (shape: 10⁻⁴–0.05 Hz); ``kf0`` replaces ``kf``
``fractional_charge``       ``cpe_a`` (0–0.95), its DC corner ``cpe_f_lo``           yes (a→0)
                            (shape: 10⁻⁴–0.05 Hz); tried on request only
``solvent_diffusion``       ``D_solvent`` (h²/Ds from 0.2 s to 10⁵ s)               yes (Ds→0)
``viscoelastic``            the free shape ``ve_slope``, ``ve_tan_delta`` and its    no
                            low end ``ve_f_lo`` (10⁻³–20 Hz); ``dma_scale``
                            replaces ``Y``
``layered_beam``            ``Y_electrode``; ``Y_polymer`` replaces ``Y``           no
``humidity``                ``kf`` and ``Y`` once per RH level (Table V style)      yes
                            instead of shared values (needs ≥ 2 RH levels)
``nonlinear_charge``        ``diffuse_share`` when the data determine it (below)   no
==========================  =====================================================  ==========

A parameter that moves between roles (``kf`` ↔ ``kf0``, ``Y`` ↔ ``dma_scale`` ↔
``Y_polymer``) starts from the base's fitted value translated to the new role (same
gain at the band's geometric mid-frequency, same modulus).  Each fit is bounded
least squares on the complex log FRF (:func:`physics.identify.fit_lsq`, multi-start, plus a
grid of starts over the effect's own parameter, whose scale is unknown); a parameter that
ends on the edge of its default search window (3 decades around a start that may itself be
far off) is searched again around that edge (:func:`_on_search_window_edge`); linear models
cost milliseconds per evaluation.  ``nonlinear_charge`` uses the describing function of
:mod:`.describing` in the FRF fit, each record standing for a tone with its drive's power
(:attr:`.records.PreparedRecord.tone_amplitude`).  Its large-signal parameter (the compact
layers' share of the voltage, which sets the voltage at which the charge saturates) is fitted only
when records at two or more amplitude levels exist and it changes the large-signal gain by
more than 10 % across its range; otherwise it is held at the device value and the report
says so.

**Scoring.**  Every fitted model is simulated on every record (decimated, see
:mod:`.records`; the sensor's low-pass applied; the model starts at rest at the record's
first voltage).  The deflection is exactly proportional to the coupling gain, so that
free parameter is then refined on the time records in closed form (:func:`_refine_gain`).
A nested effect starts (among its other starts) from the base's optimum with the effect at
its ``off`` values, and a fit that still ends worse than the base on the time records is
replaced by that point, the model without it (:func:`no_worse_than_base`).
The residual (measured minus model, its nuisance terms — offset and linear drift of each
record, bounded so that they cannot eat physics, :meth:`.records.PreparedRecord.nuisance` — removed)
gives the RMS error and fit % at the full rate (the prediction interpolated back) and, on the
decimated samples, the effective sample size of :mod:`.stats`; the evidence is computed on
that pooled error (:func:`compare_fits`).
"""
from __future__ import annotations

import dataclasses
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..device import Device, all_param_specs
from ..identify.problem import InertParameterError
from ..identify.settings import DEFAULT_DECADES
from ..errors import InputError, ModelError
from ..execution.memo import remembered
from ..identify import (IdentifiabilityWarning, IdentificationProblem, IdentificationResult, fit_lsq)
from ..identify.free_parameters import FreeParameter
from ..effects import EFFECTS
from ..model import ActuatorModel, resolve_effects
from ..solvers.timedomain import simulate
from ..analysis import stats
from .describing import DescribingFunction, charge_effects
from .records import NUISANCE_TERMS, PreparedRecord, remove_nuisance, sensor_filter, upsample
from .specs import (declared_default, default_candidates, effect_params, is_nested, off_values, param_bounds,
                    param_used, role_family, role_param, shape_params, spec_of, start_points)

ROLE_GAIN, ROLE_STIFF = "gain", "stiffness"
#: The large-signal parameter is fitted when it changes the large-signal gain by more than this (relative).
DF_MIN_SENSITIVITY = 0.10
#: Simulations of every record the time-domain refinement of a pick may spend, its finite-difference
#: Jacobians and final uncertainty included (:func:`refine_on_time`).
TIME_REFINE_SIMS = 60
#: ... and the joint refinement of the model the command writes (:func:`polish_on_time`).
POLISH_SIMS = 8 * TIME_REFINE_SIMS
#: Evaluations per start of the time refinement of an input effect's parameters, each a simulation
#: of every record on the mapped voltage (:func:`_refine_added_effects`; an output effect's only filter
#: one simulation and may spend 200).
INPUT_REFINE_NFEV = 40
#: ... from this many of its starts, those whose first evaluation fits the records best (each start
#: of a kept draft low-pass's grid cost 160 simulations of every record per candidate map of the
#: drive fitted with it: over 4 minutes per candidate on a held-out strip).
INPUT_REFINE_STARTS = 2
#: A parameter ending on the edge of its default search window is searched again around it at most this often.
RECENTRE_ROUNDS = 3
#: ... when that lowers the fit's cost by more than this share (else the window edge lies along a
#: valley the data leave flat, e.g. the gain and the stiffness together, and the first fit stands).
RECENTRE_GAIN = 1e-3
#: A start point of an added effect replaces its FRF optimum when it lowers the time records' sum of
#: squares by more than this share (2 %, ~1 % in RMS: less is not worth a time-domain refinement).
TIME_START_GAIN = 0.02
#: Simulations of every record spent refining a held large-signal parameter between its grid's
#: neighbours on the time records (:func:`held_on_time`), beside one per other grid coordinate.
HELD_REFINE_SIMS = 5


def gain_param(ids) -> str:
    return role_param(ROLE_GAIN, ids)


def stiffness_param(ids) -> str:
    return role_param(ROLE_STIFF, ids)


def default_free(ids) -> list[str]:
    """The base's free parameters by default: gain, stiffness, damping."""
    return [gain_param(ids), stiffness_param(ids), "beta_f"]


def _layered(ids) -> bool:
    """True when the section of a model with effects ``ids`` includes the electrode layers."""
    return any(getattr(EFFECTS[e], "layered", False) for e in ids if e in EFFECTS)


# ============================================================================ specs


@dataclass
class ModelSpec:
    """A model to fit: effects, free and per-RH parameters, start values, bounds."""

    label: str
    effects: tuple[str, ...]
    free: list[str]
    per_rh: list[str] = field(default_factory=list)
    start: dict = field(default_factory=dict)
    bounds: dict = field(default_factory=dict)
    extra_starts: list[dict] = field(default_factory=list)
    added: str | None = None
    removed: str | None = None
    notes: list[str] = field(default_factory=list)


def _ref_omega(band) -> float:
    return 2 * math.pi * math.sqrt(band[0] * band[1])


def translate_start(device: Device, from_ids, to_ids, band) -> dict:
    """Start values for the gain and stiffness roles of ``to_ids`` from the fitted values
    of ``from_ids`` in ``device`` (see the module doc), through the stages' role hooks
    (``gain_equivalent``/``gain_start`` of the coupling stage, ``modulus_equivalent``/
    ``modulus_start`` of the modulus stage, ``layer_modulus`` of the section stage)."""
    p = dict(device.params)
    out: dict = {}
    w = _ref_omega(band)
    f_ref = w / (2 * math.pi)
    m0 = ActuatorModel(device, from_ids)
    m1 = ActuatorModel(device, to_ids)
    if gain_param(from_ids) != gain_param(to_ids):
        out.update(m1.hook("gain_start")(m0.hook("gain_equivalent")(p, w), p, w))
    if stiffness_param(from_ids) != stiffness_param(to_ids):
        lay0, lay1 = _layered(from_ids), _layered(to_ids)
        # the modulus of an equivalent homogeneous strip the fitted model has [Pa]
        E = m0.hook("modulus_equivalent")(p, f_ref, lay0) + m0.hook("layer_modulus")(p)
        polymer = max(E - m1.hook("layer_modulus")(p), 0.2 * E)
        out.update(m1.hook("modulus_start")(polymer, p, f_ref, lay1))
    return out


def map_free(free: Sequence[str], from_ids, to_ids) -> list[str]:
    """The base's free parameters translated to a model with effects ``to_ids``: roles
    follow their effect (kf ↔ kf0, Y ↔ dma_scale ↔ Y_polymer), unused ones are dropped."""
    out = []
    for name in free:
        if name in role_family(ROLE_GAIN):
            name = gain_param(to_ids)
        elif name in role_family(ROLE_STIFF):
            name = stiffness_param(to_ids)
        if param_used(name, to_ids) and name not in out:
            out.append(name)
    return out


def candidate_spec(effect: str, base_ids, base_free: Sequence[str], base_per_rh: Sequence[str],
                   device: Device, band, n_rh_levels: int) -> ModelSpec:
    """The base plus ``effect`` (see the module doc)."""
    to_ids = resolve_effects(list(base_ids) + [effect], device)
    free = map_free(base_free, base_ids, to_ids)
    per_rh = list(base_per_rh)
    start = {k: v for k, v in translate_start(device, base_ids, to_ids, band).items()}
    notes = []
    spec = spec_of(effect)
    if not spec.get("describing_function"):    # else decided after the describing-function probe
        free += [name for name in effect_params(effect) + shape_params(effect) if name not in free]
    per = list(spec.get("per_rh", ()))
    if per:
        if n_rh_levels >= 2:
            for name in per:
                for role in (ROLE_GAIN, ROLE_STIFF):
                    if name in role_family(role) and role_param(role, to_ids) in free:
                        free.remove(role_param(role, to_ids))
            per_rh += [name for name in per if name not in per_rh]
            free = [name for name in free if name not in per_rh]      # shared or per RH, never both
            notes.append(f"{effect}: {', '.join(per)} fitted once per RH level (Table V style), replacing the "
                         "shared values")
        else:
            notes.append(f"{effect}: one RH level, so its per-RH parameters ({', '.join(per)}) keep the device's "
                         "values")
    bounds = {name: b for name in free if (b := param_bounds(name, device)) is not None}
    derived = derived_starts(effect, device)      # e.g. a DMA table's own shape
    for name, b in bounds.items():
        start[name] = float(np.clip(start[name], b[0], b[1])) if name in start else start_in_range(name, device,
                                                                                                   derived, b)
    off = {k: v for k, v in off_values(effect, device).items() if k in free} if is_nested(effect) else {}
    # an effect switched on does not start at its "off" value (a declared default that leaves it off):
    # its shape parameters would have no effect there and be held; it starts at its spec's first start
    first = next(iter(start_points(effect, device)), {})
    for name, v in off.items():
        if name in first and name in start and np.isclose(start[name], v):
            start[name] = float(np.clip(first[name], *bounds.get(name, (-np.inf, np.inf))))
    # starts over the effect's own parameters (unknown scale), and the base's optimum with the effect
    # off (a nested effect: its fit then never ends worse than the base on the FRF criterion)
    extra = [st for st in ({k: v for k, v in pt.items() if k in free} for pt in start_points(effect, device)) if st]
    if off:
        extra.append({k: float(np.clip(v, *bounds[k])) if k in bounds else v for k, v in off.items()})
    return ModelSpec(f"+{effect}", to_ids, free, per_rh, start, bounds, extra, added=effect, notes=notes)


def start_in_range(name: str, device: Device, derived: dict, bounds) -> float:
    """Start of a parameter fitted with an effect: the device's value, else the effect's own
    derived start (``derived``, e.g. a DMA table's own shape), else the declared default, else
    the middle of its range (geometric for a positive range); always inside ``bounds``."""
    lo, hi = bounds
    v = device.params.get(name, derived.get(name, declared_default(name)))
    if v is None or not (lo <= v <= hi):
        v = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
    return float(np.clip(v, lo, hi))


def derived_starts(effect: str, device: Device) -> dict:
    """The effect's own starts derived from the device (its ``diagnosis_start`` hook), or {}."""
    hook = getattr(EFFECTS[effect], "diagnosis_start", None)
    return hook(device) if callable(hook) else {}


def removal_spec(effect: str, base_ids, base_free, base_per_rh, device: Device, band) -> ModelSpec:
    """The base without ``effect`` (to check that the data support it)."""
    to_ids = resolve_effects([e for e in base_ids if e != effect], device)
    per = spec_of(effect).get("per_rh")      # its per-RH parameters become shared ones again
    shared = list(base_free) + (list(base_per_rh) if per else [])
    per_rh = [] if per else list(base_per_rh)
    free = map_free(shared, base_ids, to_ids)
    start = translate_start(device, base_ids, to_ids, band)
    start = {k: v for k, v in start.items() if k in free}
    return ModelSpec(f"-{effect}", to_ids, free, per_rh, start, {}, [], removed=effect)


# ============================================================================ fitting


class DescribingFunctionProblem(IdentificationProblem):
    """An identification problem whose model response for each target is multiplied by
    the describing function N(A, f) of the large-signal double layer (see :mod:`.describing`)."""

    def __init__(self, *args, amplitudes: Sequence[float], df: DescribingFunction, **kw):
        self.amplitudes = list(amplitudes)
        self.df = df
        super().__init__(*args, **kw)

    def responses(self, theta):
        out = super().responses(theta)
        names = [p.name for p in self.params]
        name = self.df.param
        value = float(theta[names.index(name)]) if name in names else \
            float(self.device.params.get(name, declared_default(name)))
        return [H * self.df(a, t.freq, value) for H, a, t in zip(out, self.amplitudes, self.targets)]


@dataclass
class ModelFit:
    """A fitted, scored model (see the module doc); arrays per record."""

    spec: ModelSpec
    result: IdentificationResult | None
    device: Device | None
    model: ActuatorModel | None
    values: dict = field(default_factory=dict)
    std_errors: dict = field(default_factory=dict)
    rel_std_errors: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    k: int = 0
    pred_d: list = field(default_factory=list)
    resid_d: list = field(default_factory=list)
    rss: list = field(default_factory=list)
    n: list = field(default_factory=list)
    taus: list = field(default_factory=list)
    rmse_records: list = field(default_factory=list)
    rmse: float = math.nan
    fit_pct: float = math.nan
    bic: float = math.nan
    aic: float = math.nan
    frf_cost: float = math.nan
    fit_s: float = 0.0
    score_s: float = 0.0
    error: str | None = None
    df_info: dict | None = None
    nuisance: list = field(default_factory=list)     # :class:`.records.Nuisance` per record
    time_refined: bool = False                       # set by :func:`refine_on_time`
    correlation: np.ndarray | None = None            # of the free parameters, in ``values`` order

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def effects(self) -> tuple[str, ...]:
        return self.spec.effects


def fit_model(spec: ModelSpec, device: Device, targets, target_records: Sequence[PreparedRecord], *, n_starts: int = 4,
              seed: int = 0, n_modes: int = 4, df_cache: dict | None = None, keep: int | None = None) -> ModelFit:
    """Fit ``spec`` on the FRF ``targets`` (one record each in ``target_records``); ``keep``: the
    starts screened, only that many to convergence (:func:`physics.identify.fitting.fit_lsq`)."""
    t0 = time.perf_counter()
    try:
        kw = dict(start={k: v for k, v in spec.start.items() if k in spec.free},
                  bounds={k: v for k, v in spec.bounds.items() if k in spec.free}, n_modes=n_modes)
        time_only = time_only_params(spec, device)
        df = any(spec_of(e).get("describing_function") for e in spec.effects)
        frf_free = [n for n in spec.free if n not in time_only]
        kw = {**kw, "start": {k: v for k, v in kw["start"].items() if k in frf_free},
              "bounds": {k: v for k, v in kw["bounds"].items() if k in frf_free}}

        def build(start, drop_inert=True):
            k = {**kw, "start": start}
            while True:
                try:
                    if df:
                        return _df_problem(spec, device, targets, target_records, k, df_cache, time_only)
                    return IdentificationProblem(device, spec.effects, targets, frf_free, spec.per_rh, **k), None
                except InertParameterError as exc:   # e.g. a damping another effect's loss replaces: held
                    left = len(frf_free) + len(spec.per_rh) - 1      # what would still be fitted without it
                    if not drop_inert or exc.name not in frf_free + list(spec.per_rh) or left < 1:
                        raise
                    if exc.name in frf_free:
                        frf_free.remove(exc.name)
                    spec.free = [n for n in spec.free if n != exc.name]
                    spec.per_rh = [n for n in spec.per_rh if n != exc.name]     # held at each level's value
                    k = {**k, "start": {a: v for a, v in k["start"].items() if a != exc.name},
                         "bounds": {a: v for a, v in k["bounds"].items() if a != exc.name}}
                    spec.notes.append(f"{exc.name} has no effect on the frequency response of this model: held at "
                                      "its value, not fitted")

        problem, df_info = build(kw["start"])
        extra = []
        for e in spec.extra_starts:
            th = problem.theta0.copy()
            for i, prm in enumerate(problem.params):
                if prm.name in e:
                    th[i] = float(np.clip(e[prm.name], prm.lower, prm.upper))
            # a start over parameters the FRF cannot see (set on the time records) is the first one again
            if not any(np.array_equal(th, t) for t in [problem.theta0] + extra):
                extra.append(th)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentifiabilityWarning)
            warnings.simplefilter("ignore", RuntimeWarning)
            j0 = problem.j_err(problem.theta0)
            fit = fit_lsq(problem, n_starts=n_starts, seed=seed, extra_starts=extra, keep=keep)
            for _ in range(RECENTRE_ROUNDS):
                edge = _on_search_window_edge(problem, fit.x, set(kw["bounds"]))
                if not edge:
                    break
                start = {**kw["start"], **{prm.name: float(v) for prm, v in zip(problem.params, fit.theta)
                                           if prm.rh is None}}
                try:
                    moved, info = build(start, drop_inert=False)
                except InertParameterError:       # a parameter gone inert where the fit ended: keep that fit
                    break
                again = fit_lsq(moved, n_starts=1, seed=seed, extra_starts=[fit.theta])
                if again.cost >= (1.0 - RECENTRE_GAIN) * fit.cost:      # a flat valley is not worth following
                    break
                problem, df_info, fit = moved, info, again
                spec.notes.append(f"{', '.join(edge)} ended on the edge of {DEFAULT_DECADES:g} decades around its "
                                  "start (a search window, not a physical bound): searched again around it")
        res = IdentificationResult(problem, {"lsq": fit}, "lsq", problem.device_for(fit.theta), j0,
                                   [t.source for t in targets], {"method": "lsq", "diagnosis": spec.label},
                                   time.perf_counter() - t0)
    except (InputError, ModelError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        return ModelFit(spec, None, None, None, error=str(exc), fit_s=time.perf_counter() - t0)
    labels = problem.labels
    mf = ModelFit(spec, res, res.device, ActuatorModel(res.device, spec.effects, n_modes=n_modes),
                  values=dict(zip(labels, fit.theta.tolist())), std_errors=dict(zip(labels, fit.std_error.tolist())),
                  rel_std_errors=dict(zip(labels, fit.rel_std_error.tolist())), warnings=list(fit.warnings),
                  k=len(labels) + len(time_only), frf_cost=float(fit.cost), fit_s=time.perf_counter() - t0,
                  df_info=df_info, correlation=np.array(fit.correlation, dtype=float))
    for n in time_only:     # set on the time records (_refine_added_effects)
        mf.values[n] = float(res.device.params.get(n, declared_default(n)))
    return mf


def _on_search_window_edge(problem, x, explicit: set) -> list[str]:
    """Shared log-scaled parameters of ``problem`` whose search coordinates ``x`` end on the
    edge of their default window (:data:`~physics.identify.settings.DEFAULT_DECADES` around the
    start), neither a range given for them (``explicit``: the spec's or the user's) nor the
    edge of their admissible range: the window is centred on a start that may be far off
    (a base fitted along a degenerate valley hands its candidates such starts)."""
    specs = all_param_specs()
    lo, hi = problem.x_bounds
    out = []
    for i, prm in enumerate(problem.params):
        if prm.rh is not None or prm.scale != "log" or prm.name in explicit:
            continue
        adm = specs[prm.name]
        tol = 1e-3 * (hi[i] - lo[i])
        if (x[i] <= lo[i] + tol and prm.lower > adm.lo * (1 + 1e-9)) or \
                (x[i] >= hi[i] - tol and prm.upper < adm.hi * (1 - 1e-9)):
            out.append(prm.name)
    return out


def time_only_params(spec: ModelSpec, device: Device) -> list[str]:
    """Free parameters of output effects that do not change the frequency response (e.g. an
    additive drift, :func:`physics.contract.time_only_params`): fitted on the time
    records only, never on the FRF targets."""
    from ..contract import time_only_params as blind
    p = {n: float(device.params.get(n, declared_default(n) or 0.0)) for n in spec.free}
    return blind(ActuatorModel(device, spec.effects), spec.free, {**device.params, **p})


def _df_problem(spec, device, targets, target_records, kw, df_cache, time_only):
    """The describing-function problem of a large-signal ``spec`` and its gain table; ``time_only``
    (:func:`time_only_params`) stay free in the spec but out of the problem, set on the time records."""
    amps = [float(f"{r.tone_amplitude:.3g}") for r in target_records]     # one table row per drive level
    lo = min(float(t.freq.min()) for t in targets)
    hi = max(float(t.freq.max()) for t in targets)
    rh = target_records[0].rh_measured
    shaping = charge_effects(spec.effects)
    owned = sorted({n for e in shaping for n in [q.name for q in EFFECTS[e].params] + list(EFFECTS[e].requires)})
    key = (tuple(spec.effects), tuple(round(float(device.params.get(n, math.nan)), 12) for n in owned),
           tuple(sorted(set(round(a, 9) for a in amps))), round(lo, 6), round(hi, 6))
    cache = df_cache if df_cache is not None else {}
    if key not in cache:
        probe = DescribingFunction(device, spec.effects, [max(amps)], (lo, hi), rh=rh, n_freqs=1)
        sens = probe.sensitivity
        if sens > DF_MIN_SENSITIVITY:
            df = DescribingFunction(device, spec.effects, amps, (lo, hi), rh=rh)
        else:
            now = device.params.get(probe.param, declared_default(probe.param))
            df = DescribingFunction(device, spec.effects, amps, (lo, hi), rh=rh,
                                    coordinates=[probe.coordinate(float(now))])
        cache[key] = (df, sens)
    df, sens = cache[key]
    name = df.param
    free = [n for n in spec.free if n not in time_only]
    note = None
    if sens > DF_MIN_SENSITIVITY and name not in free and len({r.amplitude_level for r in target_records}) >= 2:
        free.append(name)
        large = [e for e in spec.effects if spec_of(e).get("describing_function")]
        spec.extra_starts = list(spec.extra_starts) + [{name: pt[name]} for e in large
                                                       for pt in start_points(e, device) if name in pt]
    elif name in free and sens <= DF_MIN_SENSITIVITY:
        free.remove(name)
    if name in free:                        # its diagnosis range, a start inside it
        lo, hi = param_bounds(name, device)
        now = float(kw.get("start", {}).get(name, device.params.get(name, declared_default(name))))
        kw["bounds"] = {**kw.get("bounds", {}), name: (lo, hi)}
        kw["start"] = {**kw.get("start", {}), name: now if lo <= now <= hi else math.sqrt(lo * hi)}
    if name not in free:
        now = device.params.get(name, declared_default(name))
        note = (f"{name} held at {now:.4g}: across its range it changes the large-signal gain by only "
                f"{100 * sens:.2g} % and otherwise scales the gain, so these data cannot determine it")
        if note not in spec.notes:
            spec.notes.append(note)
    spec.free = free + [n for n in spec.free if n in time_only]      # those set on the time records stay free
    problem = DescribingFunctionProblem(device, spec.effects, targets, free, spec.per_rh, amplitudes=amps, df=df, **kw)
    info = {"sensitivity": sens, "parameter": name, "fitted": name in free, **df.gain_table()}
    return problem, info


# ============================================================================ scoring


def predict(model: ActuatorModel, rec: PreparedRecord) -> np.ndarray:
    """Model deflection [m] at the record's analysis rate, sensor response applied, each jump
    of the voltage placed within its sample interval (:func:`place_edges`)."""
    res = simulate(model, None, rec.t_sim, rec.v_sim, rh=rec.rh_model, hold=rec.hold)
    return place_edges(sensor_filter(res.deflection, rec.fs_d, rec.sensor_bandwidth)[rec.i0:], rec)


def place_edges(yh: np.ndarray, rec: PreparedRecord) -> np.ndarray:
    """``yh`` (a prediction of a step record at its analysis rate [m]) with the response to each
    jump of the voltage shifted in time by δ within ±½ sample interval: the samples show only
    that a jump happened between two of them, not where, and the linear hold puts it in the
    middle; a resonance ringing after a jump tells where (δ ω of its phase).  δ of each jump is
    the least-squares shift of the prediction over the jump's stretch (to the next jump),
    linearised, y(t − δ) ≈ y(t) − δ ẏ(t), with the residual's offset and drift removed; every
    model's prediction is placed alike.  Bounded by half a sample, it cannot take a lag the
    records resolve (a delay of a few samples stays in the error)."""
    if rec.kind != "steps" or not rec.steps.size or yh.size < 3:
        return yh
    h = 1.0 / rec.fs_d
    dy = np.gradient(yh, h)
    e = remove_nuisance(rec.y_d[:yh.size] - yh)
    out = yh.copy()
    for a, b in zip(rec.steps, list(rec.steps[1:]) + [yh.size]):
        g = dy[a:b] - dy[a:b].mean()
        den = float(g @ g)
        if den > 0:
            d = float(np.clip(-float(e[a:b] @ g) / den, -0.5 * h, 0.5 * h))
            out[a:b] -= d * dy[a:b]
    return out


def score(mf: ModelFit, records: Sequence[PreparedRecord], n_offsets: int | None = None) -> ModelFit:
    """Simulate ``mf`` on every record and fill in its residuals and metrics (in place)."""
    if not mf.ok:
        return mf
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            _refine_added_effects(mf, records)
            preds = [predict(mf.model, r) for r in records]
    except (InputError, ModelError, np.linalg.LinAlgError, FloatingPointError) as exc:
        mf.error = f"time simulation failed: {exc}"
        return mf
    preds = _refine_gain(mf, records, preds)
    mf.pred_d, mf.resid_d, mf.rss, mf.n, mf.taus, mf.rmse_records = [], [], [], [], [], []
    num, den, sq, cnt = 0.0, 0.0, 0.0, 0
    mf.nuisance = []
    for r, yh in zip(records, preds):
        y = r.ts.deflection
        yf = upsample(yh, r.q, y.size)
        nz = r.nuisance(y - yf)          # bounded: the offset and drift cannot eat physics
        e = nz.remove(r.y_d - yh, r.t_d)
        mf.pred_d.append(yh)
        mf.resid_d.append(e)
        mf.rss.append(float(e @ e))
        mf.n.append(int(e.size))
        mf.taus.append(stats.integrated_time(e))
        mf.nuisance.append(nz)
        ef = nz.remove(y - yf, r.ts.time)
        mf.rmse_records.append(float(np.sqrt(np.mean(ef ** 2))))
        sq += float(ef @ ef)
        cnt += ef.size
        num += float(ef @ ef)
        den += float(np.sum((y - y.mean()) ** 2))
    mf.rmse = math.sqrt(sq / cnt)
    mf.fit_pct = 100.0 * (1.0 - math.sqrt(num / den)) if den > 0 else math.nan
    k = mf.k + (NUISANCE_TERMS * len(records) if n_offsets is None else n_offsets)
    n_eff = sum(n / t for n, t in zip(mf.n, mf.taus))
    mf.bic = stats.bic([mf.rmse ** 2], [1], [n_eff], k)
    mf.aic = stats.aic([mf.rmse ** 2], [1], [n_eff], k)
    mf.score_s = time.perf_counter() - t0
    return mf


def _refine_added_effects(mf: ModelFit, records: Sequence[PreparedRecord]) -> None:
    """Refit the free parameters of user output and input effects on the time records (in place).

    An output effect (:class:`physics.effects.OutputEffect`) filters the deflection of the
    rest of the model, so the rest is simulated once and each evaluation only filters it
    (milliseconds); an input effect (:class:`physics.effects.InputEffect`) maps the voltage, so
    while its parameters are free each evaluation simulates the rest on the mapped voltage (a
    linear chain: a fraction of a second per record, :data:`INPUT_REFINE_NFEV` evaluations per
    start, from the :data:`INPUT_REFINE_STARTS` starts that fit best at once; the rest is simulated
    again only when the map's parameters move; a large-signal rest holds the map at its values, as
    each evaluation would run the implicit stepper on every record).  Bounded least squares over the effects'
    parameters, the coupling gain solved in closed form at each step (once per RH level while a map
    of the drive moves and ``kf`` is fitted per level, :func:`_gain_levels`; the levels' gains are
    then kept), from the FRF estimate and the spec's starts.  Slow effects (creep)
    and maps of the voltage (a dead-zone) that a frequency response cannot determine are then
    set by the records.  A nested effect is also started from its off values (the model without
    it), so that its fit never ends worse than the base on this criterion."""
    from scipy.optimize import least_squares
    outs = [e for e in mf.model.outputs if spec_of(e.id)]
    ins = [e for e in mf.model.inputs if spec_of(e.id)]
    names = [n for e in outs + ins for n in effect_params(e.id) if n in mf.spec.free]
    if not names:
        return
    core = ActuatorModel(mf.device, [e for e in mf.effects if e not in {o.id for o in outs + ins}],
                         n_modes=mf.model.n_modes)
    p0 = mf.model.params_at(records[0].rh_measured if np.ndim(records[0].rh_model) == 0 else None)
    mapped = [n for e in ins for n in effect_params(e.id) if n in names]      # the voltage map moves
    if mapped and not core.is_linear:   # each evaluation would run the implicit stepper on every record: held
        names = [n for n in names if n not in mapped]
        mapped = []
        if not names:
            return
    memos = [{} for _ in records]       # the rest is simulated again only when the map moves

    def core_response(k, q):
        def run():
            r, v = records[k], records[k].v_sim
            for e in ins:
                v = np.asarray(e.filter_input(v, r.fs_d, q), dtype=float)
            return simulate(core, None, r.t_sim, v, rh=r.rh_model, hold=r.hold).deflection
        return remembered(memos[k], tuple(float(q[n]) for n in mapped), run)

    ys = [remove_nuisance(r.y_d) for r in records]
    scale = [1.0 / (np.std(y) * math.sqrt(y.size) or 1.0) for y in ys]
    levels = _gain_levels(mf, records) if mapped else np.zeros(len(records), dtype=int)

    def predictions(theta):
        q = {**p0, **dict(zip(names, theta))}
        preds = []
        for k, r in enumerate(records):
            y = core_response(k, q)
            for e in outs:
                y = e.filter_output(y, r.fs_d, q)
            yh = sensor_filter(y, r.fs_d, r.sensor_bandwidth)[r.i0:]
            preds.append(remove_nuisance(yh))
        return preds

    def resid(theta):
        preds = predictions(theta)
        a = _level_gains(preds, ys, levels)[levels]
        return np.concatenate([(y - g * ph) * c for y, ph, c, g in zip(ys, preds, scale, a)])

    bounds = [param_bounds(n, mf.device) or (-np.inf, np.inf) for n in names]
    lo, hi = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    x_now = np.array([float(mf.device.params.get(n, declared_default(n))) for n in names])
    starts = [x_now] + [np.array([float(st.get(n, x)) for n, x in zip(names, x_now)])
                        for e in outs + ins for st in start_points(e.id, mf.device)]
    off = {n: v for e in outs for n, v in off_values(e.id, mf.device).items()}
    if any(n in off for n in names):       # a nested effect also starts from the model without it
        starts.append(np.array([float(off.get(n, x)) for n, x in zip(names, x_now)]))
    starts = [np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo)) for x0 in starts]
    if mapped:          # a cost never rises along a fit: the best never ends worse than any start
        starts = sorted(starts, key=lambda x: float(np.sum(resid(x) ** 2)))[:INPUT_REFINE_STARTS]
    best = None
    for x0 in starts:
        sol = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac",
                            max_nfev=INPUT_REFINE_NFEV if mapped else 200)
        if best is None or sol.cost < best.cost:
            best = sol
    vals = dict(zip(names, best.x.tolist()))
    mf.device = mf.device.with_params(**vals)
    mf.result.device = mf.device
    mf.model = ActuatorModel(mf.device, mf.effects, n_modes=mf.model.n_modes)
    if levels.max() > 0:      # each level's gain as the map left it
        gains = _level_gains(predictions(best.x), ys, levels, np.size(mf.device.humidity_maps["kf"].values))
        gains = np.where(gains > 0, gains, 1.0)
        _scale_gain(mf, gains)
        rh = mf.device.humidity_maps["kf"].rh
        mf.spec.notes.append("coupling gain of each RH level refined with the map on the time records: "
                             + ", ".join(f"RH {r:.3g} % ×{g:.5g}" for r, g in zip(rh, gains)))
    _time_uncertainty(mf, names, best, resid, lo, hi)
    mf.spec.notes.append("parameters of " + ", ".join(e.id for e in outs + ins) + " refined on the time records: "
                         + ", ".join(f"{k} = {v:.4g}" for k, v in vals.items()))


def _gain_levels(mf: ModelFit, records: Sequence[PreparedRecord]) -> np.ndarray:
    """The per-RH coupling gain level (index into the device's ``kf`` humidity map) of each record
    when ``kf`` is fitted once per RH level as absolute values, else all 0 (one gain).  A map of the
    drive changes each record's gain by its amplitude, which the FRF fit does not see: the per-RH
    gains it fitted carry that change, and one factor over all records cannot undo it (a test-bed
    strip whose drive saturated, records at 0.32, 0.64 and 1.6 V over three RH levels: its drafted
    soft saturation ended at 3.04× the true model's error with one factor, 1.03× with one per level;
    docs/reference/truth-families.md)."""
    m = mf.device.humidity_maps.get("kf")
    if gain_param(mf.effects) != "kf" or "kf" not in mf.spec.per_rh or m is None or m.mode != "absolute" \
            or np.size(m.rh) < 2:
        return np.zeros(len(records), dtype=int)
    return np.array([_level_of(m, r.rh_measured) for r in records])


def _level_of(m, rh: float) -> int:
    """Index of the level of the humidity map ``m`` nearest to ``rh`` [%]."""
    return int(np.argmin(np.abs(np.asarray(m.rh) - rh)))


def _level_gains(preds: list, ys: list, levels: np.ndarray, n: int = 0) -> np.ndarray:
    """The least-squares factor Σ⟨ŷ, y⟩/Σ⟨ŷ, ŷ⟩ of the predictions ``preds`` on the records ``ys``
    within each level of ``levels`` (``n`` levels at least; 1 where a level has no prediction)."""
    out = np.ones(max(int(levels.max()) + 1, n))
    for k in range(out.size):
        num = sum(float(ph @ y) for ph, y, lv in zip(preds, ys, levels) if lv == k)
        den = sum(float(ph @ ph) for ph, lv in zip(preds, levels) if lv == k)
        if den > 0:
            out[k] = num / den
    return out


def _time_uncertainty(mf: ModelFit, names: list[str], sol, resid, lo, hi) -> None:
    """Values, standard errors, correlations and identifiability warnings of the parameters
    ``names`` refined on the time records (least-squares solution ``sol`` of ``resid``),
    replacing those of the FRF fit, which no longer describe them: the linearised covariance
    s²(JᵀJ)⁻¹ with s² inflated by the residual's integrated autocorrelation time (Bates &
    Watts 1988, §2.3; the gain is profiled out)."""
    from ..identify.settings import REL_SE_LIMIT
    r, J = resid(sol.x), np.asarray(sol.jac, dtype=float)
    n, k = J.shape
    s2 = float(r @ r) / max(n - k, 1) * stats.integrated_time(r)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((k, k), np.inf)
    se = np.sqrt(np.abs(np.diag(cov)))
    labels = mf.result.problem.labels
    idx = {prm.name: i for i, prm in enumerate(mf.result.problem.params) if prm.rh is None}
    fit = mf.result.fit
    corr = mf.correlation if mf.correlation is not None else np.full((len(labels),) * 2, np.nan)
    stale = [n_ for n_ in names]
    mf.warnings = [w for w in mf.warnings if not any(w.startswith(n_ + " ") for n_ in stale)]
    for a, name in enumerate(names):
        v = float(sol.x[a])
        rel = float(se[a] / abs(v)) if v != 0 else math.inf
        i = idx.get(name)       # None: a parameter the FRF cannot see, fitted on the time records only
        label = name if i is None else labels[i]
        mf.values[label], mf.std_errors[label], mf.rel_std_errors[label] = v, float(se[a]), rel
        if i is not None:
            fit.theta[i] = v
            fit.std_error[i], fit.rel_std_error[i] = se[a], rel
            corr[i, :] = np.nan
            corr[:, i] = np.nan
            corr[i, i] = 1.0
        if not math.isfinite(rel) or rel > REL_SE_LIMIT:
            mf.warnings.append(f"{name} is not identifiable from these data: relative standard error "
                               f"{'∞' if not math.isfinite(rel) else f'{100 * rel:.3g} %'} (> {100 * REL_SE_LIMIT:g} %)")
        span = hi[a] - lo[a]
        if v <= lo[a] + 1e-6 * span or v >= hi[a] - 1e-6 * span:
            mf.warnings.append(f"{name} ended on a bound of its search range [{lo[a]:g}, {hi[a]:g}]: widen the "
                               "bounds or fix it; its interval is not meaningful")
    known = np.isfinite(se) & (se > 0)      # a singular J'J leaves the correlations unknown (NaN), not ∞/∞
    for a, na in enumerate(names):
        for b, nb in enumerate(names):
            if a != b and known[a] and known[b] and na in idx and nb in idx:
                corr[idx[na], idx[nb]] = cov[a, b] / (se[a] * se[b])
    mf.correlation = corr


def _refine_gain(mf: ModelFit, records: Sequence[PreparedRecord], preds: list) -> list:
    """Refine the free coupling gain (kf, kf0 or the per-RH kf) on the time records.

    The deflection is exactly proportional to the coupling gain (everything upstream of
    the load — the charge law included — does not depend on it), so the least-squares
    factor α = Σ⟨ŷ, y⟩/Σ⟨ŷ, ŷ⟩ (offsets removed) is the time-domain optimum of that
    parameter given the others.  It absorbs what the frequency-domain fit misses in gain
    (e.g. the describing-function approximation of a large-signal sweep); the fitted
    values and device are updated so that the applied device reproduces the score."""
    gain = gain_param(mf.effects)
    names = [p.name for p in mf.result.problem.params]
    if gain not in names and "kf" not in mf.spec.per_rh:
        return preds
    num = den = 0.0
    for r, p in zip(records, preds):
        pc = remove_nuisance(p)
        num += float(pc @ remove_nuisance(r.y_d))
        den += float(pc @ pc)
    if den <= 0 or not math.isfinite(num / den) or num / den <= 0:
        return preds
    a = num / den
    if gain in names:       # the refined gain stays within its admissible range (a fit on a bound is reported)
        spec = all_param_specs()[gain]
        v = float(mf.device.params[gain])
        a = min(max(a, spec.lo / v), spec.hi / v) if v > 0 else a
    _scale_gain(mf, a)
    if abs(a - 1) > 1e-3:
        mf.spec.notes.append(f"coupling gain refined on the time records (×{a:.5g})")
    return [a * p for p in preds]


def _scale_gain(mf: ModelFit, a) -> None:
    """Multiply the fitted coupling gain of ``mf`` by ``a`` (in place: values, errors, device,
    model): a scalar for the shared gain and every per-RH ``kf``, or one factor per level of the
    device's ``kf`` humidity map (:func:`_gain_levels`) for the per-RH ``kf`` alone."""
    gain, names = gain_param(mf.effects), [p.name for p in mf.result.problem.params]
    fit, dev = mf.result.fit, mf.device
    m = dev.humidity_maps.get("kf")
    level = (lambda rh: a) if np.ndim(a) == 0 else (lambda rh: a[_level_of(m, rh)])
    for i, prm in enumerate(mf.result.problem.params):
        if prm.name == gain and prm.rh is None and np.ndim(a) == 0 or (prm.name == "kf" and prm.rh is not None):
            f = level(prm.rh)
            fit.theta[i] *= f
            fit.std_error[i] *= f
            fit.ci95[i] *= f
            mf.values[prm.label] *= f
            mf.std_errors[prm.label] *= f
    if gain in names and np.ndim(a) == 0:
        dev = dev.with_params(**{gain: dev.params[gain] * a})
    if "kf" in mf.spec.per_rh and m is not None:
        dev = dataclasses.replace(dev, humidity_maps={**dev.humidity_maps, "kf": dataclasses.replace(m, values=m.values * a)})
    mf.device = dev
    mf.result.device = dev
    mf.model = ActuatorModel(dev, mf.effects, n_modes=mf.model.n_modes)


def model_at(mf: ModelFit, theta, time_only: dict | None = None) -> ActuatorModel:
    """The model of ``mf`` with its FRF-fitted parameters at ``theta`` (problem coordinates) and
    the parameters the FRF fit does not hold (set on the time records) at their current values,
    or at ``time_only``'s."""
    problem = mf.result.problem
    held = {p.name for p in problem.params}
    extra = {n: mf.device.params[n] for n in mf.spec.free if n not in held and n in mf.device.params}
    extra.update(time_only or {})
    dev = problem.device_for(theta)
    return ActuatorModel(dev.with_params(**extra) if extra else dev, mf.effects, n_modes=mf.model.n_modes)


def _map_params(names: list[str], device: Device) -> list[FreeParameter]:
    """The free parameters ``names`` the FRF fit does not hold (an output or input map's, set on the
    time records) as search coordinates: their draft or spec bounds, the logarithm within positive
    ones, started at the device's values."""
    out = []
    for n in names:
        lo, hi = param_bounds(n, device) or (-np.inf, np.inf)
        out.append(FreeParameter(n, float(device.params[n]), lo, hi, "log" if lo > 0 else "linear", ""))
    return out


def refine_on_time(mf: ModelFit, records: Sequence[PreparedRecord], *, sims: int = TIME_REFINE_SIMS,
                   start=None, joint: bool = False) -> bool:
    """Refit the FRF-fitted free parameters of ``mf`` on the time records, from the FRF
    optimum — or from ``start`` (problem coordinates, e.g. its start point) when that fits the
    time records better — within ``sims`` simulations (in place; True when the error fell).
    The FRF fit weighs the frequencies by their coherence on a log scale; the verdict's error
    is the time records' RMS, dominated by the large slow motion: with a base that cannot match
    the device exactly the two optima differ.  Bounded least squares in the FRF fit's search
    coordinates, each evaluation a simulation of every record at the analysis rate, within
    ``sims`` simulations of the records (default :data:`TIME_REFINE_SIMS`; each iteration costs one
    per parameter for its Jacobian, the uncertainty two per parameter); the uncertainties are
    then those of the time residual (Bates & Watts, the covariance inflated by its
    autocorrelation time).  A start that fits better than the FRF optimum is kept even when the
    search cannot improve on it (it is the time records' optimum already: a model refined before,
    refitted on the FRF alone).  Linear models only: a large-signal model runs the implicit stepper,
    ~10× dearer.  A fit already refined (:func:`start_on_time`) is left as it is (False), unless
    ``joint``: then the free parameters the FRF fit does not hold (an output or input map's,
    otherwise refined with the rest held, :func:`_refine_added_effects`) are fitted together with
    the others, from the current values (:func:`polish_on_time`)."""
    from scipy.optimize import least_squares
    from ..identify.fitting import uncertainty
    if not mf.ok or not mf.model.is_linear or mf.time_refined and not joint:
        return False
    problem, fit = mf.result.problem, mf.result.fit
    own = {p.name for p in problem.params}
    extra = [n for n in mf.spec.free if n not in own and n in mf.device.params]
    maps = _map_params(extra, mf.device) if joint else []
    p = len(problem.params)
    lo, hi = (np.concatenate([b, [q.x_bounds[k] for q in maps]]) for k, b in enumerate(problem.x_bounds))
    span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    scale = math.sqrt(sum(mf.rss) / sum(mf.n)) or 1.0
    memos = [{} for _ in records]       # a per-RH parameter's Jacobian column re-simulates only its level's records

    def resid(x):
        m = model_at(mf, problem.from_x(x[:p]), map_values(x[p:]))
        parts = []
        for r, memo in zip(records, memos):
            parts.append(r.detrend_d(r.y_d - remembered(memo, m.key_at(r.rh_model), lambda: predict(m, r))))
        return np.concatenate(parts) / scale

    def map_values(x):
        return {q.name: float(q.from_x(v)) for q, v in zip(maps, x)}

    def inside(theta):
        with np.errstate(divide="ignore"):          # a map switched off (0) on a log scale: its lower bound
            x = np.concatenate([problem.to_x(theta), [q.to_x(q.initial) for q in maps]])
        return np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)

    x0 = inside(fit.theta)
    iterations = (sims - 2 * p - 1 - (start is not None)) // (x0.size + 1)
    if iterations < 1:
        return False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        r0 = resid(x0)
        if start is not None and (r := resid(xs := inside(start))) @ r < r0 @ r0:
            x0, r0 = xs, r
        else:
            start = None
        sol = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", max_nfev=iterations)
        if sol.cost < 0.5 * float(r0 @ r0) * (1.0 - 1e-9):
            x, r = sol.x, sol.fun
        elif start is not None:     # the start beats the FRF optimum and is the time records' optimum already
            x, r = x0, r0
        else:
            return False
        x_maps = x[p:]
        unc = uncertainty(problem, x[:p], lambda xp: resid(np.concatenate([xp, x_maps])),
                          inflate=stats.integrated_time(r))
    before = mf.rmse
    theta = problem.from_x(x[:p])
    fit.theta[:], fit.x[:] = theta, x[:p]
    fit.std_error[:], fit.rel_std_error[:], fit.ci95[:] = unc["std_error"], unc["rel_std_error"], unc["ci95"]
    labels = problem.labels
    mf.model = model_at(mf, theta, map_values(x_maps))
    mf.device = mf.result.device = mf.model.device
    mf.values.update(zip(labels, theta.tolist()))
    mf.values.update(map_values(x_maps))
    mf.std_errors.update(zip(labels, unc["std_error"].tolist()))
    mf.rel_std_errors.update(zip(labels, unc["rel_std_error"].tolist()))
    mf.correlation = np.array(unc["correlation"], dtype=float)
    mf.warnings = unc["warnings"] + [w for w in mf.warnings if any(w.startswith(n + " ") for n in extra)]
    score(mf, records)
    mf.time_refined = True
    origin = "start" if start is not None else "values it had" if joint else "FRF optimum"
    mf.spec.notes.append(f"{', '.join(labels + [q.name for q in maps])} refined on the time records from the {origin}: "
                         f"RMS error {1e6 * before:.4g} → {1e6 * mf.rmse:.4g} µm")
    return True


def polish_on_time(mf: ModelFit, records: Sequence[PreparedRecord], sims: int = POLISH_SIMS) -> "ModelFit | None":
    """A copy of ``mf`` with all its free parameters refined on the time records at once — those
    the FRF fit holds and those of its output and input maps (a drafted play, a user's creep), which
    the fits refine one group at a time, the other held (:func:`_refine_added_effects`,
    :func:`refine_on_time`) — within ``sims`` simulations of the records, when that lowers its RMS
    error; else None.  For the model the command writes: on a ``circuit_lab`` strip behind a 70 µm
    play (seed 89) the draft rounds ended with a 48 µm play and the linear parameters fitted around
    it, 7.62 µm (2.78× the true model's error); refitted at once from those values, 3.65 µm (1.33×),
    the play 69 µm."""
    import copy
    trial = copy.deepcopy(mf)
    if refine_on_time(trial, records, sims=sims, joint=True) and trial.rmse < mf.rmse:
        return trial
    return None


def on_bound(prm, value: float) -> bool:
    """True when ``value`` of the problem parameter ``prm`` is at (or past) a bound of its range
    (within 10⁻³ of the search coordinate's span; the off value 0 of a log-scaled one too)."""
    if not prm.lower < value < prm.upper:
        return True
    x, (lo, hi) = float(prm.to_x(value)), prm.x_bounds
    tol = 1e-3 * max(1.0, hi - lo) if prm.scale == "linear" else 1e-3
    return x <= lo + tol or x >= hi - tol


def profiled_cost(model: ActuatorModel, records: Sequence[PreparedRecord]) -> float:
    """Sum of squares [m²] of ``model`` on the time records with its gain profiled out in closed form
    (α = Σ⟨ŷ, y⟩/Σ⟨ŷ, ŷ⟩, offsets removed; 1 when that is not positive) and each residual's bounded
    nuisance removed (:meth:`.records.PreparedRecord.detrend_d`)."""
    preds = [predict(model, r) for r in records]
    num = sum(float(remove_nuisance(p) @ remove_nuisance(r.y_d)) for p, r in zip(preds, records))
    den = sum(float(remove_nuisance(p) @ remove_nuisance(p)) for p in preds)
    a = num / den if den > 0 and num > 0 else 1.0
    return sum(float(np.sum(r.detrend_d(r.y_d - a * p) ** 2)) for p, r in zip(preds, records))


def start_on_time(mf: ModelFit, records: Sequence[PreparedRecord]) -> bool:
    """Start the added effect's own parameters from the spec's start points when the FRF
    optimum left one of them on a bound of its range and a start point fits the time records
    better (in place; True when it did).

    The FRF fit weighs every line of the band on a log scale; when the base misses physics
    elsewhere in the band (a second hidden effect), that misfit can hold the added effect at its
    off value although the time records — dominated by the large slow motion — want it: a slow
    effect pushed to the bound where it vanishes.  Each start point (the other parameters at the
    FRF optimum) is scored on the time records, the gain profiled out in closed form, the
    residual's bounded nuisance removed (:meth:`.records.PreparedRecord.detrend_d`); the best,
    when it beats the FRF optimum, is refined on the time records (:func:`refine_on_time`), so
    that its values, uncertainties and quality flags are those of the error the verdict
    reports.  Linear models only, as :func:`refine_on_time`."""
    eff = mf.spec.added
    if not mf.ok or eff is None or not mf.model.is_linear:
        return False
    problem, fit = mf.result.problem, mf.result.fit
    own = {prm.name: i for i, prm in enumerate(problem.params) if prm.rh is None and prm.name in effect_params(eff)}
    if not any(on_bound(problem.params[i], float(fit.theta[i])) for i in own.values()):
        return False

    def cost(theta) -> float:
        return profiled_cost(model_at(mf, theta), records)

    trials = []
    for st in start_points(eff, mf.device):
        theta = fit.theta.copy()
        for name, v in st.items():
            if name in own:
                prm = problem.params[own[name]]
                theta[own[name]] = float(np.clip(v, prm.lower, prm.upper))
        if not np.array_equal(theta, fit.theta):
            trials.append(theta)
    if not trials:
        return False
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            now = cost(fit.theta)
            costs = [cost(th) for th in trials]
    except (InputError, ModelError, np.linalg.LinAlgError, FloatingPointError):
        return False
    k = int(np.argmin(costs))
    if not costs[k] < (1.0 - TIME_START_GAIN) * now:
        return False
    before = mf.rmse
    fit.theta[:] = trials[k]
    fit.x[:] = problem.to_x(trials[k])
    mf.model = model_at(mf, trials[k])
    mf.device = mf.result.device = mf.model.device
    mf.values.update(zip(problem.labels, fit.theta.tolist()))
    score(mf, records)
    start = ", ".join(f"{n} = {fit.theta[i]:.4g}" for n, i in own.items())
    mf.spec.notes.append(f"the FRF optimum of {eff} ({1e6 * before:.4g} µm RMS on the time records) is not the "
                         f"time records': started again from {start}")
    refine_on_time(mf, records)
    return True


def held_on_time(mf: ModelFit, records: Sequence[PreparedRecord]) -> bool:
    """Choose on the time records the large-signal parameter the frequency fit of ``mf`` held (in
    place; True when it moved).

    With one drive amplitude among the frequency fit's records the describing function's parameter
    only scales the fundamental's gain (:func:`_df_problem` holds it at the device's value, e.g.
    ``diffuse_share`` 1: a charge law that saturates at a few tenths of a volt), while the time
    records — a sweep beside a square of another power, the flattened top of the square — show how
    the strip saturates.  When the added effect is the large-signal one and the time records hold
    two amplitude levels (the law's own reveal rule; a candidate forced on records of one level is
    left as it is: eleven simulations of a 200 s record at 1 kHz cost 87 s), every other coordinate
    of its describing grid is simulated on every record with the gain profiled out in closed form
    (as :func:`start_on_time`), the best is refined between its neighbours
    (:data:`HELD_REFINE_SIMS`) and replaces the held value when it lowers the time records' sum of
    squares by more than :data:`TIME_START_GAIN`; the gain is refined and the model scored again,
    the parameter counted in its BIC.  Chosen on a strip whose double layer saturates through
    compact layers, seen with a sweep and a square of one voltage (`pnp_sweep` seed 41):
    ``nonlinear_charge`` held at ``diffuse_share`` 1 lowered the error 10.18 → 5.99 µm."""
    info, eff = mf.df_info, mf.spec.added
    if not mf.ok or not info or info.get("fitted") or info["sensitivity"] <= DF_MIN_SENSITIVITY \
            or eff is None or not spec_of(eff).get("describing_function") \
            or len({r.amplitude_level for r in records}) < 2:
        return False
    name, coords, scale = EFFECTS[eff].describing_grid(mf.device)
    if name != info["parameter"]:
        return False
    now = float(mf.device.params.get(name, declared_default(name)))

    def cost(value) -> float:
        return profiled_cost(ActuatorModel(mf.device.with_params(**{name: value}), mf.effects,
                                           n_modes=mf.model.n_modes), records)

    from scipy.optimize import minimize_scalar
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            base = cost(now)
            grid = sorted(set(coords[::2]) | {coords[-1]})     # every other one and the last, refined (log scale)
            tried = {c: cost(scale / c) for c in grid if not math.isclose(scale / c, now, rel_tol=1e-6)}
            if not tried:
                return False
            best = min(tried, key=tried.get)
            i = grid.index(best)
            lo, hi = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, len(grid) - 1)])
            sol = minimize_scalar(lambda x: cost(scale / math.exp(x)), bounds=(lo, hi), method="bounded",
                                  options={"maxiter": HELD_REFINE_SIMS, "xatol": 0.02})
            if sol.fun < tried[best]:
                best = math.exp(float(sol.x))
                tried[best] = float(sol.fun)
    except (InputError, ModelError, np.linalg.LinAlgError, FloatingPointError):
        return False
    if not tried[best] < (1.0 - TIME_START_GAIN) * base:
        return False
    before, value = mf.rmse, scale / best
    mf.device = mf.result.device = mf.device.with_params(**{name: value})
    mf.model = ActuatorModel(mf.device, mf.effects, n_modes=mf.model.n_modes)
    mf.values[name] = value
    mf.k += 1
    held = [n for n in mf.spec.notes if n.startswith(f"{name} held at ")]
    mf.spec.notes[:] = [n for n in mf.spec.notes if n not in held]
    score(mf, records)
    mf.spec.notes.append(f"{name} chosen on the time records, whose waveforms show the saturation (the frequency "
                         "fit's records hold one drive amplitude and cannot tell it from the gain): "
                         f"{now:.4g} → {value:.4g}, RMS error {1e6 * before:.4g} → {1e6 * mf.rmse:.4g} µm")
    return True


def no_worse_than_base(mf: ModelFit, base: ModelFit) -> ModelFit:
    """``mf`` — the base with a nested effect added, fitted and scored — or, when it ends worse
    than ``base`` on the time records (its FRF optimum need not be theirs), the base itself
    with the effect at its off values (the model without it, so the base's scores are exact),
    said in its notes.  A nested effect can thus never make the model worse."""
    eff = mf.spec.added
    if not mf.ok or eff is None or not is_nested(eff) or mf.rmse <= base.rmse:
        return mf
    off = off_values(eff, base.device)
    if not off:
        return mf
    dev = base.device.with_params(**off)
    kept = dataclasses.replace(
        mf, device=dev, model=ActuatorModel(dev, mf.effects, n_modes=mf.model.n_modes),
        values={k: float(dev.params.get(k, base.values.get(k, v))) for k, v in mf.values.items()},
        std_errors={k: math.nan for k in mf.values}, rel_std_errors={k: math.nan for k in mf.values},
        pred_d=list(base.pred_d), resid_d=list(base.resid_d), rss=list(base.rss), n=list(base.n),
        taus=list(base.taus), rmse_records=list(base.rmse_records), rmse=base.rmse, fit_pct=base.fit_pct,
        nuisance=list(base.nuisance), correlation=None)
    kept.spec = dataclasses.replace(mf.spec, notes=mf.spec.notes + [
        f"fitted, the model with {eff} ended worse than the model without it on the time records "
        f"({1e6 * mf.rmse:.4g} vs {1e6 * base.rmse:.4g} µm RMS): the model without it ({eff} at its off values, "
        + ", ".join(f"{k} = {v:.4g}" for k, v in off.items()) + ") is kept"])
    return kept


@dataclass
class Comparison:
    """Candidate against base on the same records (see :mod:`.stats`)."""

    delta_bic: float
    delta_aic: float
    p_value: float
    test: str
    n_eff: float
    tau: float
    dk: int


def compare_fits(base: ModelFit, cand: ModelFit, nested: bool, taus: Sequence[float] | None = None) -> Comparison:
    """ΔBIC, ΔAIC and p-value of ``cand`` against ``base``, computed on what the verdict
    reports: one Gaussian noise model over all records whose variance is the pooled mean
    square error (the squared RMS error the report prints), so the evidence and the error can
    never disagree in sign (the parameter penalty aside).  The effective sample size
    N_eff = Σ_r n_r/τ_r takes ``taus`` per record (the diagnosis passes those of the residual
    closest to noise, the best-fitting model's, so that every comparison uses one noise
    model), by default those of the candidate's residuals (module doc of :mod:`.stats`)."""
    taus = list(cand.taus if taus is None else taus)
    n_eff = float(sum(n / t for n, t in zip(cand.n, taus)))
    dk = cand.k - base.k
    kb = base.k + NUISANCE_TERMS * len(base.n)
    kc = cand.k + NUISANCE_TERMS * len(cand.n)
    ms_b, ms_c = [base.rmse ** 2], [cand.rmse ** 2]
    bb = stats.bic(ms_b, [1], [n_eff], kb)
    bc = stats.bic(ms_c, [1], [n_eff], kc)
    ab = stats.aic(ms_b, [1], [n_eff], kb)
    ac = stats.aic(ms_c, [1], [n_eff], kc)
    if nested and dk > 0:
        p = stats.lr_pvalue(ms_b, ms_c, [n_eff], dk)
        test = f"likelihood ratio, χ²({dk})"
    else:
        p = stats.vuong_pvalue(base.resid_d, cand.resid_d, taus, dk, pooled=True)
        test = "Vuong (non-nested)"
    tau = float(sum(cand.n) / n_eff)
    return Comparison(bc - bb, ac - ab, p, test, n_eff, tau, dk)


def effect_values(mf: ModelFit, effect: str) -> dict:
    """Fitted values of an effect's own parameters, of those taking over a role (kf0,
    dma_scale, ...) and, for an effect with per-RH parameters, of those."""
    spec = spec_of(effect)
    if spec.get("per_rh"):
        return {k: v for k, v in mf.values.items() if "@RH" in k}
    names = set(effect_params(effect) + shape_params(effect)) | {r[0] for r in spec.get("roles", {}).values()}
    return {k: v for k, v in mf.values.items() if k in names}



def effect_rows(mf: ModelFit, effect: str) -> dict:
    """:func:`effect_values` with their standard errors, as a verdict line gives them:
    {name: {"value", "std_error"}} (SI units)."""
    return {n: {"value": v, "std_error": mf.std_errors.get(n)} for n, v in effect_values(mf, effect).items()}


def prediction_distance(a: ModelFit, b: ModelFit) -> float:
    """RMS difference [m] between two fitted models' predictions (decimated, offsets removed)."""
    sq, cnt = 0.0, 0
    for pa, pb in zip(a.pred_d, b.pred_d):
        d = remove_nuisance(pa - pb)
        sq += float(d @ d)
        cnt += d.size
    return math.sqrt(sq / max(cnt, 1))


__all__ = ["default_candidates", "ModelSpec", "ModelFit", "Comparison", "candidate_spec", "removal_spec", "fit_model",
           "score", "no_worse_than_base", "refine_on_time", "polish_on_time", "compare_fits", "default_free", "map_free", "param_used", "predict", "prediction_distance"]
