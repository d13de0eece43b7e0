"""Frequency-domain solver: closed-form small-signal response per volt.

Everything is evaluated exactly (no realisation): the linearised PNP double layer, the
transmission-line voltage cosh(m(L−z))/cosh(mL) integrated against the mode slopes by
Gauss–Legendre quadrature, the solvent factor B(s), kf(s), the Prony modulus and the
modal cantilever plus the exact quasi-static contribution of the higher modes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..execution.threads import single_threaded
from ..errors import InputError
from ..model import ActuatorModel, as_model
from .discretisation import line_functionals, quadrature


@dataclass
class FrequencyResponse:
    """The result of :func:`frequency_response`: the small-signal response per volt at the clamp.

    Sign convention: a positive voltage drives the cations to the upper face (the cathode);
    the strip bends towards the anode, counted positive.

    Attributes
    ----------
    freq : ndarray
        Frequencies [Hz].
    deflection : ndarray of complex
        Tip deflection per volt [m/V].
    current : ndarray of complex
        Current drawn per volt [A/V].
    cs_up : ndarray of complex
        Interface solvent excess at the upper face, averaged over the electrode length
        (thesis eq. 8) [mol/m³ per V]; the lower face's is ``-cs_up``.
    rh : float
        Relative humidity [%].
    device : str
        The device's name.
    effects : tuple of str
        The effects that were on.
    natural_frequencies : ndarray
        Natural frequencies of the first bending modes [Hz].

    Examples
    --------
    >>> import physics
    >>> fr = physics.frequency_response("ipmc_pt_eg", "none", [0.1, 1.0, 10.0])
    >>> [f"{1e3 * m:.3f} mm/V" for m in fr.magnitude]
    ['0.925 mm/V', '0.927 mm/V', '1.165 mm/V']
    >>> f"{fr.natural_frequencies[0]:.1f} Hz"
    '21.7 Hz'
    """

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
        """Electrical input impedance [Ω] (complex)."""
        return 1.0 / self.current

    @property
    def magnitude(self) -> np.ndarray:
        """Magnitude of the tip deflection per volt [m/V]."""
        return np.abs(self.deflection)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase of the tip deflection [°], unwrapped along frequency."""
        return np.degrees(np.unwrap(np.angle(self.deflection)))

    def resonance(self) -> tuple[float, float] | None:
        """The most prominent peak of the deflection magnitude (the first bending resonance).

        Returns
        -------
        tuple of float or None
            (frequency [Hz], magnitude [m/V]) of the peak, or None when the magnitude has no
            local maximum in the frequencies computed.
        """
        from scipy.signal import find_peaks
        idx, props = find_peaks(np.log(self.magnitude), prominence=0.05)
        if idx.size == 0:
            return None
        i = idx[int(np.argmax(props["prominences"]))]
        return float(self.freq[i]), float(self.magnitude[i])

    def to_dict(self) -> dict:
        """The response as plain lists, keys named with their units (what ``eap frf --json`` writes)."""
        return {"device": self.device, "effects": list(self.effects), "rh_pct": self.rh,
                "freq_Hz": self.freq.tolist(), "mag_m_per_V": self.magnitude.tolist(),
                "phase_deg": self.phase_deg.tolist(),
                "impedance_ohm_abs": np.abs(self.impedance).tolist(),
                "impedance_phase_deg": np.degrees(np.angle(self.impedance)).tolist(),
                "cs_up_mol_m3_per_V_abs": np.abs(self.cs_up).tolist(),
                "natural_frequencies_Hz": self.natural_frequencies.tolist()}


@single_threaded
def frequency_response(device, effects=None, freqs=None, rh=None, *, n_modes: int = 4) -> FrequencyResponse:
    """Closed-form small-signal frequency response of a strip, per volt at the clamp.

    Parameters
    ----------
    device : str, path or Device
        A device name, a device YAML file, a :class:`~physics.Device`, or a model already
        built with its effects (then ``effects`` may be left out).
    effects : str or list of str, optional
        Effect ids and groups as for :func:`simulate` (default: the device's own list).
    freqs : array_like, optional
        Frequencies [Hz], finite and positive (default: 500 log-spaced points over 0.1–50 Hz).
    rh : float, optional
        Relative humidity [%]; required when the ``humidity`` effect is on.
    n_modes : int, optional
        Bending modes resolved dynamically (default 4).

    Returns
    -------
    FrequencyResponse
        Tip deflection [m/V], current [A/V] and interface solvent excess [mol/m³ per V] at
        each frequency, with the first natural frequencies [Hz].

    Examples
    --------
    The first bending resonance of the thesis IPMC moves down as the polymer takes up water
    (Table V: drier is stiffer):

    >>> import numpy as np, physics
    >>> f = np.logspace(-1, 2, 600)
    >>> for rh in (40, 100):
    ...     f_res, peak = physics.frequency_response("ipmc_pt_eg", "default", f, rh=rh).resonance()
    ...     print(f"RH {rh} %: {f_res:.1f} Hz, {1e3 * peak:.2f} mm/V")
    RH 40 %: 36.2 Hz, 0.83 mm/V
    RH 100 %: 22.1 Hz, 3.29 mm/V
    """
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


def response_per_volt(model: ActuatorModel, s: np.ndarray, rh: float, p: dict | None = None):
    """(tip [m/V], current [A/V], Cs_up [mol/m³/V], natural frequencies [Hz]) at ``s`` [rad/s];
    ``p``: ``model.params_at(rh)`` when the caller has it already."""
    p = model.params_at(rh) if p is None else p
    d = model.double_layer_props(p)
    q, cint = model.hook("small_signal")(s, d, p)
    Yp = s * q + d.G_leak
    L, Lc, Lt = model.free_length, p["L_clamp"], p["L_total"]
    w, h, n = p["width"], 0.5 * p["t_polymer"], p["n_solvation"]
    zq, _ = quadrature(L)
    U = model.hook("distribution")(s, Yp, p, zq)                 # (n_s, n_q) per volt
    modes = model.modes()
    ints = U @ line_functionals(L, modes.n_modes)                   # ∫U, ∫U phi_i', ∫U a(L − a/2)
    intU = ints[:, 0]
    load = model.load_response(s, p) * cint
    c = 2.0 * h * w * n * load                                      # couple per volt and unit U [N m/m/V]
    Q = c[:, None] * ints[:, 1:-1]                                  # generalised loads (n_s, n_modes)
    stat = c * ints[:, -1]
    EI, rhoA = model.section(p, float(model.hook("stiffness_factor")(rh)))
    EIs = EI(s) * (1.0 + s * p["beta_f"])
    k_unit = modes.beta ** 4 * L
    qm = Q / (s[:, None] ** 2 * rhoA * L + EIs[:, None] * k_unit[None, :])
    resid = (stat - Q @ (modes.tip / k_unit)) / EIs
    drive = model.input_response(s, p)                              # the voltage the strip sees, per volt
    tip = (qm @ modes.tip + resid) * model.output_response(s, p) * drive
    current = w * Yp * (Lc + intU) * drive
    cs = n * model.hook("solvent_factor")(s, p) * cint * (Lc + intU) / Lt * drive
    fn = modes.natural_frequencies(float(EI(np.array([0.0]))[0].real), rhoA)
    return tip, current, cs, fn
