"""Frequency-response files (``docs/reference/file-formats.md``).

A CSV with one row per frequency: ``freq_Hz``, ``mag_m_per_V`` (or ``mag_mm_per_V``),
``phase_deg`` and optionally ``coherence`` (γ², 0–1) and ``rh_pct`` (%).  Frequencies
must be positive and strictly increasing, magnitudes non-negative, every value finite;
violations raise :class:`~physics.errors.InputError` naming the file, line and column.
An optional sidecar ``NAME.yaml`` is read into ``meta``.  Files are written atomically
with the magnitude in m/V and the phase unwrapped along frequency.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .csvtable import check_input_path, read_table, write_table
from .record import Locate, check_finite, check_range
from .sidecar import read_sidecar
from .timeseries import parse_header

#: Largest |H| [m/V] a file may hold: strips give µm–mm per volt; far beyond is a unit error.
PLAUSIBLE_GAIN = 1e3
#: quantity -> {unit: scale to stored units}; ``coherence`` has no unit.
FRF_UNITS: dict[str, dict[str, float]] = {
    "freq": {"Hz": 1.0},
    "mag": {"m_per_V": 1.0, "mm_per_V": 1e-3},
    "phase": {"deg": 1.0},
    "coherence": {"": 1.0},
    "rh": {"pct": 1.0},
}


@dataclass
class FRFData:
    """A measured or simulated frequency response of tip deflection to voltage.

    ``freq`` Hz (positive, strictly increasing); ``response`` complex, m/V;
    ``coherence`` γ² in 0–1 or ``None``; ``rh`` % as a constant, one value per
    frequency, or ``None``.
    """
    freq: np.ndarray
    response: np.ndarray
    coherence: np.ndarray | None = None
    rh: np.ndarray | float | None = None
    meta: dict = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self):
        self.freq = np.asarray(self.freq, dtype=float)
        self.response = np.asarray(self.response, dtype=complex)
        if self.coherence is not None:
            self.coherence = np.asarray(self.coherence, dtype=float)
        if self.rh is not None:
            rh = np.asarray(self.rh, dtype=float)
            self.rh = float(rh) if rh.ndim == 0 else rh
        where = self.source or "FRF data"
        n = self.freq.size
        for name in ("freq", "response", "coherence", "rh"):
            arr = getattr(self, name)
            if isinstance(arr, np.ndarray) and (arr.ndim != 1 or arr.size != n):
                raise InputError(f"{where}: {name} must be a 1-D array of {n} values (one per "
                                 f"frequency), got shape {arr.shape}")
        if n == 0:
            raise InputError(f"{where}: no frequencies")
        _check_frf(self.freq, self.response, self.coherence, self.rh, where,
                   lambda i: f"point {i}")

    @property
    def magnitude(self) -> np.ndarray:
        """|H| (m/V)."""
        return np.abs(self.response)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase (deg), unwrapped along frequency."""
        return np.degrees(np.unwrap(np.angle(self.response)))


def _check_frf(freq, response, coherence, rh, where: str, locate: Locate) -> None:
    check_finite(freq, where, locate, "freq")
    bad = np.flatnonzero(freq <= 0)
    if bad.size:
        raise InputError(f"{where}, {locate(bad[0])}, freq: {float(freq[bad[0]])!r} Hz is not "
                         "positive; frequencies must be > 0")
    bad = np.flatnonzero(np.diff(freq) <= 0)
    if bad.size:
        i = bad[0] + 1
        raise InputError(f"{where}, {locate(i)}, freq: {float(freq[i])!r} Hz is not above the "
                         f"previous {float(freq[i - 1])!r} Hz; frequencies must be strictly "
                         "increasing")
    check_finite(response.real, where, locate, "response")
    check_finite(response.imag, where, locate, "response")
    if coherence is not None:
        check_finite(coherence, where, locate, "coherence")
        check_range(coherence, 0.0, 1.0, where, locate, "coherence", "(γ²)")
    if isinstance(rh, np.ndarray):
        check_finite(rh, where, locate, "rh")
        check_range(rh, 0.0, 100.0, where, locate, "rh", "%")
    elif rh is not None and not 0.0 <= rh <= 100.0:
        raise InputError(f"{where}: rh {rh!r} % is outside 0–100 %")


def read_frf(path) -> FRFData:
    """Read a frequency-response CSV (see module doc) into :class:`FRFData`."""
    p = check_input_path(path, (".csv",))
    table = read_table(p)
    values: dict[str, np.ndarray] = {}
    names: dict[str, str] = {}
    for name in table.columns:
        quantity, unit = parse_header(name, FRF_UNITS, p)
        if quantity in names:
            raise InputError(f"{p}: columns {names[quantity]!r} and {name!r} both give "
                             f"{quantity}; keep one")
        names[quantity] = name
        values[quantity] = table.floats(name) * FRF_UNITS[quantity][unit]
    for quantity in ("freq", "mag", "phase"):
        if quantity not in values:
            accepted = " or ".join(f"{quantity}_{u}" for u in FRF_UNITS[quantity])
            raise InputError(f"{p}: missing column {accepted}")
    bad = np.flatnonzero(values["mag"] < 0)
    if bad.size:
        raise InputError(f"{p}, {table.locate(bad[0])}, column {names['mag']!r}: magnitude "
                         f"{float(values['mag'][bad[0]])!r} is negative; expected |H| >= 0")
    check_range(values["mag"], 0.0, PLAUSIBLE_GAIN, str(p), table.locate, f"column {names['mag']!r}",
                "m/V (a larger gain is a unit or export error, and overflows the metrics)")
    response = values["mag"] * np.exp(1j * np.radians(values["phase"]))
    _check_frf(values["freq"], response, values.get("coherence"), values.get("rh"), str(p),
               table.locate)
    return FRFData(values["freq"], response, values.get("coherence"), values.get("rh"),
                   meta=read_sidecar(p), source=str(p))


def write_frf(frf: FRFData, path, *, overwrite: bool = False, protect=()) -> Path:
    """Write ``frf`` atomically as CSV (m/V, unwrapped phase in degrees, full float
    precision) plus the sidecar ``NAME.yaml`` when ``frf.meta`` is non-empty."""
    cols = {"freq_Hz": frf.freq, "mag_m_per_V": frf.magnitude, "phase_deg": frf.phase_deg}
    if frf.coherence is not None:
        cols["coherence"] = frf.coherence
    if frf.rh is not None:
        cols["rh_pct"] = np.broadcast_to(frf.rh, frf.freq.shape)
    return write_table(cols, frf.meta, path, overwrite=overwrite, protect=protect)
