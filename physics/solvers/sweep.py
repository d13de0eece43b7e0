"""Parameter sweeps: the model over a grid of device parameters, RH and amplitudes, as one
tidy table (one row per grid point, the grid as columns), run through :mod:`physics.execution.parallel`.

Grid values are given per name as a list ``a,b,c`` or a range ``lin:a:b:n`` / ``log:a:b:n``,
in the SI unit of the parameter (see ``eap effects``); ``rh`` is in % and ``amplitude`` in V.

Kinds:

* ``frf`` — closed-form response: first resonance [Hz] and its gain [m/V], and gain [m/V] and
  phase [deg] at the chosen frequencies;
* ``simulate`` — time simulation of a sine of ``amplitude`` V at one frequency: the
  deflection's peak-to-peak [m] over the last period (large-signal effects included).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, arg
from ..execution.parallel import ParallelSettings, map_tasks

#: Largest grid accepted (rows); a bigger sweep should be split.
MAX_POINTS = 1_000_000
SPECIAL = {"rh": "%", "amplitude": "V"}


def parse_values(name: str, text: str) -> list[float]:
    """``a,b,c``, ``lin:a:b:n`` or ``log:a:b:n`` → values (errors name the grid entry)."""
    where = f"{arg('grid')} {name}={text}"
    try:
        if text.startswith(("lin:", "log:")):
            kind, a, b, n = text.split(":")
            a, b, n = float(a), float(b), int(n)
            if n < 1 or n > MAX_POINTS:
                raise InputError(f"{where}: the count must lie in 1…{MAX_POINTS}")
            if kind == "log":
                if a <= 0 or b <= 0:
                    raise InputError(f"{where}: a log range needs positive ends")
                return np.geomspace(a, b, n).tolist()
            return np.linspace(a, b, n).tolist()
        vals = [float(v) for v in text.split(",") if v.strip()]
    except InputError:
        raise
    except ValueError:
        raise InputError(f"{where}: expected numbers a,b,c or a range lin:a:b:n / log:a:b:n") from None
    if not vals or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{where}: expected finite numbers")
    return vals


def parse_grid(items, device) -> dict[str, list[float]]:
    """``["Y=1e8,2e8", "rh=40,60"]`` → {name: values}; unknown names are refused."""
    from ..device import all_param_specs
    specs = all_param_specs()
    grid: dict[str, list[float]] = {}
    for item in items:
        name, sep, text = (s.strip() for s in item.partition("="))
        if not sep or not name:
            raise InputError(f"{arg('grid')} {item!r}: expected NAME=VALUES, e.g. Y=lin:1e8:3e8:5 or rh=40,60,80")
        if name in grid:
            raise InputError(f"{arg('grid')}: {name} is given twice")
        if name not in SPECIAL and name not in specs:
            import difflib
            close = difflib.get_close_matches(name, list(specs) + list(SPECIAL), n=3)
            raise InputError(f"{arg('grid')} {name}: unknown parameter" + (f" (did you mean {', '.join(close)}?)" if close
                                                                     else "; see `eap effects` for names"))
        vals = parse_values(name, text)
        if name in specs:
            for v in vals:
                specs[name].check(v, f"{arg('grid')} {name}")
        if name == "rh" and not all(0 <= v <= 100 for v in vals):
            raise InputError(f"{arg('grid')} rh={text}: RH must lie within 0–100 %")
        grid[name] = vals
    if not grid:
        raise InputError(f"give at least one {arg('grid')} entry NAME=VALUES")
    n = math.prod(len(v) for v in grid.values())
    if n > MAX_POINTS:
        raise InputError(f"the grid has {n} points; at most {MAX_POINTS} per sweep — split it")
    return grid


def sweep_task(task: dict) -> dict:
    """One grid point (a plain dict in, a plain row out): runs in any worker."""
    from .frequency import frequency_response
    from ..model import ActuatorModel
    from ..device import load_device
    point = task["point"]
    dev = load_device(task["device"])
    params = {k: v for k, v in point.items() if k not in SPECIAL}
    if params:
        dev = dev.with_params(**params)
    model = ActuatorModel(dev, task["effects"], n_modes=task["n_modes"])
    rh = point.get("rh", task["rh"])
    row = dict(point)
    if task["kind"] == "frf":
        f = np.geomspace(task["f_min"], task["f_max"], 400)
        fr = frequency_response(model, None, f, rh=rh)
        res = fr.resonance()
        row["resonance_Hz"], row["resonance_gain_m_per_V"] = res if res else (math.nan, math.nan)
        at = frequency_response(model, None, task["freqs"], rh=rh)
        for fq, h in zip(task["freqs"], at.deflection):
            row[f"gain_{fq:g}Hz_m_per_V"] = float(abs(h))
            row[f"phase_{fq:g}Hz_deg"] = float(np.degrees(np.angle(h)))
    else:
        from .. import signals
        from .timedomain import simulate
        f0, fs = task["frequency"], task["fs"]
        sig = signals.tone(point.get("amplitude", task["amplitude"]), f0, task["periods"] / f0, fs)
        y = simulate(model, None, sig.t, sig.v, rh=rh).deflection
        last = y[-int(round(fs / f0)):]
        row["deflection_pp_m"] = float(np.ptp(last))
    return row


@dataclass(frozen=True)
class SweepTone:
    """The sine of a ``simulate`` sweep: ``amplitude`` [V] (unless the grid varies it) at
    ``frequency`` [Hz], ``periods`` periods sampled at ``fs`` [Hz]."""

    frequency: float = 1.0
    amplitude: float = 1.0
    fs: float = 200.0
    periods: int = 5


def run_sweep(device, effects, grid: dict[str, list[float]], *, kind: str = "frf", rh: float | None = None,
              freqs=(0.1, 1.0, 10.0), f_range=(0.1, 100.0), tone: SweepTone = SweepTone(), n_modes: int = 4,
              settings: ParallelSettings | None = None, progress: bool = True):
    """The sweep as a pandas DataFrame (grid columns first, in grid order).  ``freqs`` [Hz]: where
    ``frf`` reports gain and phase, ``f_range`` [Hz]: where it looks for the resonance;
    ``tone``: the sine of ``simulate`` (:class:`SweepTone`)."""
    import pandas as pd
    if kind not in ("frf", "simulate"):
        raise InputError(f"{arg('kind')} {kind!r}: expected frf or simulate")
    if not (0 < f_range[0] < f_range[1]):
        raise InputError(f"frequency range {f_range}: must be positive and increasing")
    dev_ref = str(device) if isinstance(device, (str, Path)) else device
    names = list(grid)
    tasks = [{"point": dict(zip(names, combo)), "device": dev_ref, "effects": effects, "rh": rh, "kind": kind,
              "freqs": list(freqs), "f_min": f_range[0], "f_max": f_range[1], "frequency": tone.frequency,
              "amplitude": tone.amplitude, "fs": tone.fs, "periods": tone.periods, "n_modes": n_modes}
             for combo in itertools.product(*(grid[n] for n in names))]
    rows = map_tasks(sweep_task, tasks, settings, desc="sweep", progress=progress)
    return pd.DataFrame(rows)
