"""One test-bed case: the records a lab would hand over, what the user passes to ``eap diagnose``,
and the answer the diagnosis should give.

Nothing here imports the package under test: the records are written with a few lines of csv
and YAML of our own, in the format ``eap compare``/``eap diagnose`` read (columns
``quantity_unit``, a sidecar ``NAME.yaml`` beside ``NAME.csv``).

Scoring conventions (the same as the diagnosis's, re-implemented): a record's *nuisance terms*
are the least-squares offset and linear drift of its residual; the offset is quoted at the
record's start.  :meth:`Case.true_error` is the RMS over all samples of (measured − true clean
deflection) with each record's nuisance terms removed — the level a perfect model reaches.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml


@dataclass
class Record:
    """One exported record.  ``clean`` is the deflection the sensor sees without its noise,
    offset or quantisation [m]; ``measured`` what the file holds [m]; ``offset`` the sensor's
    true offset [m]; ``rh`` the RH column [%] (hygrometer reading); ``meta`` the sidecar."""

    name: str
    time: np.ndarray
    voltage: np.ndarray
    measured: np.ndarray
    clean: np.ndarray
    rh: np.ndarray
    offset: float
    meta: dict = field(default_factory=dict)


@dataclass
class Truth:
    """What is hidden and what the diagnosis should answer.

    ``kind``: ``none`` (nothing beyond the family's base physics), ``catalog`` (an analogue of
    one catalog effect, written in the family), ``outside`` (physics no catalog effect has),
    ``twin`` (a near twin of a catalog effect, outside its parametrisation) or ``pair`` (two
    hidden effects).  ``expected``: catalog ids the verdict must name (empty: none);
    ``acceptable``: ids that may be named without being wrong (a near twin's relative);
    ``ingredients``: the family's physics switched on (names of the family's own forms)."""

    name: str
    kind: str
    expected: tuple = ()
    acceptable: tuple = ()
    ingredients: tuple = ()
    slow: bool = False          # slow physics (back-relaxation, fractional memory): the lab-export target

    def judge_pick(self, effect: str) -> str:
        """``right`` (expected), ``acceptable`` or ``wrong`` for one named effect."""
        if effect in self.expected:
            return "right"
        if effect in self.acceptable:
            return "acceptable"
        return "wrong"


@dataclass
class Case:
    """Records of one (family, truth, seed) and what a user would pass to the command line.

    ``params``: ``--param NAME=VALUE`` geometry the lab knows; ``effects``: the user's
    ``--effects``; ``truth_params``: the drawn values of the hidden physics; ``noise_floor``:
    the sensor's white noise and quantisation [m]; ``units``: column units of the export."""

    family: str
    truth: Truth
    seed: int
    records: list
    params: dict
    effects: str
    truth_params: dict
    noise_floor: float
    device: str = "ipmc_pt_eg"
    units: dict = field(default_factory=lambda: {"deflection": "m"})
    notes: list = field(default_factory=list)

    # --------------------------------------------------------------- scoring
    def true_error(self) -> float:
        """RMS error [m] of the true model, scored like the diagnosis (module doc)."""
        sq = cnt = 0.0
        for r in self.records:
            e = remove_trend(r.measured - r.clean, r.time)
            sq += float(e @ e)
            cnt += e.size
        return math.sqrt(sq / cnt)

    def true_offsets(self) -> dict:
        """{record: (sensor offset [m], offset a perfect model's residual shows at the record's
        start [m])}: the first is what the sensor added, the second the same in the diagnosis's
        convention (its least-squares line through the residual, noise included)."""
        return {r.name: (r.offset, trend_terms(r.measured - r.clean, r.time)[0]) for r in self.records}

    def param_args(self) -> list[str]:
        out = []
        for k, v in self.params.items():
            out += ["--param", f"{k}={v}"]
        return out

    def describe(self) -> dict:
        """A JSON-ready summary: the truth, its answer, the user's command-line choices and the
        true model's error and offsets."""
        return {"family": self.family, "truth": self.truth.name, "kind": self.truth.kind, "seed": self.seed,
                "expected": list(self.truth.expected), "acceptable": list(self.truth.acceptable),
                "slow": self.truth.slow, "ingredients": list(self.truth.ingredients), "device": self.device,
                "params": dict(self.params), "effects": self.effects, "truth_params": _plain(self.truth_params),
                "noise_floor_m": self.noise_floor, "true_error_m": self.true_error(),
                "true_offsets_m": {k: list(v) for k, v in self.true_offsets().items()},
                "records": [r.name for r in self.records], "notes": list(self.notes)}

    # --------------------------------------------------------------- export
    def write(self, folder) -> list[Path]:
        """The records as ``NAME.csv`` + ``NAME.yaml`` in ``folder`` (created).  Returns the CSVs."""
        d = Path(folder)
        d.mkdir(parents=True, exist_ok=True)
        unit = self.units.get("deflection", "m")
        scale = {"m": 1.0, "mm": 1e3, "um": 1e6}[unit]
        digits = {"m": 10, "mm": 5, "um": 2}[unit]
        out = []
        for r in self.records:
            p = d / f"{r.name}.csv"
            cols = [("time_s", r.time, 6), ("voltage_V", r.voltage, 5),
                    (f"deflection_{unit}", scale * r.measured, digits), ("rh_pct", r.rh, 2)]
            _write_csv(p, cols)
            if r.meta:
                (d / f"{r.name}.yaml").write_text(yaml.safe_dump(_plain(r.meta), sort_keys=False), encoding="utf-8")
            out.append(p)
        return out


def _write_csv(path: Path, cols) -> None:
    """A plain comma-separated table; each column rounded to its number of decimals."""
    header = ",".join(c[0] for c in cols)
    arr = np.column_stack([np.round(np.asarray(c[1], dtype=float), c[2]) for c in cols])
    fmt = ",".join(f"%.{c[2]}f" for c in cols)
    tmp = path.with_name(path.name + ".part")
    np.savetxt(tmp, arr, fmt=fmt, delimiter=",", header=header, comments="")
    tmp.replace(path)


def _plain(x):
    """Numbers and containers as plain Python (for YAML/JSON)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    return x


# ------------------------------------------------------------------ nuisance terms


def trend_terms(e: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """(offset at the record's start, slope per second) of the least-squares line through ``e``."""
    e = np.asarray(e, dtype=float)
    tc = t - t.mean()
    slope = float(tc @ e) / float(tc @ tc)
    return float(e.mean() - slope * (t.mean() - t[0])), slope


def remove_trend(e: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``e`` minus its least-squares offset and linear drift."""
    e = np.asarray(e, dtype=float)
    tc = t - t.mean()
    return e - e.mean() - (float(tc @ e) / float(tc @ tc)) * tc


def shared_draw(ing: str, rng) -> dict:
    """Parameters of an ingredient both families draw alike (a near twin's Zener arm, an output
    saturation, and the forms outside the catalog: creep, a second-order sensor low-pass, drift,
    play, dead zone, an eigen-moment load, a dead time of the deflection channel, a sensor's AC
    coupling, mains pickup, a sensor's bowed characteristic and its range cut); {} for another."""
    if ing == "zener":
        return {"zener_delta": float(rng.uniform(0.3, 0.6)), "zener_f_Hz": float(np.exp(rng.uniform(np.log(1), np.log(8))))}
    if ing == "saturation":
        return {"sat_Us_over_amp": float(rng.uniform(0.5, 1.2))}
    if ing == "creep":
        return {"creep_g": float(rng.uniform(0.25, 0.45)), "creep_tau_s": float(np.exp(rng.uniform(np.log(10), np.log(40))))}
    if ing == "lowpass2":
        return {"lowpass_Hz": float(rng.uniform(10, 20)), "lowpass_zeta": float(rng.uniform(0.5, 0.8))}
    if ing == "drift":
        return {"drift_over_noise": float(rng.uniform(5, 10))}
    if ing == "play":
        return {"play_um": float(rng.uniform(30, 80))}
    if ing == "deadzone":
        return {"deadzone_over_amp": float(rng.uniform(0.1, 0.2))}
    if ing == "eigen_moment":
        return {"eigen_moment": 1.0}
    if ing == "delay":
        return {"delay_ms": float(rng.uniform(4, 15))}
    if ing == "ac_coupled":
        return {"highpass_Hz": float(np.exp(rng.uniform(np.log(0.01), np.log(0.04))))}
    if ing == "hum":
        return {"hum_um": float(rng.uniform(2, 4))}
    if ing == "bow":
        return {"bow": float(rng.uniform(0.03, 0.08)) * float(rng.choice([-1.0, 1.0]))}
    if ing == "clipped":
        return {"clip_over_stroke": float(rng.uniform(0.75, 0.9))}
    return {}
