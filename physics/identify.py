"""Parameter identification from measurements, with honest uncertainty.

Given measurements (time-series records and/or frequency-response files), a device
with a set of effects and the names of the free parameters, :func:`identify` finds the
parameter values that make the model reproduce the measured frequency response.

**Data.**  Each time record is turned into an H1 frequency-response estimate
(:func:`physics.compare.estimate_record_frf`, settings from its excitation; excited
frequencies with coherence ≥ ``min_coherence``, thinned to about ``max_points``
log-spaced lines); frequency-response files are used as they are.  Known sensor
dynamics (a first-order low-pass, see :mod:`physics.compare`) multiply the model.

**Methods.**

``"nelder-mead"`` — the thesis procedure, reproducible (De Luca 2014, ch. 1 §5):
    Nelder–Mead simplex (Nelder & Mead, Computer Journal 7:308, 1965;
    :func:`scipy.optimize.minimize`, the algorithm of MATLAB ``fminsearch``) on the cost
    of eq. 13, J_err = sqrt(Σ_i (|δ_exp(f_i)| − |δ_sim(f_i)|)²/N), FRF magnitudes only,
    at most 100 iterations, tolerance 1e-6 on parameters and cost.  The thesis does not
    say in which units the tolerance applies; here the parameters are divided by their
    start values (the initial simplex is the start plus 5 % of each component, as in
    ``fminsearch``; 0.00025 for a zero start) and J_err by the RMS measured magnitude, so
    both tolerances are relative and unit-independent.  Bounds clip the simplex.

``"lsq"`` (default) — bounded nonlinear least squares (:func:`scipy.optimize.least_squares`,
    trust-region reflective) on the complex FRF: the residual at frequency f_i is
    w_i · ln(Ĥ_model(f_i)/Ĥ_meas(f_i)), whose real part is the log-magnitude error and
    imaginary part the (wrapped) phase error in rad — the two are on the same relative
    scale.  With ``weighting="coherence"`` w_i = 1/ε_i, ε the Bendat–Piersol random error
    of the H1 estimate (std of ln|Ĥ| and of the phase; median-smoothed over 9 lines,
    floored at 1e-4), so the weighted residuals are about N(0, 1); without coherence (or
    with ``"uniform"``) w_i = 1.  ``residual="time"`` fits the time records instead
    (simulated output minus measurement, best offset removed, in units of the
    measurement's standard deviation); ``"both"`` stacks the two blocks, each scaled to
    the same total weight.  Parameters are searched in log space (ln θ; fractional
    orders and other dimensionless quantities bounded within [0, 1] in linear space)
    within bounds from the parameter specifications, narrowed by default to three
    decades either side of the start.  Multi-start: the start plus ``n_starts − 1``
    Latin-hypercube points within ``start_spread`` decades of it (the whole range for
    linear parameters); the lowest cost wins and every start is reported.

**Uncertainty** (Bates & Watts, *Nonlinear Regression Analysis and its Applications*,
Wiley 1988, §2.3; linear approximation at the optimum).  With the weighted residual
vector r (n values) and its Jacobian J = ∂r/∂x in the search coordinates x (central
differences), the residual variance s² = ‖r‖²/(n − p) scales the covariance

    Cov(x̂) = s² (JᵀJ)⁻¹,    computed as s² V S⁻² Vᵀ from the SVD J = U S Vᵀ,

so the standard errors are right whatever the absolute level of the weights (and s²
itself — the reduced chi-square — should be ≈ 1 with coherence weights when the model is
adequate).  For a log parameter the standard error of θ is θ·se(ln θ) (delta method) and
the 95 % interval θ·exp(±t se) (Student t, n − p degrees of freedom); for a linear one
θ ± t se.  Time residuals are autocorrelated: their covariance is multiplied by the
integrated autocorrelation time of the residuals (effective number of independent
samples).  Correlations are Cov_ij/sqrt(Cov_ii Cov_jj).  A parameter is flagged **not
identifiable** (an :class:`IdentifiabilityWarning`, also listed in the result) when its
relative standard error exceeds 50 %, when a correlation exceeds 0.98 in magnitude
(only a combination is determined), when JᵀJ is near-singular (condition number of J
above 1e7; the parameters in the weakest direction are named) or when it ends on a bound
(its interval is then not meaningful).  A parameter that does not change the frequency
response at all is refused before an FRF fit (:class:`~physics.errors.InputError`).

**Humidity (joint fits).**  Records at several RH levels (grouped within
``rh_tolerance`` %) are fitted together.  Two designs, which can be combined:

* ``free``: one value shared by all records.  With the ``humidity`` effect on and a
  ``ratio`` map for that parameter in the device (Table V as shipped), the value fitted
  is the one at the device's reference RH and the map's shape carries it to every RH.
* ``per_rh``: Table V style — one free value of the parameter at each RH level present in
  the data.  They become an ``absolute`` humidity map of that parameter with the data's
  RH levels as nodes (replacing any map it had), so the model at level k uses exactly
  the k-th value; between levels it is interpolated linearly, outside held at the ends.
  Needs the ``humidity`` effect and records at two or more RH levels.  For ``Y`` the map
  scales whichever modulus is active (an absolute ``Y`` value divided by the device's
  ``Y``, e.g. the DMA table with ``viscoelastic``), for ``kf`` it scales ``kf0`` as well.

:func:`write_identification` writes the fitted device (same schema as
``configs/devices/*.yaml``, each identified value with its unit and a source "identified
by eap identify from FILES on DATE"), ``report.json``, CSV tables, PNGs and one
self-contained HTML page.
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import difflib
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import yaml
from scipy import optimize, stats
from scipy.ndimage import median_filter

from .compare import (FRFOptions, cluster_rh, estimate_record_frf, load_measurements, model_rh,
                      sensor_bandwidth_of, sensor_lowpass, sensor_response, source_name, thin_log,
                      valid_points)
from .device import Device, HumidityMap, all_param_specs, load_device, parse_device
from .errors import InputError, ModelError
from .frequency import response_per_volt
from .frfdata import FRFData
from .model import ActuatorModel, resolve_effects
from .parameters import BASE_SECTIONS
from .threads import single_threaded
from .timeseries import TimeSeries
from .units import to_si

#: Thesis cost of one model evaluation: COMSOL, 15 min per frequency (PHYSICS.md §1).
THESIS_SECONDS_PER_FREQUENCY = 15 * 60.0
#: Thesis Nelder–Mead settings (ch. 1 §5).
THESIS_MAX_ITER = 100
THESIS_TOL = 1e-6

REL_SE_LIMIT = 0.5        # relative standard error above which a parameter is flagged
CORR_LIMIT = 0.98         # |correlation| above which a pair is flagged
COND_LIMIT = 1e7          # condition number of J above which JᵀJ is near-singular
EPS_FLOOR = 1e-4          # floor of the relative random error used as weight
DEFAULT_DECADES = 3.0     # default search range either side of the start (log parameters)

#: Why a parameter may have no effect, by name (shown when it is refused).
_HINTS = {
    "Y": "Y sets the modulus only with viscoelastic off (the DMA table does otherwise) and "
         "without layered_beam (Y_polymer then); with humidity it can be fitted per RH (per_rh)",
    "Y_polymer": "Y_polymer is used only with layered_beam and viscoelastic off",
    "Y_electrode": "Y_electrode is used only with layered_beam",
    "kf": "with fractional_coupling on, the load is kf0/((j2πf)^a (j2πf+p)^b) and kf is unused "
          "(a humidity map on kf then acts as a ratio on kf0)",
    "kf0": "kf0 is used only with fractional_coupling",
    "frac_a": "fractional orders are used only with fractional_coupling",
    "frac_b": "frac_b is used only with fractional_coupling",
    "frac_p": "frac_p has no effect when frac_b = 0",
    "D_solvent": "D_solvent is used only with solvent_diffusion",
    "Rs": "Rs is used only with electrode_resistance",
    "C_max": "C_max acts only in the large-signal (time-domain) response of nonlinear_charge",
}


class IdentifiabilityWarning(UserWarning):
    """A parameter is not (or poorly) determined by the data."""


# ============================================================================ parameters


def _section_of() -> dict[str, str]:
    from .effects import EFFECTS
    out = {}
    for sec, specs in BASE_SECTIONS.items():
        for k in specs:
            out[k] = sec
    for eff in EFFECTS.values():
        for p in eff.params:
            out[p.name] = eff.id
    return out


@dataclass
class FreeParameter:
    """A free parameter in SI units. ``scale`` ``"log"`` searches x = ln θ, ``"linear"``
    x = θ; ``rh`` is the RH level [%] of a per-RH value (None: shared)."""

    name: str
    initial: float
    lower: float
    upper: float
    scale: str
    unit: str
    rh: float | None = None

    @property
    def label(self) -> str:
        return self.name if self.rh is None else f"{self.name}@RH{self.rh:g}"

    def to_x(self, theta):
        return np.log(theta) if self.scale == "log" else np.asarray(theta, dtype=float)

    def from_x(self, x):
        return np.exp(x) if self.scale == "log" else np.asarray(x, dtype=float)

    @property
    def x_bounds(self) -> tuple[float, float]:
        return float(self.to_x(self.lower)), float(self.to_x(self.upper))


def parse_names(text: str | Sequence[str] | None, what: str = "--free") -> list[str]:
    """``"kf,beta_f"`` or a list → names (duplicates refused)."""
    if text is None:
        return []
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if str(n).strip()]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{what}: parameter(s) {', '.join(dup)} given twice")
    return names


def _value_with_unit(text: str, name: str, spec_unit: str, where: str) -> float:
    parts = text.strip().split(None, 1)
    try:
        v = float(parts[0])
    except (ValueError, IndexError):
        raise InputError(f"{where}: {name}={text!r}: expected a number, optionally followed by a unit "
                         f"(SI unit {spec_unit!r})") from None
    if len(parts) == 2:
        try:
            v = to_si(v, parts[1], spec_unit)
        except Exception as exc:
            raise InputError(f"{where}: {name}={text!r}: {exc}") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: {name}={text!r} is not finite")
    return float(v)


def parse_assignments(text: str | Mapping | None, *, ranges: bool = False, what: str = "--start") -> dict:
    """``"kf=0.004,Y=0.2 GPa"`` → {name: SI value}; with ``ranges`` ``"kf=1e-4:1e-1"`` →
    {name: (lo, hi)} (a unit after the range applies to both ends).  SI when no unit."""
    if text is None:
        return {}
    specs = all_param_specs()
    items = text.items() if isinstance(text, Mapping) else \
        [tuple(s.split("=", 1)) if "=" in s else (s, None) for s in text.split(",") if s.strip()]
    out = {}
    for name, val in items:
        name = str(name).strip()
        if val is None:
            raise InputError(f"{what}: item {name!r} must look like name=value")
        if name not in specs:
            raise InputError(f"{what}: unknown parameter {name!r}{_suggest(name, specs)}")
        unit = specs[name].unit
        if ranges:
            if isinstance(val, (tuple, list)):
                lo, hi = (float(v) for v in val)
            else:
                body, _, u = str(val).strip().partition(" ")
                if ":" not in body:
                    raise InputError(f"{what}: {name}={val!r}: expected lo:hi, e.g. {name}=1e-4:1e-1")
                a, b = body.split(":", 1)
                lo = _value_with_unit(f"{a} {u}".strip(), name, unit, what)
                hi = _value_with_unit(f"{b} {u}".strip(), name, unit, what)
            if not lo < hi:
                raise InputError(f"{what}: {name}: lower bound {lo:g} must be below upper bound {hi:g}")
            out[name] = (lo, hi)
        else:
            out[name] = float(val) if isinstance(val, (int, float)) else _value_with_unit(str(val), name, unit, what)
    return out


def _suggest(key: str, known) -> str:
    close = difflib.get_close_matches(key, list(known), n=3)
    return f" (did you mean {', '.join(close)}?)" if close else ""


def _default_scale(spec) -> str:
    return "linear" if (spec.unit == "1" and spec.lo >= 0 and spec.hi <= 1) else "log"


def _make_param(name, initial, spec, bounds, rh=None) -> FreeParameter:
    scale = _default_scale(spec)
    where = f"parameter {name}" + (f" at RH {rh:g} %" if rh is not None else "")
    if bounds is not None:
        lo, hi = bounds
        if lo < spec.lo or hi > spec.hi:
            raise InputError(f"bounds of {name}: [{lo:g}, {hi:g}] {spec.unit} leave the admissible range "
                             f"[{spec.lo:g}, {spec.hi:g}] {spec.unit}")
    elif scale == "log":
        if initial <= 0:
            raise InputError(f"{where}: start value {initial:g} {spec.unit} is not positive; it is searched "
                             f"in log space: give a positive start value (start={{'{name}': ...}} / --start)")
        lo = max(spec.lo, initial * 10 ** -DEFAULT_DECADES)
        hi = min(spec.hi, initial * 10 ** DEFAULT_DECADES)
    else:
        lo, hi = spec.lo, spec.hi
    if scale == "log" and lo <= 0:
        if bounds is not None:
            raise InputError(f"bounds of {name}: the lower bound must be positive (log-space search)")
    if not (lo <= initial <= hi):
        raise InputError(f"{where}: start value {initial:g} {spec.unit} is outside its bounds "
                         f"[{lo:g}, {hi:g}] {spec.unit}")
    return FreeParameter(name, float(initial), float(lo), float(hi), scale, spec.unit, rh)


# ============================================================================ targets


@dataclass
class FRFTarget:
    """One measured frequency response to fit: ``freq`` Hz, ``response`` complex m/V,
    ``weight`` per frequency (relative), ``rh`` the RH level [%] the model is evaluated at."""

    source: str
    freq: np.ndarray
    response: np.ndarray
    weight: np.ndarray
    rh: float
    coherence: np.ndarray | None
    sensor_bandwidth: float | None
    estimator: dict
    record: TimeSeries | None = None
    rh_model: object = None          # RH given to the time solver (constant or smoothed series)

    @property
    def s(self) -> np.ndarray:
        return 2j * np.pi * self.freq


def _weights(eps: np.ndarray | None, n: int, weighting: str) -> np.ndarray:
    if weighting == "uniform" or eps is None:
        return np.ones(n)
    e = np.where(np.isfinite(eps), eps, np.nan)
    if np.all(np.isnan(e)):
        return np.ones(n)
    e = np.where(np.isnan(e), np.nanmax(e), e)
    e = median_filter(e, size=min(9, max(1, n)), mode="nearest")
    return 1.0 / np.maximum(e, EPS_FLOOR)


def build_targets(measurements: Sequence, *, frf_options: FRFOptions | None = None,
                  min_coherence: float = 0.0, weighting: str = "coherence", rh_tolerance: float = 2.5,
                  sensor_bandwidth="auto", default_rh: float | None = None) -> list[FRFTarget]:
    """FRF targets from loaded measurements (see the module doc)."""
    if weighting not in ("coherence", "uniform"):
        raise InputError(f"weighting {weighting!r}: expected 'coherence' or 'uniform'")
    if not 0 <= min_coherence <= 1:
        raise InputError(f"min_coherence={min_coherence!r} must lie within 0–1")
    opts = frf_options or FRFOptions()
    raw = []
    for k, m in enumerate(measurements):
        where = source_name(m, k)
        bw = sensor_bandwidth_of(m, sensor_bandwidth)
        if isinstance(m, TimeSeries):
            if m.deflection is None:
                raise InputError(f"{where}: no deflection; identification needs measured deflection_m")
            rh = m.rh if m.rh is not None else (None if default_rh is None else np.full(m.n, default_rh))
            if rh is None:
                raise InputError(f"{where}: no relative humidity; add an rh_pct column or give the RH")
            est, info = estimate_record_frf(m, m.deflection, opts)
            ok = valid_points(est, min_coherence)
            idx = np.flatnonzero(ok)
            if idx.size == 0:
                raise InputError(f"{where}: no usable frequency (excited, coherence ≥ {min_coherence:g})")
            idx = idx[thin_log(est.freq[idx], opts.max_points)]
            eps = est.rel_error[idx]
            raw.append(dict(source=where, freq=est.freq[idx], response=est.response[idx],
                            eps=eps, rh=float(np.median(rh)), coherence=est.coherence[idx], bw=bw,
                            estimator=info, record=m, rh_series=rh))
        elif isinstance(m, FRFData):
            if m.rh is None and default_rh is None:
                raise InputError(f"{where}: the FRF file has no rh_pct column; give the RH explicitly")
            rh = float(np.mean(m.rh)) if m.rh is not None else float(default_rh)
            ok = np.ones(m.freq.size, bool)
            if m.coherence is not None and min_coherence > 0:
                ok &= m.coherence >= min_coherence
            ok &= np.abs(m.response) > 0
            idx = np.flatnonzero(ok)
            if idx.size == 0:
                raise InputError(f"{where}: no usable frequency (non-zero magnitude, coherence ≥ {min_coherence:g})")
            idx = idx[thin_log(m.freq[idx], opts.max_points)]
            eps = None
            if m.coherence is not None:
                g = np.clip(m.coherence[idx], 1e-12, 1.0)
                eps = np.sqrt(1 - g) / np.sqrt(2 * g)
            raw.append(dict(source=where, freq=m.freq[idx], response=m.response[idx], eps=eps, rh=rh,
                            coherence=None if m.coherence is None else m.coherence[idx], bw=bw,
                            estimator={"method": "file"}, record=None, rh_series=None))
        else:
            raise InputError(f"{where}: expected a TimeSeries or FRFData, got {type(m).__name__}")
    if not raw:
        raise InputError("no measurement given")
    levels = cluster_rh([r["rh"] for r in raw], rh_tolerance)
    out = []
    for r, lv in zip(raw, levels):
        rec = r["record"]
        out.append(FRFTarget(r["source"], r["freq"], r["response"], _weights(r["eps"], r["freq"].size, weighting),
                             lv, r["coherence"], r["bw"], r["estimator"], rec,
                             None if rec is None else model_rh(r["rh_series"], rec.fs, rh_tolerance)))
    return out


# ============================================================================ the problem


class IdentificationProblem:
    """Model evaluation for a set of free parameters (SI values θ or search coordinates x).

    ``free``: names of shared parameters; ``per_rh``: names fitted per RH level (see the
    module doc); ``start`` {name: SI} overrides start values; ``bounds`` {name: (lo, hi)}
    the search ranges; ``fit_phase`` False fits log-magnitudes only."""

    def __init__(self, device, effects, targets: Sequence[FRFTarget], free: Sequence[str] = (),
                 per_rh: Sequence[str] = (), *, start: Mapping[str, float] | None = None,
                 bounds: Mapping[str, tuple[float, float]] | None = None, n_modes: int = 4,
                 fit_phase: bool = True, residual: str = "frf", skip_s: float = 0.0):
        self.device = load_device(device)
        self.effects = resolve_effects(effects, self.device)
        self.n_modes = int(n_modes)
        self.targets = list(targets)
        if not self.targets:
            raise InputError("no measurement to fit")
        if residual not in ("frf", "time", "both"):
            raise InputError(f"residual {residual!r}: expected frf, time or both")
        self.residual = residual
        self.fit_phase = bool(fit_phase)
        self.skip_s = float(skip_s)
        if residual in ("time", "both"):
            bad = [t.source for t in self.targets if t.record is None]
            if residual == "time" and bad:
                raise InputError(f"residual='time' needs time-series records; {bad[0]} is a frequency-response file")
        free, per_rh = list(free), list(per_rh)
        if not free and not per_rh:
            raise InputError("no free parameter: name at least one (e.g. --free kf,beta_f)")
        both = sorted(set(free) & set(per_rh))
        if both:
            raise InputError(f"{', '.join(both)}: a parameter is either shared (--free) or per RH (--per-rh), not both")
        specs = all_param_specs()
        start = dict(start or {})
        bounds = dict(bounds or {})
        for name in list(start) + list(bounds):
            if name not in free and name not in per_rh:
                raise InputError(f"start value or bounds given for {name!r}, which is not a free parameter")
        for name in free + per_rh:
            if name not in specs:
                raise InputError(f"unknown parameter {name!r}{_suggest(name, specs)}")
        # RH levels
        self.levels = sorted({t.rh for t in self.targets})
        self.model0 = ActuatorModel(self.device, self.effects, n_modes=self.n_modes)
        hum_on = self.model0.components["humidity"].enabled
        if per_rh:
            if not hum_on:
                raise InputError(f"per-RH parameters ({', '.join(per_rh)}) need the humidity effect: add "
                                 "'humidity' to the effects")
            if len(self.levels) < 2:
                raise InputError(f"per-RH parameters ({', '.join(per_rh)}) need records at two or more RH levels; "
                                 f"all records are at RH {self.levels[0]:g} %")
        self.params: list[FreeParameter] = []
        for name in free:
            if name in start:
                v0 = start[name]
            elif name in self.device.params:
                v0 = self.device.params[name]
            else:
                raise InputError(f"device {self.device.name!r} has no value for {name!r}; give a start value "
                                 f"(start={{'{name}': ...}} / --start {name}=...)")
            self.params.append(_make_param(name, v0, specs[name], bounds.get(name)))
        for name in per_rh:
            for lv in self.levels:
                if name in start:
                    v0 = start[name]
                else:
                    v0 = self._effective_value(name, lv)
                self.params.append(_make_param(name, v0, specs[name], bounds.get(name), rh=lv))
        self.free, self.per_rh = free, per_rh
        self.n_eval = 0
        if residual == "frf":      # a time fit may use large-signal parameters the FRF does not see
            self._check_params_used()

    # --- parameter vectors -----------------------------------------------------------------
    @property
    def labels(self) -> list[str]:
        return [p.label for p in self.params]

    @property
    def theta0(self) -> np.ndarray:
        return np.array([p.initial for p in self.params])

    def to_x(self, theta) -> np.ndarray:
        return np.array([p.to_x(t) for p, t in zip(self.params, theta)], dtype=float)

    def from_x(self, x) -> np.ndarray:
        return np.array([p.from_x(v) for p, v in zip(self.params, x)], dtype=float)

    @property
    def x_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        b = np.array([p.x_bounds for p in self.params])
        return b[:, 0], b[:, 1]

    def _effective_value(self, name: str, rh: float) -> float:
        if name not in self.device.params:
            raise InputError(f"device {self.device.name!r} has no value for {name!r}; give a start value")
        if name == "Y":
            return float(self.device.params["Y"] * self.model0.components["humidity"].stiffness_factor(rh))
        return float(self.model0.params_at(rh)[name])

    def device_for(self, theta) -> Device:
        """The device with parameters θ (SI) applied (per-RH values as absolute maps)."""
        theta = np.asarray(theta, dtype=float)
        shared = {p.name: float(v) for p, v in zip(self.params, theta) if p.rh is None}
        dev = self.device.with_params(**shared) if shared else self.device
        if self.per_rh:
            maps = dict(dev.humidity_maps)
            for name in self.per_rh:
                vals = np.array([v for p, v in zip(self.params, theta) if p.name == name and p.rh is not None])
                maps[name] = HumidityMap(name, np.array(self.levels, dtype=float), vals, "absolute",
                                         "identified per RH")
            dev = dataclasses.replace(dev, humidity_maps=maps)
        return dev

    def model_for(self, theta) -> ActuatorModel:
        return ActuatorModel(self.device_for(theta), self.effects, n_modes=self.n_modes)

    # --- model evaluations -------------------------------------------------------------------
    def responses(self, theta) -> list[np.ndarray]:
        """Model FRF [m/V] (sensor included) at each target's frequencies."""
        model = self.model_for(theta)
        self.n_eval += 1
        out = []
        for t in self.targets:
            H = response_per_volt(model, t.s, t.rh)[0]
            out.append(H * sensor_response(t.freq, t.sensor_bandwidth))
        return out

    def frf_residuals(self, theta) -> np.ndarray:
        """Weighted complex-log residuals, real and imaginary parts stacked."""
        parts = []
        for t, H in zip(self.targets, self.responses(theta)):
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = H / t.response
            if not np.all(np.isfinite(ratio)) or np.any(ratio == 0):
                ratio = np.where(np.isfinite(ratio) & (ratio != 0), ratio, 1e-30)
            lr = np.log(ratio)
            parts.append(t.weight * lr.real)
            if self.fit_phase:
                parts.append(t.weight * lr.imag)
        return np.concatenate(parts)

    def magnitude_residuals(self, theta) -> np.ndarray:
        """|H_model| − |H_meas| [m/V] over all targets (the residuals of eq. 13)."""
        return np.concatenate([np.abs(H) - np.abs(t.response) for t, H in zip(self.targets, self.responses(theta))])

    def j_err(self, theta) -> float:
        """Thesis cost eq. 13 over every fitted frequency [m/V]."""
        r = self.magnitude_residuals(theta)
        return float(np.sqrt(np.mean(r ** 2)))

    def time_residuals(self, theta) -> np.ndarray:
        """(ŷ − y − mean)/std(y) for each time record after ``skip_s``, stacked."""
        from .timedomain import simulate
        model = self.model_for(theta)
        self.n_eval += 1
        parts = []
        for t in self.targets:
            ts = t.record
            if ts is None:
                continue
            v = ts.voltage
            tt = np.arange(v.size) / ts.fs
            y_hat = simulate(model, None, tt, v, rh=t.rh_model, hold="cubic").deflection
            y_hat = sensor_lowpass(y_hat, ts.fs, t.sensor_bandwidth)
            i0 = int(math.ceil(self.skip_s * ts.fs))
            e = (y_hat - ts.deflection)[i0:]
            e = e - e.mean()
            parts.append(e / np.std(ts.deflection[i0:]))
        return np.concatenate(parts)

    def residuals(self, theta) -> np.ndarray:
        if self.residual == "frf":
            return self.frf_residuals(theta)
        if self.residual == "time":
            return self.time_residuals(theta)
        a, b = self.frf_residuals(theta), self.time_residuals(theta)
        return np.concatenate([a, b * math.sqrt(a.size / b.size)])

    def residuals_x(self, x) -> np.ndarray:
        return self.residuals(self.from_x(x))

    def normalised_jerr(self, z, scale) -> float:
        return self.j_err(z * scale) / self._mag_rms

    @property
    def _mag_rms(self) -> float:
        return float(np.sqrt(np.mean(np.concatenate([np.abs(t.response) ** 2 for t in self.targets]))))

    # --- checks ----------------------------------------------------------------------------
    def _check_params_used(self) -> None:
        """Refuse parameters that leave the frequency response unchanged."""
        x0 = self.to_x(self.theta0)
        base = np.concatenate(self.responses(self.theta0))
        scale = np.max(np.abs(base))
        lo, hi = self.x_bounds
        for i, p in enumerate(self.params):
            x = x0.copy()
            step = 0.05 if p.scale == "log" else 0.05 * (hi[i] - lo[i])
            x[i] = x0[i] + step if x0[i] + step <= hi[i] else x0[i] - step
            H = np.concatenate(self.responses(self.from_x(x)))
            if np.max(np.abs(H - base)) <= 1e-10 * scale:
                hint = _HINTS.get(p.name, "")
                raise InputError(f"parameter {p.label} has no effect on the frequency response of "
                                 f"{self.device.name!r} with effects [{', '.join(self.effects)}]"
                                 + (f": {hint}" if hint else "") + "; choose other free parameters or effects")


# ============================================================================ fitting


@dataclass
class Fit:
    """One fit's result: values θ (SI), search coordinates x, uncertainties and diagnostics."""

    method: str
    theta: np.ndarray
    x: np.ndarray
    cost: float                     # 0.5‖r‖² of the method's own residual (J_err for Nelder–Mead)
    j_err: float                    # eq. 13 at θ [m/V]
    nfev: int                       # model evaluations (finite-difference ones included)
    nit: int | None
    success: bool
    message: str
    wall_s: float
    std_error: np.ndarray           # SI, 1σ (inf when not determined)
    rel_std_error: np.ndarray
    ci95: np.ndarray                # (p, 2) SI
    correlation: np.ndarray         # (p, p), NaN when undetermined
    singular_values: np.ndarray
    condition: float
    s2: float                       # residual variance (reduced chi-square with coherence weights)
    dof: int
    warnings: list[str] = field(default_factory=list)
    starts: list[dict] = field(default_factory=list)
    residual_kind: str = ""


def jacobian(fun, x, steps) -> tuple[np.ndarray, np.ndarray]:
    """(r(x), central-difference Jacobian ∂r/∂x) with per-coordinate ``steps``."""
    r0 = fun(x)
    J = np.empty((r0.size, x.size))
    for i in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[i] += steps[i]
        xm[i] -= steps[i]
        J[:, i] = (fun(xp) - fun(xm)) / (2 * steps[i])
    return r0, J


def _autocorr_time(e: np.ndarray, max_lag: int = 2000) -> float:
    """Integrated autocorrelation time 1 + 2 Σ ρ_k (summed until ρ first drops below 0.05)."""
    e = e - e.mean()
    n = e.size
    if n < 4 or not np.any(e):
        return 1.0
    f = np.fft.rfft(e, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:min(n, max_lag)]
    ac /= ac[0]
    tau = 1.0
    for k in range(1, ac.size):
        if ac[k] < 0.05:
            break
        tau += 2 * ac[k]
    return float(tau)


def uncertainty(problem: IdentificationProblem, x: np.ndarray, fun, *, inflate: float = 1.0,
                labels: Sequence[str] | None = None) -> dict:
    """Bates–Watts linearised uncertainty at ``x`` for residual function ``fun(x)`` (see
    the module doc).  Returns std errors (x and SI), correlations, s², singular values,
    condition number and the list of identifiability warnings."""
    params = problem.params
    labels = list(labels or problem.labels)
    lo, hi = problem.x_bounds
    steps = np.array([1e-4 if p.scale == "log" else 1e-4 * max(hi[i] - lo[i], 1e-12)
                      for i, p in enumerate(params)])
    # keep the stencil inside the bounds
    xc = np.clip(x, lo + steps, hi - steps)
    r, J = jacobian(fun, xc, steps)
    n, p = J.shape
    dof = n - p
    if dof <= 0:
        raise InputError(f"{n} residuals cannot determine {p} parameters; give more frequencies or records")
    s2 = float(r @ r / dof) * inflate
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    smax = S[0] if S.size and S[0] > 0 else 1.0
    good = S > smax * 1e-12
    inv_s2 = np.where(good, 1.0 / np.where(good, S, 1.0) ** 2, np.inf)
    cond = float(smax / S[-1]) if S[-1] > 0 else math.inf
    with np.errstate(invalid="ignore", over="ignore"):
        if np.all(good):
            cov = s2 * (Vt.T * inv_s2) @ Vt
        else:
            cov = np.full((p, p), np.nan)
            cov_g = s2 * (Vt[good].T * inv_s2[good]) @ Vt[good]
            for i in range(p):
                for j in range(p):
                    cov[i, j] = cov_g[i, j]
            weak = np.abs(Vt[~good]).max(axis=0) > 1e-3
            for i in np.flatnonzero(weak):
                cov[i, :] = np.nan
                cov[:, i] = np.nan
                cov[i, i] = np.inf
    se_x = np.sqrt(np.diag(cov))
    theta = problem.from_x(x)
    tq = float(stats.t.ppf(0.975, dof))
    se, rel, ci = np.empty(p), np.empty(p), np.empty((p, 2))
    for i, par in enumerate(params):
        if par.scale == "log":
            se[i] = theta[i] * se_x[i]
            rel[i] = se_x[i]
            with np.errstate(over="ignore", invalid="ignore"):
                ci[i] = theta[i] * np.exp(-tq * se_x[i]), theta[i] * np.exp(tq * se_x[i])
        else:
            se[i] = se_x[i]
            ref = abs(theta[i]) if abs(theta[i]) > 1e-3 * (par.upper - par.lower) else (par.upper - par.lower)
            rel[i] = se_x[i] / ref
            ci[i] = theta[i] - tq * se_x[i], theta[i] + tq * se_x[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    warns = []
    for i, lab in enumerate(labels):
        if not np.isfinite(rel[i]) or rel[i] > REL_SE_LIMIT:
            warns.append(f"{lab} is not identifiable from these data: relative standard error "
                         f"{'∞' if not np.isfinite(rel[i]) else f'{100 * rel[i]:.3g} %'} (> {100 * REL_SE_LIMIT:g} %)")
        if x[i] <= lo[i] + 1e-6 * max(1.0, abs(lo[i])) or x[i] >= hi[i] - 1e-6 * max(1.0, abs(hi[i])):
            warns.append(f"{lab} ended on a bound of its search range [{params[i].lower:g}, {params[i].upper:g}] "
                         f"{params[i].unit}: widen the bounds or fix it; its interval is not meaningful")
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORR_LIMIT:
                warns.append(f"{labels[i]} and {labels[j]} are strongly correlated (ρ = {corr[i, j]:+.4f}): "
                             "only a combination of them is determined by these data")
    if not math.isfinite(cond) or cond > COND_LIMIT:
        v = Vt[-1]
        names = [labels[i] for i in np.argsort(-np.abs(v)) if abs(v[i]) > 0.2]
        warns.append(f"the Jacobian is near-singular (condition number {cond:.3g}); the weakest direction "
                     f"involves {', '.join(names)}")
    return {"r": r, "J": J, "s2": s2, "dof": dof, "se_x": se_x, "std_error": se, "rel_std_error": rel,
            "ci95": ci, "correlation": corr, "singular_values": S, "condition": cond, "warnings": warns}


def _starts(problem: IdentificationProblem, n_starts: int, seed: int, spread: float) -> list[np.ndarray]:
    x0 = problem.to_x(problem.theta0)
    lo, hi = problem.x_bounds
    out = [x0]
    if n_starts <= 1:
        return out
    sampler = stats.qmc.LatinHypercube(d=x0.size, seed=seed)
    u = sampler.random(n_starts - 1)
    for row in u:
        x = np.empty_like(x0)
        for i, p in enumerate(problem.params):
            if p.scale == "log":
                a = max(lo[i], x0[i] - spread * math.log(10))
                b = min(hi[i], x0[i] + spread * math.log(10))
            else:
                a, b = lo[i], hi[i]
            x[i] = a + row[i] * (b - a)
        out.append(x)
    return out


def _interior(x, lo, hi):
    span = hi - lo
    return np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)


def fit_lsq(problem: IdentificationProblem, *, n_starts: int = 5, seed: int = 0, start_spread: float = 1.0,
            max_nfev: int | None = None, extra_starts: Sequence[Sequence[float]] = ()) -> Fit:
    """Bounded multi-start least squares (see the module doc).  ``extra_starts``: further
    start points θ (SI, one value per free parameter, in ``problem.labels`` order) tried
    after the usual ones (e.g. a grid over a parameter whose scale is unknown)."""
    t0 = time.perf_counter()
    n0 = problem.n_eval
    lo, hi = problem.x_bounds
    best, starts = None, []
    points = _starts(problem, n_starts, seed, start_spread)
    for th in extra_starts:
        th = np.asarray(th, dtype=float)
        if th.shape != (len(problem.params),):
            raise InputError(f"extra start {th.tolist()} needs one value per free parameter ({', '.join(problem.labels)})")
        points.append(problem.to_x(th))
    for k, xs in enumerate(points):
        xs = _interior(xs, lo, hi)
        try:
            res = optimize.least_squares(problem.residuals_x, xs, bounds=(lo, hi), method="trf",
                                         x_scale=1.0, max_nfev=max_nfev or 100 * xs.size)
        except (ModelError, FloatingPointError) as exc:  # a start where the model cannot be solved
            starts.append({"start": k, "theta_start": problem.from_x(xs).tolist(), "error": str(exc)})
            continue
        starts.append({"start": k, "theta_start": problem.from_x(xs).tolist(),
                       "theta": problem.from_x(res.x).tolist(), "cost": float(res.cost),
                       "nfev": int(res.nfev), "status": int(res.status)})
        if best is None or res.cost < best.cost:
            best = res
    if best is None:
        raise ModelError("every start of the least-squares fit failed: " + "; ".join(s.get("error", "") for s in starts))
    x = best.x
    inflate = 1.0
    if problem.residual == "time":
        inflate = _autocorr_time(problem.residuals_x(x))
    unc = uncertainty(problem, x, problem.residuals_x, inflate=inflate)
    theta = problem.from_x(x)
    return Fit("lsq", theta, x, float(best.cost), problem.j_err(theta), problem.n_eval - n0, None,
               bool(best.success), str(best.message), time.perf_counter() - t0, unc["std_error"],
               unc["rel_std_error"], unc["ci95"], unc["correlation"], unc["singular_values"], unc["condition"],
               unc["s2"], unc["dof"], unc["warnings"], starts,
               {"frf": "complex log FRF", "time": "time record", "both": "complex log FRF + time record"}[problem.residual]
               + (f" (covariance × {inflate:.3g}, residual autocorrelation time)" if inflate != 1.0 else ""))


def fit_nelder_mead(problem: IdentificationProblem, *, max_iter: int = THESIS_MAX_ITER,
                    tol: float = THESIS_TOL) -> Fit:
    """The thesis procedure: Nelder–Mead on J_err (eq. 13), see the module doc."""
    t0 = time.perf_counter()
    n0 = problem.n_eval
    theta0 = problem.theta0
    scale = np.where(theta0 != 0, np.abs(theta0), 1.0)
    bnds = [(p.lower / s, p.upper / s) for p, s in zip(problem.params, scale)]
    res = optimize.minimize(lambda z: problem.normalised_jerr(z, scale), theta0 / scale, method="Nelder-Mead",
                            bounds=bnds, options={"maxiter": max_iter, "xatol": tol, "fatol": tol,
                                                  "adaptive": False})
    theta = res.x * scale
    # uncertainty with the residuals of eq. 13 (|H_model| − |H_meas|), in the search coordinates
    unc = uncertainty(problem, problem.to_x(theta), lambda x: problem.magnitude_residuals(problem.from_x(x)))
    return Fit("nelder-mead", theta, problem.to_x(theta), float(res.fun * problem._mag_rms), problem.j_err(theta),
               problem.n_eval - n0, int(res.nit), bool(res.success), str(res.message), time.perf_counter() - t0,
               unc["std_error"], unc["rel_std_error"], unc["ci95"], unc["correlation"], unc["singular_values"],
               unc["condition"], unc["s2"], unc["dof"], unc["warnings"], [],
               "FRF magnitude, eq. 13 (|H_model| − |H_meas|)")


# ============================================================================ driver


@dataclass
class IdentificationResult:
    """Everything :func:`identify` found; ``fit`` is the one the fitted ``device`` uses."""

    problem: IdentificationProblem
    fits: dict[str, Fit]
    primary: str
    device: Device
    j_err_initial: float
    sources: list[str]
    settings: dict
    wall_s: float

    @property
    def fit(self) -> Fit:
        return self.fits[self.primary]

    @property
    def values(self) -> dict[str, float]:
        """Fitted values {label: SI value}."""
        return dict(zip(self.problem.labels, self.fit.theta.tolist()))

    @property
    def std_errors(self) -> dict[str, float]:
        return dict(zip(self.problem.labels, self.fit.std_error.tolist()))

    @property
    def warnings(self) -> list[str]:
        return list(self.fit.warnings)

    @property
    def n_evaluations(self) -> int:
        return self.problem.n_eval

    def thesis_equivalent_s(self, iterations: int = THESIS_MAX_ITER) -> float:
        """Wall time of the thesis loop for the same data: ``iterations`` × 15 min per
        frequency × number of fitted frequencies (one model evaluation per iteration —
        a lower bound: Nelder–Mead needs 1–2 evaluations per iteration plus shrinks)."""
        n_f = sum(t.freq.size for t in self.problem.targets)
        return iterations * THESIS_SECONDS_PER_FREQUENCY * n_f

    def param_rows(self, fit: Fit | None = None) -> list[dict]:
        fit = fit or self.fit
        rows = []
        for i, p in enumerate(self.problem.params):
            rows.append({"parameter": p.label, "name": p.name, "rh_pct": p.rh, "unit": p.unit, "scale": p.scale,
                         "initial": p.initial, "value": float(fit.theta[i]), "std_error": float(fit.std_error[i]),
                         "rel_std_error": float(fit.rel_std_error[i]), "ci95_lo": float(fit.ci95[i, 0]),
                         "ci95_hi": float(fit.ci95[i, 1]), "lower_bound": p.lower, "upper_bound": p.upper})
        return rows

    def to_dict(self) -> dict:
        from .report import jsonable
        fits = {}
        for name, f in self.fits.items():
            fits[name] = {"method": f.method, "residual": f.residual_kind, "parameters": self.param_rows(f),
                          "correlation": {"labels": self.problem.labels, "matrix": f.correlation.tolist()},
                          "cost": f.cost, "j_err_m_per_V": f.j_err, "model_evaluations": f.nfev,
                          "iterations": f.nit, "success": f.success, "message": f.message, "wall_s": f.wall_s,
                          "residual_variance_s2": f.s2, "dof": f.dof, "condition_number": f.condition,
                          "singular_values": f.singular_values.tolist(), "warnings": f.warnings,
                          "starts": f.starts}
        return jsonable({
            "device": self.problem.device.name, "device_file": self.problem.device.path,
            "effects": list(self.problem.effects), "free": self.problem.free, "per_rh": self.problem.per_rh,
            "rh_levels_pct": self.problem.levels, "primary": self.primary, "fits": fits,
            "j_err_initial_m_per_V": self.j_err_initial, "j_err_final_m_per_V": self.fit.j_err,
            "model_evaluations": self.n_evaluations, "wall_s": self.wall_s,
            "thesis_loop_equivalent_s": self.thesis_equivalent_s(),
            "thesis_loop_assumption": "100 Nelder-Mead iterations x 1 model evaluation x 15 min per frequency "
                                      "point x number of fitted frequencies (COMSOL, thesis ch. 1 §5)",
            "speedup_vs_thesis_loop": self.thesis_equivalent_s() / max(self.wall_s, 1e-9),
            "targets": [{"source": t.source, "rh_pct": t.rh, "frequencies": int(t.freq.size),
                         "f_min_Hz": float(t.freq.min()), "f_max_Hz": float(t.freq.max()),
                         "sensor_bandwidth_Hz": t.sensor_bandwidth, "estimator": t.estimator}
                        for t in self.problem.targets],
            "settings": self.settings, "warnings": self.warnings})


@single_threaded
def identify(measurements: Sequence, device, effects=None, free: Sequence[str] | str = (), *,
             per_rh: Sequence[str] | str = (), method: str = "lsq", n_starts: int | None = None, seed: int = 0,
             start: Mapping | str | None = None, bounds: Mapping | str | None = None, residual: str = "frf",
             fit_phase: bool = True, frf_options: FRFOptions | None = None, min_coherence: float = 0.0,
             weighting: str = "coherence", rh_tolerance: float = 2.5, sensor_bandwidth="auto",
             n_modes: int = 4, start_spread: float = 1.0, rh: float | None = None, skip_s: float = 0.0,
             max_nfev: int | None = None, warn: bool = True) -> IdentificationResult:
    """Identify ``free`` (shared) and ``per_rh`` parameters of ``device`` with ``effects``
    from ``measurements`` (paths, :class:`TimeSeries` or :class:`FRFData`).

    ``method``: ``"lsq"`` (default), ``"nelder-mead"`` (thesis) or ``"both"`` (the device
    uses the least-squares fit).  ``start``/``bounds``: {name: SI value} / {name: (lo, hi)}
    or the text forms ``"kf=0.004,Y=0.2 GPa"`` / ``"kf=1e-4:1e-1"``.  ``n_starts`` defaults
    to 5 for FRF residuals and 1 for time residuals.  Identifiability problems are
    listed in the result and, with ``warn``, issued as :class:`IdentifiabilityWarning`.
    See the module doc for everything else."""
    t0 = time.perf_counter()
    if method not in ("lsq", "nelder-mead", "both"):
        raise InputError(f"method {method!r}: expected lsq, nelder-mead or both")
    if n_starts is None:
        n_starts = 5 if residual == "frf" else 1
    if int(n_starts) < 1:
        raise InputError(f"n_starts={n_starts!r} must be at least 1")
    ms = load_measurements(measurements, rh=rh)
    targets = build_targets(ms, frf_options=frf_options, min_coherence=min_coherence, weighting=weighting,
                            rh_tolerance=rh_tolerance, sensor_bandwidth=sensor_bandwidth, default_rh=rh)
    problem = IdentificationProblem(device, effects, targets, parse_names(free), parse_names(per_rh, "--per-rh"),
                                    start=parse_assignments(start), bounds=parse_assignments(bounds, ranges=True,
                                                                                             what="--bounds"),
                                    n_modes=n_modes, fit_phase=fit_phase, residual=residual, skip_s=skip_s)
    j0 = problem.j_err(problem.theta0)
    fits: dict[str, Fit] = {}
    if method in ("nelder-mead", "both"):
        fits["nelder-mead"] = fit_nelder_mead(problem)
    if method in ("lsq", "both"):
        fits["lsq"] = fit_lsq(problem, n_starts=int(n_starts), seed=seed, start_spread=start_spread,
                              max_nfev=max_nfev)
    primary = "lsq" if "lsq" in fits else "nelder-mead"
    dev = problem.device_for(fits[primary].theta)
    sources = [source_name(m, k) for k, m in enumerate(ms)]
    settings = {"method": method, "n_starts": n_starts, "seed": seed, "start_spread_decades": start_spread,
                "residual": residual, "fit_phase": fit_phase, "weighting": weighting,
                "min_coherence": min_coherence, "rh_tolerance_pct": rh_tolerance,
                "sensor_bandwidth": sensor_bandwidth, "n_modes": n_modes, "skip_s": skip_s,
                "frf": vars(frf_options or FRFOptions()).copy(),
                "thesis_nelder_mead": {"max_iter": THESIS_MAX_ITER, "xatol": THESIS_TOL, "fatol": THESIS_TOL,
                                       "tolerance_on": "parameters / start values and J_err / RMS |H_meas|"}}
    res = IdentificationResult(problem, fits, primary, dev, j0, sources, settings, time.perf_counter() - t0)
    if warn:
        for w in res.warnings:
            warnings.warn(w, IdentifiabilityWarning, stacklevel=2)
    return res


# ============================================================================ device file


def _from_si(value: float, unit: str, spec_unit: str) -> float:
    a = to_si(0.0, unit, spec_unit)
    b = to_si(1.0, unit, spec_unit)
    return (value - a) / (b - a)


def _num(v: float, digits: int = 7) -> float:
    return float(f"{v:.{digits}g}")


def device_to_raw(device: Device) -> dict:
    """A device file mapping (schema eap-device/1) that loads back to ``device``: the
    original file's entries (units, sources, notes) where the values agree, SI entries
    for everything that differs or is missing."""
    from .effects import EFFECTS
    specs = all_param_specs()
    section = _section_of()
    raw: dict = {}
    dev0 = None
    if device.path and Path(device.path).suffix in (".yaml", ".yml") and Path(device.path).is_file():
        raw = yaml.safe_load(Path(device.path).read_text(encoding="utf-8")) or {}
        try:
            dev0 = parse_device(raw, where=device.path)
        except InputError:
            raw, dev0 = {}, None
    raw.setdefault("schema", "eap-device/1")
    raw["name"] = device.name
    if device.title:
        raw["title"] = device.title
    if dev0 is None or dev0.reference_rh != device.reference_rh:
        raw["reference_rh"] = {"value": device.reference_rh, "unit": "pct", "source": ""}
    if device.default_effects:
        raw["default_effects"] = list(device.default_effects)
    for k, v in device.params.items():
        if dev0 is not None and k in dev0.params and dev0.params[k] == v:
            continue
        sec = section[k]
        entry = (raw.get(sec) or {}).get(k)
        unit = entry["unit"] if isinstance(entry, dict) and entry.get("unit") else specs[k].unit
        raw.setdefault(sec, {})[k] = {"value": _num(_from_si(v, str(unit), specs[k].unit)), "unit": unit,
                                      "source": device.sources.get(k, "")}
    table_section = {t.name: eff.id for eff in EFFECTS.values() for t in eff.tables}
    table_specs = {t.name: t for eff in EFFECTS.values() for t in eff.tables}
    for name, cols in device.tables.items():
        if dev0 is not None and name in dev0.tables and all(
                np.array_equal(dev0.tables[name][c], cols[c]) for c in cols):
            continue
        spec = table_specs[name]
        raw.setdefault(table_section[name], {})[name] = {
            "source": device.sources.get(name, ""),
            **{c: {"values": [_num(x) for x in np.asarray(cols[c]).tolist()], "unit": spec.columns[c]} for c in cols}}
    maps = {}
    for name, m in device.humidity_maps.items():
        old = (raw.get("humidity_maps") or {}).get(name)
        if dev0 is not None and name in dev0.humidity_maps and _maps_equal(dev0.humidity_maps[name], m) and old:
            maps[name] = old
            continue
        maps[name] = {"mode": m.mode, "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                      "values": {"values": [_num(x) for x in m.values.tolist()], "unit": specs[name].unit},
                      "source": m.source}
    if maps:
        raw["humidity_maps"] = maps
    else:
        raw.pop("humidity_maps", None)
    return raw


def _maps_equal(a: HumidityMap, b: HumidityMap) -> bool:
    return a.mode == b.mode and np.array_equal(a.rh, b.rh) and np.array_equal(a.values, b.values)


def identified_device_raw(result: IdentificationResult, *, name: str | None = None,
                          date: str | None = None) -> dict:
    """The fitted device as a device-file mapping: identified values with units, a source
    "identified by eap identify from FILES on DATE" and a note with the standard error."""
    prob, fit = result.problem, result.fit
    date = date or _dt.date.today().isoformat()
    files = ", ".join(Path(s).name for s in result.sources)
    src = f"identified by eap identify from {files} on {date}"
    specs = all_param_specs()
    section = _section_of()
    base = prob.device
    new_name = name or f"{base.name}_identified"
    dev = dataclasses.replace(result.device, name=new_name,
                              title=(f"{base.title} — identified" if base.title else new_name),
                              default_effects=tuple(e for e in prob.effects if e != "double_layer"))
    # dataclass equality of HumidityMap with arrays is ambiguous: compare explicitly
    raw = device_to_raw(dataclasses.replace(dev, humidity_maps={}))
    raw.pop("humidity_maps", None)
    old_raw_maps = {}
    if base.path and Path(base.path).is_file():
        old_raw_maps = (yaml.safe_load(Path(base.path).read_text(encoding="utf-8")) or {}).get("humidity_maps") or {}
    maps = {}
    for mname, m in dev.humidity_maps.items():
        if mname in prob.per_rh:
            idx = [i for i, p in enumerate(prob.params) if p.name == mname]
            old_vals = (old_raw_maps.get(mname) or {}).get("values")
            unit = str(old_vals["unit"]) if isinstance(old_vals, dict) and old_vals.get("unit") else specs[mname].unit
            conv = lambda v: _from_si(v, unit, specs[mname].unit)  # noqa: E731
            se = ", ".join(f"RH {prob.params[i].rh:g} %: ±{conv(fit.std_error[i]) - conv(0.0):.3g}" for i in idx)
            maps[mname] = {"mode": "absolute", "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                           "values": {"values": [_num(conv(x)) for x in m.values.tolist()], "unit": unit},
                           "source": f"{src} ({fit.method}; one value per RH level)",
                           "note": f"standard errors (1 sigma, {unit}): {se}"}
        elif mname in base.humidity_maps and _maps_equal(base.humidity_maps[mname], m) and mname in old_raw_maps:
            maps[mname] = old_raw_maps[mname]
        else:
            maps[mname] = {"mode": m.mode, "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                           "values": {"values": [_num(x) for x in m.values.tolist()], "unit": specs[mname].unit},
                           "source": m.source}
    if maps:
        raw["humidity_maps"] = maps
    for i, p in enumerate(prob.params):
        if p.rh is not None:
            continue
        sec = section[p.name]
        entry = raw[sec][p.name] if p.name in raw.get(sec, {}) else {}
        unit = entry.get("unit") or p.unit
        val = _from_si(float(fit.theta[i]), str(unit), p.unit)
        se = _from_si(float(fit.std_error[i]), str(unit), p.unit) - _from_si(0.0, str(unit), p.unit) \
            if np.isfinite(fit.std_error[i]) else math.inf
        raw.setdefault(sec, {})[p.name] = {
            "value": _num(val), "unit": unit, "source": f"{src} ({fit.method})",
            "note": (f"standard error {se:.3g} {unit} ({100 * fit.rel_std_error[i]:.3g} %), start value "
                     f"{_num(_from_si(p.initial, str(unit), p.unit), 6)} {unit}") if math.isfinite(se)
            else "standard error: not determined (see the identification report)"}
    notes = list(raw.get("notes") or [])
    notes.append(f"{src}: free {', '.join(prob.free) or '-'}"
                 + (f", per RH {', '.join(prob.per_rh)} at {', '.join(f'{x:g}' for x in prob.levels)} %" if prob.per_rh else "")
                 + f"; method {fit.method}; effects {', '.join(prob.effects)}; J_err {result.j_err_initial:.4g} -> "
                 f"{fit.j_err:.4g} m/V")
    raw["notes"] = notes
    raw["name"] = new_name
    raw["title"] = dev.title
    raw["default_effects"] = list(dev.default_effects)
    # self-check: the file must load back to the fitted parameters
    back = parse_device(raw, where=f"<identified device {new_name}>")
    for k, v in dev.params.items():
        if not math.isclose(back.params.get(k, math.nan), v, rel_tol=2e-6, abs_tol=1e-300):
            raise ModelError(f"internal error: identified device does not load back: {k} = {back.params.get(k)} "
                             f"instead of {v}")
    return raw


class _DeviceDumper(yaml.SafeDumper):
    """Device-file layout of ``configs/devices``: ``{value: ..., unit: ..., source: ...}``
    entries and short lists of numbers on one line."""


def _is_scalar(v) -> bool:
    return not isinstance(v, (dict, list, tuple))


def _repr_map(dumper, data):
    flow = set(data) <= {"value", "unit", "source", "note", "values"} and all(
        _is_scalar(v) or (isinstance(v, list) and all(_is_scalar(x) for x in v)) for v in data.values())
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=flow)


def _repr_seq(dumper, data):
    flow = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data) or \
        all(isinstance(x, str) and len(x) < 40 for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_DeviceDumper.add_representer(dict, _repr_map)
_DeviceDumper.add_representer(list, _repr_seq)


def write_device(result: IdentificationResult, path, *, name: str | None = None, date: str | None = None,
                 protect=()) -> Path:
    """Write the fitted device file atomically (never over an input in ``protect``)."""
    from .fileio import write_text
    raw = identified_device_raw(result, name=name, date=date)
    header = (f"# {raw['name']}: written by eap identify on {date or _dt.date.today().isoformat()}.\n"
              f"# Loads with physics.load_device(path) / eap ... --device {Path(path).name}\n")
    text = header + yaml.dump(raw, Dumper=_DeviceDumper, sort_keys=False, allow_unicode=True, width=110)
    return write_text(path, text, protect=tuple(protect))


# ============================================================================ report


def _plot_target(result: IdentificationResult, k: int, path) -> None:
    from .plotting import plot_bode_curves
    prob = result.problem
    t = prob.targets[k]
    H0 = prob.responses(prob.theta0)[k]
    curves = {"measured": (t.freq, t.response, {"lw": 1.3, "marker": ".", "ms": 3, "ls": "none"}),
              "start": (t.freq, H0, {"lw": 0.9, "ls": ":"})}
    for name, f in result.fits.items():
        curves[f"fitted ({name})"] = (t.freq, prob.responses(f.theta)[k], {"lw": 1.1})
    coh = (t.freq, t.coherence) if t.coherence is not None else None
    plot_bode_curves(curves, path, coherence=coh,
                         title=f"{Path(t.source).name}, RH {t.rh:g} %")


def _plot_corr(labels, corr, path) -> None:
    import matplotlib.pyplot as plt
    from .plotting import save
    p = len(labels)
    fig, ax = plt.subplots(figsize=(1.0 + 0.7 * p, 0.8 + 0.6 * p))
    im = ax.imshow(np.nan_to_num(corr), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(p))
    ax.set_yticks(range(p))
    ax.set_xticklabels(labels, rotation=45, ha="right", fontsize=8)
    ax.set_yticklabels(labels, fontsize=8)
    for i in range(p):
        for j in range(p):
            c = corr[i, j]
            ax.text(j, i, "–" if not np.isfinite(c) else f"{c:.2f}", ha="center", va="center", fontsize=7,
                    color="white" if np.isfinite(c) and abs(c) > 0.6 else "black")
    fig.colorbar(im, ax=ax, shrink=0.8)
    ax.set_title("parameter correlation", fontsize=9)
    save(fig, path)


def _plot_rh_maps(result: IdentificationResult, path) -> None:
    import matplotlib.pyplot as plt
    from .plotting import save
    prob, fit = result.problem, result.fit
    names = prob.per_rh
    fig, axes = plt.subplots(1, len(names), figsize=(4 * len(names), 3.2), squeeze=False)
    for ax, name in zip(axes[0], names):
        idx = [i for i, p in enumerate(prob.params) if p.name == name]
        rh = [prob.params[i].rh for i in idx]
        ax.errorbar(rh, fit.theta[idx], yerr=1.96 * fit.std_error[idx], fmt="o-", capsize=3, label="identified")
        ax.plot(rh, [prob.params[i].initial for i in idx], "x:", color="gray", label="start")
        ax.set_xlabel("RH [%]")
        ax.set_ylabel(f"{name} [{prob.params[idx[0]].unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    save(fig, path)


def write_identification(result: IdentificationResult, out_dir, *, name: str | None = None,
                         provenance: dict | None = None, protect=()) -> dict:
    """Write the fitted device ``NAME.yaml``, ``report.json``, ``parameters.csv``, PNGs and
    ``report.html`` into ``out_dir``; returns the JSON dict (with the file names)."""
    from .fileio import write_json
    from .report import Report, jsonable, write_csv
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    date = _dt.date.today().isoformat()
    dev_name = name or f"{result.problem.device.name}_identified"
    dev_path = write_device(result, d / f"{dev_name}.yaml", name=dev_name, date=date, protect=protect)
    files = [dev_path.name]
    pngs = []
    for k, t in enumerate(result.problem.targets):
        fn = f"bode_{k:02d}_{Path(t.source).stem[:40]}.png".replace(" ", "_")
        _plot_target(result, k, d / fn)
        pngs.append(fn)
    if len(result.problem.params) > 1:
        _plot_corr(result.problem.labels, result.fit.correlation, d / "correlation.png")
        pngs.append("correlation.png")
    if result.problem.per_rh:
        _plot_rh_maps(result, d / "rh_maps.png")
        pngs.append("rh_maps.png")
    rows = result.param_rows()
    write_csv(rows, d / "parameters.csv")
    files += ["parameters.csv", "report.json", "report.html"] + pngs
    out = result.to_dict()
    out["files"] = files
    out["device_written"] = dev_path.name
    if provenance:
        out["provenance"] = provenance
    write_json(d / "report.json", jsonable(out))
    # HTML
    fit = result.fit
    rep = Report("Parameter identification",
                 subtitle=f"{result.problem.device.name} [{', '.join(result.problem.effects)}] from "
                          f"{len(result.sources)} measurement(s); fitted device: {dev_path.name}")
    for w in result.warnings:
        rep.warning(w)
    rep.heading("Result")
    rep.table({"method": fit.method, "residual": fit.residual_kind, "J_err start (eq. 13) [m/V]": result.j_err_initial,
               "J_err fitted [m/V]": fit.j_err, "model evaluations": result.n_evaluations,
               "wall time [s]": result.wall_s, "residual variance s²": fit.s2, "degrees of freedom": fit.dof,
               "condition number of J": fit.condition, "converged": fit.success, "message": fit.message,
               "thesis loop, same data [days]": result.thesis_equivalent_s() / 86400})
    rep.table([{k: r[k] for k in ("parameter", "unit", "initial", "value", "std_error", "rel_std_error",
                                  "ci95_lo", "ci95_hi", "scale", "lower_bound", "upper_bound")} for r in rows],
              caption="identified parameters (SI; std_error 1σ, Bates & Watts linear approximation scaled by s²; "
                      "95 % interval)")
    if result.problem.per_rh:
        table_v = []
        for lv in result.problem.levels:
            row = {"RH [%]": lv}
            for i, p in enumerate(result.problem.params):
                if p.rh == lv:
                    row[f"{p.name} [{p.unit}]"] = float(fit.theta[i])
                    row[f"± {p.name}"] = float(fit.std_error[i])
            table_v.append(row)
        rep.heading("Per-RH values (Table V style)")
        rep.table(table_v)
        rep.image(d / "rh_maps.png", caption="per-RH values with 95 % intervals")
    if "correlation.png" in pngs:
        rep.image(d / "correlation.png", caption="correlation matrix of the estimates")
    for name_, f in result.fits.items():
        if name_ != result.primary:
            rep.heading(f"Also fitted: {name_}")
            rep.table([{k: r[k] for k in ("parameter", "value", "std_error", "rel_std_error")}
                       for r in result.param_rows(f)],
                      caption=f"{f.method}: J_err {f.j_err:.4g} m/V, {f.nfev} evaluations, {f.nit} iterations, "
                              f"{f.message}")
            for w in f.warnings:
                rep.warning(f"{name_}: {w}")
    if fit.starts:
        rep.heading("Multi-start")
        rep.table([{"start": s["start"], "cost": s.get("cost"), "evaluations": s.get("nfev"),
                    **{lab: v for lab, v in zip(result.problem.labels, s.get("theta", []))}} for s in fit.starts])
    rep.heading("Measured and fitted frequency responses")
    for fn in pngs:
        if fn.startswith("bode_"):
            rep.image(d / fn, caption=fn)
    rep.heading("Settings")
    rep.json_block(jsonable(result.settings), "settings")
    if provenance:
        rep.json_block(provenance, "provenance")
    rep.write(d / "report.html")
    return out
