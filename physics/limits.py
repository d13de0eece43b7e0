"""Bounds on what a caller may ask for, checked before anything is allocated or solved.

One place for the sizes and ranges every entry point shares, so that a typo (``1e6`` V,
``--n-modes 1000000``, ``--f-max-Hz 1e300``) is one clear error instead of a hang, an
exhausted memory or an overflow deep in a solver.  Each bound is far beyond any real
use of the package and says why it exists.
"""
from __future__ import annotations

import math

from .errors import InputError

#: Bending modes a model retains: beyond a few dozen the modes lie decades above any
#: measured band (the rest of the response is kept quasi-statically), and cosh(βL) of
#: the mode shapes overflows past ~220.
MAX_MODES = 64
#: Frequencies of one closed-form response (a Bode plot needs a few hundred).
MAX_FREQUENCIES = 1_000_000
#: Frequencies a response or an excitation may have [Hz]: actuators and their sensors
#: live within mHz–kHz; beyond this range the closed forms overflow.
FREQ_RANGE_HZ = (1e-6, 1e6)
#: Sampling rates a record may have [Hz]: beyond them a time step is an export error (a
#: step of 1e288 s or 1e-302 s), and every solver and spectrum estimate breaks down.
FS_RANGE_HZ = (1e-6, 1e9)
#: Samples of a generated excitation (simulate, generate): 2·10⁷ is 5.5 h at 1 kHz and
#: already ~1 GB of channels in memory; split longer runs.
MAX_SAMPLES = 20_000_000
#: Samples × sampling rate [Hz] of one simulation (``simulate``): the time solver's
#: realisation resolves the response up to half the rate, so its work per sample grows with
#: the rate (measured on a loaded 2-core machine: 12 µs per sample at 1 kHz, 80 µs at
#: 1 MHz, 125 µs at 1 GHz).  The cap lets :data:`MAX_SAMPLES` through up to 10 kHz and
#: 2·10⁵ samples at 1 MHz; 2·10⁷ samples at 1 GHz (an hour) are refused at once.
MAX_SAMPLES_X_RATE = 2e11
#: Largest plausible gain of a strip's tip deflection per volt [m/V] (measured strips give
#: µm–mm per volt; a response beyond is a unit error or an unstable model, not physics).
MAX_GAIN_M_PER_V = 1.0
#: Largest drive voltage [V] (the reader's plausibility rule for a measured drive).
MAX_DRIVE_V = 1e3


def check_range(value, lo: float, hi: float, what: str, why: str = "") -> float:
    """``value`` as a float after checking that it is finite and within [lo, hi]."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what} {value!r}: expected a number") from None
    if not (math.isfinite(x) and lo <= x <= hi):
        raise InputError(f"{what} {value!r}: must lie within {lo:g}–{hi:g}" + (f" ({why})" if why else ""))
    return x


def check_count(value, lo: int, hi: int, what: str, why: str = "") -> int:
    """``value`` as an int after checking that it is a whole number within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(f"{what} {value!r}: must be a whole number within {lo:,}–{hi:,}"
                         + (f" ({why})" if why else ""))
    return value
#: Highest order of a rational factor an effect gives (``output_tf``, ``load_tf``): physical
#: factors have a few poles; the roots, the Tustin discretisation and the filter's start state
#: cost order² to order³ (a 5000-order factor takes minutes), so the order is checked first.
MAX_TF_ORDER = 32
#: Multi-start count of one fit (identify, diagnose ``--starts``): each start is a full
#: least-squares fit; a few dozen already cover a parameter space.
MAX_STARTS = 256
#: Trials of a hyper-parameter search per model (``train-compare --tune``): each trains a
#: network; Optuna's TPE settles within a few dozen.
MAX_TUNE_TRIALS = 1000
#: Horizon of a k-step-ahead prediction (``predict --steps-ahead``) [samples]: the work is
#: samples × k model steps; a longer horizon is a free run.
MAX_STEPS_AHEAD = 10_000
