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
