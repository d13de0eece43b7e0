"""How a stored quantity reads on a page and in the terminal: a name, the unit it is shown
in and the factor from the stored value — one table for every command, so a quantity has
one name and one unit everywhere (tip deflections and their errors in µm, frequency
responses in mm/V, errors relative to the signal in %).

Results are stored under program keys with their unit as a suffix, in SI
(``rmse_m``, ``nrmse_heldout_rh_pct``, ``j_err_m_per_V``); :func:`column` gives the
:class:`Column` of a key: an entry of :data:`COLUMNS`, else one read from the key's unit
suffix (:data:`SUFFIXES`) and words (:data:`WORDS`), so a key added by any command reads
like a name with its unit without an entry here.  A key whose unit cannot be read keeps
``unit=None`` and the page audit (``tests/browser_check.py``) flags its header.

The output of a plant is a deflection in metres unless a dataset says otherwise
(``{"name": "level", "unit": "V"}``, with ``"magnitude"``: a typical size of its values);
keys marked ``output`` are shown in the output's reading unit (:func:`reading_unit`: m → µm,
V → mV, or the prefix that shows the magnitude as 0.1–1000).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from typing import Any, Mapping

#: ``unit`` of a dimensionless quantity (a count, a ratio, a correlation).
ONE = ""
#: ``unit`` of a column whose rows carry their own unit (a table of parameters).
PER_ROW = "per row"


@dataclass(frozen=True)
class Column:
    """A column of a table: ``label`` (a name), ``unit`` (shown in brackets; :data:`ONE`
    for a dimensionless quantity, ``None`` when unknown), ``scale`` (shown value = stored
    value × scale), ``digits`` (significant digits) and ``output`` (the quantity is the
    plant's output: unit and scale follow the dataset's output, ``si`` being the factor
    from the stored value to the output's unit, 1e-6 for a key stored in µm)."""

    label: str
    unit: str | None = ONE
    scale: float = 1.0
    digits: int = 3
    output: bool = False
    si: float = 1.0

    @property
    def header(self) -> str:
        return f"{self.label} [{self.unit}]" if self.unit and self.unit != PER_ROW else self.label

    def for_output(self, output: Mapping[str, Any] | None) -> "Column":
        """This column for a plant whose output is ``{"name", "unit"}`` (default: metres)."""
        if not self.output:
            return self
        unit, scale = reading_unit((output or {}).get("unit") or "m", (output or {}).get("magnitude"))
        return replace(self, unit=unit, scale=scale * self.si)


_col = Column


#: The unit a stored unit is read in, and the factor: tips and errors in µm, volts in mV.
READING = {"m": ("µm", 1e6), "mm": ("µm", 1e3), "um": ("µm", 1.0), "µm": ("µm", 1.0), "V": ("mV", 1e3),
           "m/V": ("mm/V", 1e3)}


#: Engineering prefixes by power of ten (a reading unit chosen by magnitude, :func:`reading_unit`).
PREFIXES = {-12: "p", -9: "n", -6: "µ", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}
#: Units that take a prefix (a stored unit is one of these, possibly prefixed: mm, mV, kPa).
PREFIXABLE = ("m", "V", "A", "W", "N", "Pa", "g", "s", "Hz", "Ω")
_PREFIX_OF = {"u": -6, **{v: k for k, v in PREFIXES.items() if v}}


def _split_prefix(unit: str) -> tuple[str, int] | None:
    """(base unit, power of ten of its prefix) of a prefixable unit: "mm" → ("m", -3)."""
    if unit in PREFIXABLE:
        return unit, 0
    if len(unit) > 1 and unit[0] in _PREFIX_OF and unit[1:] in PREFIXABLE:
        return unit[1:], _PREFIX_OF[unit[0]]
    return None


def reading_unit(unit: str, magnitude: float | None = None) -> tuple[str, float]:
    """(unit shown, factor from ``unit``) for a stored unit: its usual reading (tips in µm,
    volts in mV; other units as they are); with ``magnitude`` (a typical size of the values
    in ``unit``, e.g. the largest) the reading keeps that unit only if it shows the magnitude
    as 0.1–1000, else takes the engineering prefix that does (a level of 35 V reads in V,
    not 35 000 mV)."""
    shown, scale = READING.get(unit, (unit, 1.0))
    if magnitude is None or not math.isfinite(magnitude) or magnitude <= 0 or 0.1 <= magnitude * scale < 1000:
        return shown, scale
    split = _split_prefix(unit)
    if split is None:
        return shown, scale
    base, p = split
    e = 3 * math.floor((math.log10(magnitude) + p) / 3)     # the value in base units is magnitude × 10^p
    e = min(max(e, min(PREFIXES)), max(PREFIXES))
    return PREFIXES[e] + base, 10.0 ** (p - e)


#: Unit suffixes of stored keys, longest first: (suffix, unit shown, scale, output quantity).
SUFFIXES = (("_mm_per_V", "mm/V", 1.0, False), ("_m_per_V", "mm/V", 1e3, False), ("_per_s", "1/s", 1.0, False),
            ("_pct", "%", 1.0, False), ("_percent", "%", 1.0, False), ("_um", "µm", 1.0, True),
            ("_mm", "µm", 1e3, True), ("_m", "µm", 1e6, True), ("_mV", "mV", 1.0, False),
            ("_Hz", "Hz", 1.0, False), ("_s", "s", 1.0, False), ("_dB", "dB", 1.0, False),
            ("_deg", "°", 1.0, False), ("_V", "V", 1.0, False), ("_ohm", "Ω", 1.0, False))

#: Units a header may end with, unbracketed ("held-out RH %", "multisine mV").
TRAILING_UNITS = ("%", "mV", "V", "µm", "mm", "s", "ms", "Hz", "dB", "°", "samples/s", "mm/V", "µm/V")

#: Words of stored keys as they read in a header.
WORDS = {"nrmse": "NRMSE", "rmse": "RMSE", "rms": "RMS", "rh": "RH", "heldout": "held-out", "frf": "FRF",
         "corr": "correlation", "fs": "sampling rate", "bic": "BIC", "dof": "degrees of freedom",
         "ci95": "95 % interval", "std": "std", "lo": "low", "hi": "high", "num": "number of",
         "n": "number of", "pct": "", "nn": "network", "mag": "magnitude", "log": "log", "err": "error",
         "j": "J", "val": "validation", "abs": "absolute", "rel": "relative"}

_NRMSE = 100.0   # NRMSE stored as a fraction, shown in %
#: Explicit entries (the keys every page shows; others are read from their suffix).
COLUMNS: dict[str, Column] = {
    # identification of a row
    "model": _col("model"), "record": _col("record"), "source": _col("record"), "kind": _col("kind"),
    "effect": _col("effect"), "parameter": _col("parameter"), "quantity": _col("quantity"),
    "group": _col("test group"), "status": _col("status"), "evidence": _col("evidence"),
    # sizes and counts
    "parameters": _col("parameters", ONE), "n_parameters": _col("parameters", ONE),
    "records": _col("records", ONE), "frf_points": _col("FRF points", ONE), "n_points": _col("FRF points", ONE),
    "evaluations": _col("model evaluations", ONE), "epochs": _col("epochs", ONE), "start": _col("start", ONE),
    # network tables (nnmodel.traincompare.table_rows)
    "train_time_s": _col("training time", "s"), "samples_per_s": _col("speed", "samples/s"),
    "nrmse_test_pct": _col("test NRMSE", "%"), "nrmse_heldout_rh_pct": _col("held-out RH NRMSE", "%"),
    "nrmse_train_rh_pct": _col("trained RH NRMSE", "%"),
    "nrmse_varying_rh_pct": _col("varying RH NRMSE", "%"),
    "nrmse_measurement_like_pct": _col("measurement-like NRMSE", "%"),
    "fit_heldout_pct": _col("held-out RH fit", "%"), "corr_heldout": _col("held-out RH correlation", ONE),
    "one_step_nrmse_test_pct": _col("one-step test NRMSE", "%"),
    # time-domain and FRF metrics (physics.compare)
    "rh_pct": _col("RH", "%"), "fit_percent": _col("fit", "%"), "nrmse": _col("NRMSE", "%", _NRMSE),
    "nrmse_in_band": _col("NRMSE in band", "%", _NRMSE), "correlation": _col("correlation", ONE),
    "rmse_m": _col("RMSE", "µm", 1e6, output=True), "rmse": _col("RMSE", "µm", 1e6, output=True),
    "residual_rms_m": _col("residual RMS", "µm", 1e6, output=True),
    "noise_floor_m": _col("noise floor", "µm", 1e6, output=True),
    "j_err_m_per_V": _col("J_err (eq. 13)", "mm/V", 1e3), "log_mag_rms_dB": _col("|H| error RMS", "dB"),
    "phase_rms_deg": _col("phase error RMS", "°"), "band_Hz": _col("band", "Hz"),
    "fit_percent_mean": _col("mean fit", "%"), "fit_percent_min": _col("worst fit", "%"),
    "nrmse_mean": _col("mean NRMSE", "%", _NRMSE), "correlation_mean": _col("mean correlation", ONE),
    "rmse_m_rms": _col("RMSE (RMS over records)", "µm", 1e6, output=True),
    "duration_s": _col("duration", "s"), "fs_Hz": _col("sampling rate", "Hz"),
    "fs_analysis_Hz": _col("analysis rate", "Hz"), "amplitude_level_V": _col("amplitude", "V"),
    "noise_floor_source": _col("noise floor from"),
    # diagnosis
    "rmse_um": _col("RMS error", "µm", output=True, si=1e-6), "delta_bic": _col("ΔBIC", ONE, digits=4),
    "ΔBIC": _col("ΔBIC", ONE, digits=4), "p": _col("p-value", ONE, digits=2), "p_value": _col("p-value", ONE, digits=2),
    "signature": _col("signature score", ONE), "confidence": _col("confidence", ONE),
    # identification
    "initial": _col("start", PER_ROW, digits=4), "value": _col("identified", PER_ROW, digits=4),
    "std_error": _col("1σ", PER_ROW, digits=2), "rel_std_error": _col("relative 1σ", "%", 100.0, digits=2),
    "ci95_lo": _col("95 % low", PER_ROW, digits=4), "ci95_hi": _col("95 % high", PER_ROW, digits=4),
    "lower_bound": _col("lower bound", PER_ROW), "upper_bound": _col("upper bound", PER_ROW),
    "cost": _col("cost (½ Σ residual²)", ONE),
    "training records": _col("training records", ONE), "seconds of data": _col("training data", "s"),
    # dimensionless quantities named for a reader by the page that shows them
    **{label: _col(label, ONE) for label in ("model evaluations", "residual variance s²", "degrees of freedom",
                                             "condition number of J", "ΔBIC if removed", "evaluations",
                                             "BIC (effective n)", "test", "iterations", "trial", "cases", "seeds")},
}


def _words(stem: str) -> str:
    out = [WORDS.get(w, w) for w in stem.split("_") if w]
    return re.sub(r"\s+", " ", " ".join(w for w in out if w)).strip()


def column(key: str, output: Mapping[str, Any] | None = None) -> Column:
    """The :class:`Column` of a stored key (or of a header already written for a reader,
    such as ``"RMS after [µm]"``, returned as it is)."""
    key = str(key)
    if key in COLUMNS:
        return COLUMNS[key].for_output(output)
    words = key.rsplit(" ", 1)
    if len(words) == 2 and words[1] in TRAILING_UNITS:   # "held-out RH %" → held-out RH [%]
        return Column(words[0], words[1])
    if "[" in key or " " in key or "_" not in key:
        return Column(key, None)
    for suffix, unit, scale, out in SUFFIXES:
        if key.endswith(suffix) and len(key) > len(suffix):
            stem = key[:-len(suffix)]
            if suffix == "_pct" and stem.startswith("nrmse"):
                stem = stem[len("nrmse"):] + "_nrmse"
            si = {"_um": 1e-6, "_mm": 1e-3}.get(suffix, 1.0)
            return Column(_words(stem), unit, scale, output=out, si=si).for_output(output)
    return Column(_words(key), None)


_SUP = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def number(x: Any, digits: int = 3) -> str:
    """A number as a reader wants it: ``digits`` significant digits in plain notation
    from 0.001 to 100 000 (integer digits are never cut: 194, 12346), ``3.11×10⁻⁵``
    outside; integers as they are; a missing value (None, NaN) as an en dash; ±∞ spelt."""
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int) or (hasattr(x, "dtype") and getattr(x.dtype, "kind", "") in "iu"):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "–"
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    if x == 0:
        return "0"
    e = math.floor(math.log10(abs(x)))
    if -3 <= e < 5:
        dec = max(0, digits - 1 - e)
        return f"{x:.{dec}f}"
    mant, exp = f"{x:.{max(digits - 1, 0)}e}".split("e")
    return f"{mant}×10{str(int(exp)).translate(_SUP)}"


def quantity(value: Any, unit: str, digits: int = 3) -> str:
    """A stored value with its SI ``unit`` as text in its reading unit (terminal and page),
    the engineering prefix chosen for the value's size (:func:`reading_unit`):
    ``quantity(3.11e-5, "m")`` → ``"31.1 µm"``, ``quantity(2.865e-3, "m")`` → ``"2.87 mm"``,
    ``quantity(0.0012, "V")`` → ``"1.20 mV"``."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return f"– {reading_unit(unit)[0]}"
    shown, scale = reading_unit(unit, abs(float(value)) or None)
    return f"{number(float(value) * scale, digits)} {shown}"


def band(lo: float, hi: float) -> str:
    """A frequency band with rounded edges: ``band(0.1333, 1.0)`` → ``"0.13–1 Hz"``."""
    def edge(f):
        return f"{f:.2g}" if f < 10 else f"{f:.3g}" if f < 1000 else f"{f:.0f}"
    return f"{edge(lo)}–{edge(hi)} Hz"


__all__ = ["Column", "COLUMNS", "ONE", "PER_ROW", "column", "number", "quantity", "band", "reading_unit"]
