"""Test beds for the diagnosis: records that look like a lab's, and a simulator whose base
physics differs a little from ours (issue 24).

A diagnosis that works only on our own simulator's clean output is not worth much.  Two
suites make harder records, each a function of (truth, seed) returning a :class:`Case`:

* :func:`lab_case` — **lab-like records** from our simulator, exported as an instrument
  would: the strip's geometry changed through device parameters (as ``--param`` does), 200 Hz
  sampling, the tip column in millimetres with 3 µm noise, a sensor offset of a few
  hundredths of a millimetre and a slow random-walk drift, the RH column with ±0.3 %
  hygrometer jitter around a slightly different humidity per record, and sidecars that say
  neither the excitation nor the sensor noise.
* :func:`perturbed_case` — a **perturbed simulator**: the base forms varied a little so the
  user's model (ours) can never fit down to the noise: the second bending mode shifted by
  8–20 % in frequency (a slightly non-uniform strip) and a double layer charging like a
  constant-phase element (exponent n = 0.75–0.9) instead of an ideal capacitor (rough
  electrodes).  Records as our simulator writes them (1 µm laser noise, sidecars with the
  excitation and the sensor).

**Truths.**  ``truth`` is ``"none"`` (nothing hidden), the id of a catalog effect that
declares how to draw a hidden truth (its ``draw_truth`` hook; :func:`.demo.hidden_effects`)
— switched on in the truth and left out of the user's model — or one of :data:`OUTSIDE`,
physics no catalog effect has, acting on the tip deflection:

============  ================================================================================
``creep``     tip × (1 + r/(1 + sτ)), r U(0.25, 0.4), τ log-uniform 10–30 s (the example effect
              ``examples/effects/creep.py`` is exactly this form)
``lowpass``   a first-order low-pass on the output (a slow sensor), cut-off U(12, 25) Hz
``drift``     an additive drift independent of the input: a smooth random wander (time scale
              ~10 s) of RMS U(3, 6) × the white noise after its linear trend is removed
``play``      a play (backlash) of width U(60, 100) µm on the output
============  ================================================================================

The base's own parameters (kf, beta_f, Y) are drawn around the device's in every case (the
diagnosis has to fit them).  Records: a logarithmic sweep 0.1–50 Hz and a square pulse
(20 s on, 40 s off) at one RH, plus what the hidden effect's ``reveal`` rule asks for (RH
levels 40/60/80 %, a second amplitude ×4); amplitudes keep the peak deflection near 2 mm.

:meth:`Case.true_error` is the error of the true model scored as the diagnosis scores
(offset and linear drift of each record removed, :func:`physics.analysis.metrics.remove_nuisance`): the
level a perfect fit reaches.  :meth:`Case.write` exports the records (CSV + sidecars) for
the command line.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from .. import signals
from ..device import Device, load_device
from ..errors import InputError
from ..solvers.frequency import response_per_volt
from ..identify.free_parameters import switchable
from ..model import ActuatorModel
from ..io.sensor import SensorModel
from ..solvers.timedomain import simulate
from ..io.timeseries import TimeSeries, write_timeseries
from ..diagnose.forms.play import play
from .demo import PEAK_M, design_for, draw_truth, hidden_effects
from ..diagnose.records import sensor_filter
from ..analysis.metrics import remove_nuisance

#: Physics outside the catalog (module doc).
OUTSIDE = ("creep", "lowpass", "drift", "play")
SUITES = ("lab", "perturbed")
#: Nominal RH levels [%] of the records (one level, or three when the truth needs them).
RH_ONE, RH_LEVELS = (60.0,), (40.0, 60.0, 80.0)


@dataclass
class Case:
    """Records of one test-bed case and what a user would pass to the commands.

    ``device`` is the user's device (nominal values, geometry applied); ``device_params``
    the same geometry as ``--param NAME=VALUE`` strings; ``effects`` the user's ``--effects``;
    ``measurements`` the records as they would be read back from :meth:`write`;
    ``clean`` the true deflection the sensor sees, per record [m] (no noise, offset, drift);
    ``noise_floor`` the sensor's white noise and quantisation [m] (drift excluded)."""

    suite: str
    truth: str
    seed: int
    device: Device
    device_name: str
    device_params: dict
    effects: str
    truth_effects: tuple
    truth_params: dict
    measurements: list
    clean: list
    noise_floor: float
    export_units: dict
    notes: list = field(default_factory=list)

    @property
    def hidden(self) -> str | None:
        """The catalog effect left out of the user's model (None: nothing hidden or outside physics)."""
        return self.truth if self.truth not in OUTSIDE + ("none",) else None

    def true_error(self) -> float:
        """RMS error [m] of the true model, scored like the diagnosis (per-record offset and
        linear drift removed), over all samples of all records."""
        sq = cnt = 0
        for m, c in zip(self.measurements, self.clean):
            e = remove_nuisance(m.deflection - c, m.time)
            sq += float(e @ e)
            cnt += e.size
        return math.sqrt(sq / cnt)

    def write(self, folder) -> list[Path]:
        """Export the records into ``folder`` (created): CSV in the suite's units plus sidecars."""
        d = Path(folder)
        d.mkdir(parents=True, exist_ok=True)
        return [write_timeseries(m, d / f"{m.source}.csv", units=self.export_units) for m in self.measurements]

    def param_args(self) -> list[str]:
        """``--param NAME=VALUE`` arguments of the command line for the user's device."""
        out = []
        for k, v in self.device_params.items():
            out += ["--param", f"{k}={v}"]
        return out

    def describe(self) -> dict:
        return {"suite": self.suite, "truth": self.truth, "seed": self.seed, "device": self.device_name,
                "device_params": self.device_params, "effects": self.effects,
                "truth_effects": list(self.truth_effects), "truth_params": self.truth_params,
                "records": [m.source for m in self.measurements], "noise_floor_m": self.noise_floor,
                "true_error_m": self.true_error(), "notes": self.notes}


# ============================================================================ the suites


def lab_case(truth: str = "none", seed: int = 0, *, device: str = "ipmc_pt_eg", fs: float = 200.0,
             duration: float = 60.0) -> Case:
    """Lab-like records of our simulator (module doc).  The user's model is the device's
    default effects without the hidden one; geometry L_total U(30, 40) mm, width U(6, 10) mm."""
    rng = np.random.default_rng([seed, 24, 1])
    base = load_device(device)
    geo = {"L_total": f"{int(rng.integers(30, 41))}mm", "width": f"{int(rng.integers(6, 11))}mm"}
    user = base.with_params(L_total=1e-3 * float(geo["L_total"][:-2]), width=1e-3 * float(geo["width"][:-2]))
    defaults = switchable(ActuatorModel(user, "default").effect_ids)
    hidden = _check_truth(truth)
    if hidden is not None and hidden not in defaults:
        model_effects, truth_ids = "default", defaults + (hidden,)
    else:
        model_effects = "default" if hidden is None else f"default,-{hidden}"
        truth_ids = defaults
    sensor = SensorModel(deflection_noise=3e-6, deflection_step=1e-7,
                         deflection_offset=float(rng.uniform(0.03, 0.07)) * 1e-3 * rng.choice([-1, 1]),
                         deflection_drift=float(rng.uniform(3e-6, 10e-6)), deflection_range=5e-3, bandwidth=None,
                         rh_noise=0.15, rh_step=0.1)
    case = _make(truth, hidden, seed, rng, user, truth_ids, fs, duration, sensor, perturb=None)
    meta = {"instrument": "laser triangulation sensor (tip, mm) and capacitive hygrometer (RH)",
            "sample": f"strip {geo['L_total']} x {geo['width']}", "exported_by": "acquisition software"}
    ms = [TimeSeries(m.time, m.voltage, np.round(m.deflection, 7), rh=m.rh, meta=dict(meta), source=m.source)
          for m in case["records"]]
    return Case("lab", truth, seed, user, device, geo, model_effects, truth_ids, case["params"], ms, case["clean"],
                _white(sensor), {"deflection": "mm"}, case["notes"])


def perturbed_case(truth: str = "none", seed: int = 0, *, device: str = "ipmc_pt_eg", fs: float = 500.0,
                   duration: float = 60.0) -> Case:
    """Records of the perturbed simulator (module doc); the user's model is the bare device
    (effects ``none``)."""
    rng = np.random.default_rng([seed, 24, 2])
    user = load_device(device)
    hidden = _check_truth(truth)
    truth_ids = (hidden,) if hidden else ()
    perturb = {"mode2_shift": float(rng.uniform(1.08, 1.2)), "cpe_n": float(rng.uniform(0.75, 0.9))}
    sensor = SensorModel()
    case = _make(truth, hidden, seed, rng, user, truth_ids, fs, duration, sensor, perturb=perturb)
    return Case("perturbed", truth, seed, user, device, {}, "none", truth_ids, {**case["params"], **perturb},
                case["records"], case["clean"], _white(sensor), {}, case["notes"])


def make_case(suite: str, truth: str = "none", seed: int = 0, **kw) -> Case:
    """:func:`lab_case` or :func:`perturbed_case` by name."""
    if suite not in SUITES:
        raise InputError(f"suite {suite!r}: choose one of {', '.join(SUITES)}")
    return (lab_case if suite == "lab" else perturbed_case)(truth, seed, **kw)


def truths(suite: str) -> tuple[str, ...]:
    """The truths a suite covers: nothing, each catalog effect with a drawn truth (the lab
    suite: the device's default effects, which it leaves out one at a time), the outside
    physics."""
    if suite == "lab":
        defaults = ActuatorModel(load_device("ipmc_pt_eg"), "default").effect_ids
        cat = tuple(e for e in hidden_effects() if e in defaults)
    else:
        cat = hidden_effects()
    return ("none",) + cat + OUTSIDE


# ============================================================================ shared machinery


def _white(sensor: SensorModel) -> float:
    """The sensor's white noise and quantisation [m] (its drift is a nuisance, not noise)."""
    return math.sqrt(sensor.deflection_noise ** 2 + sensor.deflection_step ** 2 / 12)


def _check_truth(truth: str) -> str | None:
    if truth == "none":
        return None
    if truth in OUTSIDE:
        return None
    if truth not in hidden_effects():
        raise InputError(f"truth {truth!r}: choose none, one of {', '.join(hidden_effects())} or one of "
                         f"{', '.join(OUTSIDE)}")
    return truth


def _plan(hidden: str | None, rng, fs: float, duration: float) -> list[tuple]:
    parts = design_for(hidden)
    rhs = RH_LEVELS if "rh" in parts else RH_ONE
    plan = [("sweep", 1.0, rh) for rh in rhs]
    if "amplitudes" in parts:
        plan.append(("sweep", 4.0, rhs[0]))
    plan.append(("pulse", 1.0, rhs[len(rhs) // 2]))
    return plan


def _make(truth, hidden, seed, rng, user: Device, truth_ids, fs, duration, sensor: SensorModel, perturb):
    truth_dev, tp = draw_truth(hidden, user, rng)
    model = ActuatorModel(truth_dev, truth_ids or "none")
    outside = _draw_outside(truth, rng, sensor)
    tp.update({k: v for k, v in outside.items() if not k.startswith("_")})
    plan = _plan(hidden, rng, fs, duration)
    f = np.geomspace(0.01, 50.0, 300)          # down to 0.01 Hz: the pulse's hold too
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        peak = max(float(np.max(np.abs(response_per_volt(model, 2j * np.pi * f, rh)[0]))) for _, _, rh in plan)
    amp = float(f"{min(1.0, PEAK_M / peak / max(a for _, a, _ in plan)):.2g}")
    records, clean, notes = [], [], []
    for k, (kind, scale, rh_nom) in enumerate(plan):
        rh_true = rh_nom + float(rng.uniform(-0.5, 0.5))
        a = amp * scale
        if kind == "sweep":
            sig, hold = signals.sweep(a, 0.1, 50.0, duration, fs), "cubic"
        else:
            sig, hold = signals.square(a, t_on=20.0, t_off=40.0, cycles=1, fs=fs), "linear"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            y = simulate(model, None, sig.t, sig.v, rh=rh_true, hold=hold).deflection
            if perturb is not None:
                y = _perturb(model, y, fs, rh_true, perturb)
        y = _apply_outside(truth, outside, y, fs, rng)
        name = f"{k + 1:02d}_{kind}_{a:g}V_RH{rh_nom:g}"
        ts = TimeSeries(sig.t, sig.v, y, rh=np.full(sig.t.size, rh_true), meta={"signal": sig.describe()},
                        source=name)
        m = sensor.apply(ts, seed=int(rng.integers(2 ** 31)))
        records.append(m)
        clean.append(sensor._lowpass(y, fs))
    if perturb is not None:
        notes.append(f"base perturbed: second mode ×{perturb['mode2_shift']:.3g} in frequency, double layer a "
                     f"constant-phase element n = {perturb['cpe_n']:.3g}")
    return {"records": records, "clean": clean, "params": tp, "notes": notes}


def _draw_outside(truth: str, rng, sensor: SensorModel) -> dict:
    if truth == "creep":
        return {"creep_r": float(rng.uniform(0.25, 0.4)), "creep_tau_s": float(np.exp(rng.uniform(np.log(10),
                                                                                                  np.log(30))))}
    if truth == "lowpass":
        return {"lowpass_Hz": float(rng.uniform(12.0, 25.0))}
    if truth == "drift":
        return {"drift_rms_m": float(rng.uniform(3.0, 6.0)) * sensor.deflection_noise, "drift_time_s": 10.0}
    if truth == "play":
        return {"play_width_m": float(rng.uniform(60e-6, 100e-6))}
    return {}


def _apply_outside(truth: str, p: dict, y: np.ndarray, fs: float, rng) -> np.ndarray:
    if truth == "creep":
        a = math.exp(-1.0 / (p["creep_tau_s"] * fs))
        return y + p["creep_r"] * lfilter([1 - a], [1, -a], y)
    if truth == "lowpass":      # exact in continuous time (a one-pole recursion leads by half a sample)
        return sensor_filter(y, fs, p["lowpass_Hz"])
    if truth == "drift":
        n = y.size
        a = math.exp(-1.0 / (p["drift_time_s"] * fs))
        w = lfilter([1 - a], [1, -a], lfilter([1 - a], [1, -a], rng.normal(0.0, 1.0, n)))
        w = remove_nuisance(w, np.arange(n) / fs)
        return y + p["drift_rms_m"] * w / max(float(np.std(w)), 1e-300)
    if truth == "play":
        return play(y, p["play_width_m"])
    return y


class _ShiftedModes:
    """Cantilever modes whose second natural frequency is ``shift`` × the uniform strip's
    (same shapes; the static deflection is unchanged)."""

    def __init__(self, modes, shift: float):
        self._m = modes
        self.beta = modes.beta.copy()
        if self.beta.size > 1:
            self.beta[1] *= math.sqrt(shift)

    def __getattr__(self, name):
        return getattr(self._m, name)

    def natural_frequencies(self, EI: float, rhoA: float) -> np.ndarray:
        return (self.beta * self._m.L) ** 2 * np.sqrt(EI / rhoA) / (2.0 * np.pi * self._m.L ** 2)


def _perturb(model: ActuatorModel, y: np.ndarray, fs: float, rh: float, perturb: dict) -> np.ndarray:
    """``y`` through the factor P(f) = H_perturbed(f)/H(f) (zero-padded FFT, even extension)."""
    n = y.size
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    s = 2j * np.pi * np.maximum(f, 1e-6)
    shifted = replace_modes(model, perturb["mode2_shift"])
    h0 = response_per_volt(model, s, rh)[0]
    h1 = response_per_volt(shifted, s, rh)[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        P = np.where(np.abs(h0) > 0, h1 / h0, 1.0)
    tau = model.double_layer_props(model.params_at(rh)).tau
    x = s * tau
    P = P * (1.0 + x) / (1.0 + x ** perturb["cpe_n"])
    P[0] = 1.0
    ext = np.concatenate([y, y[::-1]])
    return np.fft.irfft(np.fft.rfft(ext, nfft) * P, nfft)[:n]


def replace_modes(model: ActuatorModel, shift: float) -> ActuatorModel:
    """A copy of ``model`` whose second bending mode is ``shift`` × higher in frequency."""
    m = ActuatorModel(model.device, model.effect_ids, n_modes=model.n_modes)
    base = m.modes
    m.modes = lambda: _ShiftedModes(base(), shift)
    return m


__all__ = ["Case", "OUTSIDE", "SUITES", "lab_case", "perturbed_case", "make_case", "truths", "replace_modes"]
