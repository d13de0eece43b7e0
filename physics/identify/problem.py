"""The identification problem: FRF targets from measurements, weights and residuals."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy.ndimage import median_filter

from ..compare import (FRFOptions, cluster_rh, estimate_record_frf, model_rh,
                      sensor_bandwidth_of, sensor_lowpass, sensor_response, source_name, thin_log,
                      valid_points)
from ..device import Device, HumidityMap, all_param_specs, load_device
from ..errors import InputError, arg
from ..execution.memo import remembered
from ..solvers.frequency import response_per_volt
from ..analysis.frf_estimation import detect_excitation
from ..io.frfdata import FRFData
from ..model import ActuatorModel, resolve_effects
from ..io.timeseries import TimeSeries
from .free_parameters import FreeParameter, _make_param, _suggest, hint as _hint
from .settings import EPS_FLOOR


class InertParameterError(InputError):
    """A free parameter that leaves the frequency response unchanged (``name``): it cannot be
    fitted.  The command line reports it; the diagnosis, which chooses free parameters itself,
    holds such a parameter at its value instead."""

    def __init__(self, message: str = "", *args, name: str = ""):
        super().__init__(message, *args)
        self.name = name


@dataclass
class FRFTarget:
    """One measured frequency response to fit: ``freq`` Hz, ``response`` complex m/V,
    ``weight`` per frequency (relative), ``rh`` the record's RH [%] the model is evaluated
    at, ``level`` the nominal RH of its humidity group [%] (the key of per-RH parameters)."""

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
    level: float | None = None       # nominal RH of the record's humidity group [%]
    use_frf: bool = True             # False: a step record, used in the time domain only

    def __post_init__(self):
        if self.level is None:
            self.level = self.rh

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
                  min_coherence: float = 0.0, weighting: str = "coherence", rh_tolerance: float = 1.0,
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
                            estimator=info, record=m, rh_series=rh, steps=_is_steps(m)))
        elif isinstance(m, FRFData):
            if m.rh is None and default_rh is None:
                raise InputError(f"{where}: the FRF file has no rh_pct column; give the RH with {arg('rh')}")
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
                            estimator={"method": "file"}, record=None, rh_series=None, steps=False))
        else:
            raise InputError(f"{where}: expected a TimeSeries or FRFData, got {type(m).__name__}")
    if not raw:
        raise InputError("no measurement given")
    if any(r["steps"] for r in raw) and not all(r["steps"] for r in raw):
        for r in raw:     # a step's response need not end at rest within the record: its FRF leaks
            if r["steps"]:
                r["estimator"] = {**r["estimator"], "use": "time only: a step record beside broadband ones (the "
                                  "FRF of a transient that does not end at rest is biased)"}
    levels = cluster_rh([r["rh"] for r in raw], rh_tolerance)
    out = []
    for r, lv in zip(raw, levels):
        rec = r["record"]
        out.append(FRFTarget(r["source"], r["freq"], r["response"], _weights(r["eps"], r["freq"].size, weighting),
                             r["rh"], r["coherence"], r["bw"], r["estimator"], rec,
                             None if rec is None else model_rh(r["rh_series"], rec.fs, rh_tolerance), lv,
                             not (r["steps"] and not all(x["steps"] for x in raw))))
    return out


def _is_steps(ts: TimeSeries) -> bool:
    """True when a record's excitation is steps or pulses (its metadata, else its voltage)."""
    sig = ts.meta.get("signal") if isinstance(ts.meta.get("signal"), dict) else {}
    kind = str(sig.get("kind", ""))
    if kind:
        return kind in ("square", "steps")
    try:
        return detect_excitation(ts.voltage, ts.fs, ts.source).kind == "steps"
    except InputError:
        return False


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
        self._memos: list[dict] = [{} for _ in self.targets]     # :meth:`responses`
        self._sim_memos: list[dict] = [{} for _ in self.targets]  # :meth:`time_errors`
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
            raise InputError(f"no free parameter: name at least one (e.g. {arg('free')} kf,beta_f)")
        both = sorted(set(free) & set(per_rh))
        if both:
            raise InputError(f"{', '.join(both)}: a parameter is either shared ({arg('free')}) or per RH ({arg('per_rh')}), not both")
        specs = all_param_specs()
        start = dict(start or {})
        bounds = dict(bounds or {})
        for name in list(start) + list(bounds):
            if name not in free and name not in per_rh:
                raise InputError(f"start value or bounds given for {name!r}, which is not a free parameter")
        for name in free + per_rh:
            if name not in specs:
                raise InputError(f"unknown parameter {name!r}{_suggest(name, specs)}")
        # RH levels: nominal labels; each evaluated at the mean RH of its records
        self.levels = sorted({t.level for t in self.targets})
        self.level_rh = {lv: float(np.mean([t.rh for t in self.targets if t.level == lv])) for lv in self.levels}
        self.model0 = ActuatorModel(self.device, self.effects, n_modes=self.n_modes)
        hum_on = self.model0.needs_rh
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
            elif specs[name].default is not None:
                v0 = float(specs[name].default)
            else:
                raise InputError(f"device {self.device.name!r} has no value for {name!r}; give a start value "
                                 f"({arg('start')}: {name}=...)")
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
        rh = self.level_rh.get(rh, rh)
        if name == "Y":
            return float(self.device.params["Y"] * self.model0.hook("stiffness_factor")(rh))
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
                maps[name] = HumidityMap(name, np.array([self.level_rh[lv] for lv in self.levels], dtype=float), vals,
                                         "absolute", "identified per RH (nodes at each level's mean RH)")
            dev = dataclasses.replace(dev, humidity_maps=maps)
        return dev

    def model_for(self, theta) -> ActuatorModel:
        return ActuatorModel(self.device_for(theta), self.effects, n_modes=self.n_modes)

    # --- model evaluations -------------------------------------------------------------------
    def responses(self, theta) -> list[np.ndarray]:
        """Model FRF [m/V] (sensor included) at each target's frequencies.

        A target's response depends on θ only through the parameters at its RH (and the
        stiffness factor there), so it is kept for the last few parameter sets per target
        (:mod:`physics.execution.memo`): a finite-difference Jacobian column of a per-RH
        parameter recomputes only the targets at that RH level (the same numbers, bit for bit)."""
        model = self.model_for(theta)
        self.n_eval += 1
        out = []
        for t, memo in zip(self.targets, self._memos):
            p = model.params_at(t.rh)
            out.append(remembered(memo, model.key_at(t.rh, p), lambda: response_per_volt(model, t.s, t.rh, p)[0]
                                  * sensor_response(t.freq, t.sensor_bandwidth)))
        return out

    def frf_residuals(self, theta) -> np.ndarray:
        """Weighted complex-log residuals, real and imaginary parts stacked."""
        parts = []
        for t, H in zip(self.targets, self.responses(theta)):
            if not t.use_frf:
                continue
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
        return np.concatenate([np.abs(H) - np.abs(t.response) for t, H in zip(self.targets, self.responses(theta))
                               if t.use_frf])

    def j_err(self, theta) -> float:
        """Thesis cost eq. 13 over every fitted frequency [m/V]."""
        r = self.magnitude_residuals(theta)
        return float(np.sqrt(np.mean(r ** 2)))

    def time_errors(self, theta) -> list[np.ndarray]:
        """Simulated minus measured deflection [m] of each time record after ``skip_s``, its
        offset and linear drift removed (:func:`physics.analysis.metrics.remove_nuisance`)."""
        from ..analysis.metrics import remove_nuisance
        from ..solvers.timedomain import simulate
        model = self.model_for(theta)
        self.n_eval += 1
        parts = []
        for t, memo in zip(self.targets, self._sim_memos):
            ts = t.record
            if ts is None:
                continue
            v = ts.voltage
            tt = np.arange(v.size) / ts.fs
            y_hat = remembered(memo, model.key_at(t.rh_model), lambda: sensor_lowpass(
                simulate(model, None, tt, v, rh=t.rh_model, hold="cubic").deflection, ts.fs, t.sensor_bandwidth))
            i0 = int(math.ceil(self.skip_s * ts.fs))
            parts.append(remove_nuisance((y_hat - ts.deflection)[i0:]))
        return parts

    def time_rmse(self, theta) -> float:
        """RMS of :meth:`time_errors` over all time records [m] (NaN without time records)."""
        parts = self.time_errors(theta)
        if not parts:
            return math.nan
        return float(np.sqrt(sum(float(e @ e) for e in parts) / sum(e.size for e in parts)))

    def time_residuals(self, theta) -> np.ndarray:
        """:meth:`time_errors` of each record divided by the std of its measurement, stacked."""
        i0s = [int(math.ceil(self.skip_s * t.record.fs)) for t in self.targets if t.record is not None]
        recs = [t.record for t in self.targets if t.record is not None]
        return np.concatenate([e / np.std(ts.deflection[i0:]) for e, ts, i0 in zip(self.time_errors(theta), recs, i0s)])

    def residuals(self, theta) -> np.ndarray:
        if self.residual == "frf":
            return self.frf_residuals(theta)
        if self.residual == "time":
            return self.time_residuals(theta)
        a, b = self.frf_residuals(theta), self.time_residuals(theta)
        return np.concatenate([a, b * math.sqrt(a.size / b.size)])

    def criterion(self, theta, method: str = "lsq") -> float:
        """The cost a method minimises at θ: 0.5‖r‖² of the least-squares residual, J_err
        (eq. 13) for Nelder–Mead."""
        if method == "nelder-mead":
            return self.j_err(theta)
        r = self.residuals(theta)
        return float(0.5 * r @ r)

    def residuals_x(self, x) -> np.ndarray:
        return self.residuals(self.from_x(x))

    def normalised_jerr(self, z, scale) -> float:
        return self.j_err(z * scale) / self._mag_rms

    @property
    def _mag_rms(self) -> float:
        return float(np.sqrt(np.mean(np.concatenate([np.abs(t.response) ** 2 for t in self.targets if t.use_frf]))))

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
                hint = _hint(p.name, self.effects)
                raise InertParameterError(f"parameter {p.label} has no effect on the frequency response of "
                                          f"{self.device.name!r} with effects [{', '.join(self.effects)}]"
                                          + (f": {hint}" if hint else "") + "; choose other free parameters or effects",
                                          name=p.name)


# ============================================================================ fitting


