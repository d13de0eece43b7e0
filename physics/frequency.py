"""Frequency-domain solver: closed-form small-signal response per volt.

Everything is evaluated exactly (no realisation): the linearised PNP double layer, the
transmission-line voltage cosh(m(L−z))/cosh(mL) integrated against the mode slopes by
Gauss–Legendre quadrature, the solvent factor B(s), kf(s), the Prony modulus and the
modal cantilever plus the exact quasi-static contribution of the higher modes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .threads import single_threaded
from .errors import InputError
from .model import ActuatorModel, as_model
from .strip import quadrature


@dataclass
class FrequencyResponse:
    """Small-signal response per volt of input at the clamp.

    deflection: tip deflection [m/V]; current: input current [A/V]; cs_up: interface
    solvent excess averaged over the electrode length (thesis eq. 8) [mol/m³ per V];
    the lower interface is −cs_up.  Sign convention: Vin > 0 drives the cations to the
    upper face (cathode); the strip bends towards the anode, counted positive."""

    freq: np.ndarray
    deflection: np.ndarray
    current: np.ndarray
    cs_up: np.ndarray
    rh: float
    device: str
    effects: tuple[str, ...]
    natural_frequencies: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def impedance(self) -> np.ndarray:
        """Electrical input impedance [Ω]."""
        return 1.0 / self.current

    @property
    def magnitude(self) -> np.ndarray:
        return np.abs(self.deflection)

    @property
    def phase_deg(self) -> np.ndarray:
        return np.degrees(np.unwrap(np.angle(self.deflection)))

    def resonance(self) -> tuple[float, float] | None:
        """(frequency [Hz], magnitude [m/V]) of the most prominent local maximum of the
        deflection magnitude (the first bending resonance), or None if there is none."""
        from scipy.signal import find_peaks
        idx, props = find_peaks(np.log(self.magnitude), prominence=0.05)
        if idx.size == 0:
            return None
        i = idx[int(np.argmax(props["prominences"]))]
        return float(self.freq[i]), float(self.magnitude[i])

    def to_dict(self) -> dict:
        return {"device": self.device, "effects": list(self.effects), "rh_pct": self.rh,
                "freq_Hz": self.freq.tolist(), "mag_m_per_V": self.magnitude.tolist(),
                "phase_deg": self.phase_deg.tolist(),
                "impedance_ohm_abs": np.abs(self.impedance).tolist(),
                "impedance_phase_deg": np.degrees(np.angle(self.impedance)).tolist(),
                "cs_up_mol_m3_per_V_abs": np.abs(self.cs_up).tolist(),
                "natural_frequencies_Hz": self.natural_frequencies.tolist()}


@single_threaded
def frequency_response(device, effects=None, freqs=None, rh=None, *, n_modes: int = 4) -> FrequencyResponse:
    """Closed-form frequency response of a device with the given effects at ``rh`` [%].

    ``device`` may be a device name, a YAML path, a :class:`~physics.device.Device` or an
    :class:`~physics.model.ActuatorModel` (then ``effects`` may be omitted).  ``freqs`` in Hz
    (default: 500 log-spaced points over 0.1–50 Hz)."""
    model = as_model(device, effects, n_modes)
    f = np.logspace(-1, np.log10(50.0), 500) if freqs is None else np.atleast_1d(np.asarray(freqs, dtype=float))
    if f.size == 0 or np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise InputError("frequencies must be finite and positive (Hz)")
    rh = model.check_rh(rh)
    if np.ndim(rh):
        raise InputError("frequency_response needs one RH value (a time series of RH is for simulate)")
    tip, cur, cs, fn = response_per_volt(model, 2j * np.pi * f, rh)
    return FrequencyResponse(freq=f, deflection=tip, current=cur, cs_up=cs, rh=float(rh),
                             device=model.device.name, effects=model.effect_ids, natural_frequencies=fn)


def response_per_volt(model: ActuatorModel, s: np.ndarray, rh: float):
    """(tip [m/V], current [A/V], Cs_up [mol/m³/V], natural frequencies [Hz]) at ``s`` [rad/s]."""
    p = model.params_at(rh)
    d = model.double_layer_props(p)
    q, cint = model.hook("small_signal")(s, d, p)
    Yp = s * q + d.G_leak
    L, Lc, Lt = model.free_length, p["L_clamp"], p["L_total"]
    w, h, n = p["width"], 0.5 * p["t_polymer"], p["n_solvation"]
    zq, wq = quadrature(L)
    U = model.hook("distribution")(s, Yp, p, zq)                 # (n_s, n_q) per volt
    intU = U @ wq
    load = model.load_response(s, p) * cint
    mu = (2.0 * h * w * n * load)[:, None] * U                     # couple per volt [N m/m/V]
    modes = model.modes()
    Q = (mu * wq[None, :]) @ modes.dphi(zq).T                       # generalised loads (n_s, n_modes)
    stat = (mu * wq[None, :]) @ (zq * (L - 0.5 * zq))
    EI, rhoA = model.section(p, float(model.hook("stiffness_factor")(rh)))
    EIs = EI(s) * (1.0 + s * p["beta_f"])
    k_unit = modes.beta ** 4 * L
    qm = Q / (s[:, None] ** 2 * rhoA * L + EIs[:, None] * k_unit[None, :])
    resid = (stat - Q @ (modes.tip / k_unit)) / EIs
    tip = (qm @ modes.tip + resid) * model.output_response(s, p)
    current = w * Yp * (Lc + intU)
    cs = n * model.hook("solvent_factor")(s, p) * cint * (Lc + intU) / Lt
    fn = modes.natural_frequencies(float(EI(np.array([0.0]))[0].real), rhoA)
    return tip, current, cs, fn
