"""What :func:`~physics.identify.identify` and :func:`~physics.diagnose.diagnose` share: how
the measurements are read and how a model is fitted to them, in one options object; and the
least-squares search settings of ``identify`` alone (:class:`LsqOptions`)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from ..compare import FRFOptions
from ..errors import InputError
from ..execution.parallel import ParallelSettings

#: Default RH tolerance [%]: a hygrometer's (records within it are one humidity level).
RH_TOLERANCE = 1.0


@dataclass
class FitOptions:
    """Measurement and fit options of ``identify`` and ``diagnose``.

    Measurements: ``rh`` [%] for records without an RH column; ``rh_tolerance`` [%] groups
    records into humidity levels (a hygrometer's tolerance, default ±1 %; a group is labelled
    by its nominal value); ``sensor_bandwidth`` ("auto": from the records' metadata, a number
    [Hz], or None); ``frf`` how time records become frequency responses
    (:class:`~physics.compare.FRFOptions`); ``min_coherence`` and ``weighting`` of the FRF
    lines.  Fit: ``free`` and ``per_rh`` parameters (names or "a,b"), ``start`` {name: SI} or
    "kf=0.004,Y=0.2 GPa", ``bounds`` {name: (lo, hi)} or "kf=1e-4:1e-1", ``n_starts`` (None:
    the caller's default), ``keep_starts`` (None: every start of a fit runs to convergence; a
    number: all are screened by a short run and only that many go on,
    :func:`~physics.identify.fitting.fit_lsq` ``keep``), ``seed``, ``n_modes``, ``settings``
    (where the fits run, :mod:`physics.execution.parallel`)."""

    rh: float | None = None
    rh_tolerance: float = RH_TOLERANCE
    sensor_bandwidth: object = "auto"
    frf: FRFOptions = field(default_factory=FRFOptions)
    min_coherence: float = 0.0
    weighting: str = "coherence"
    free: Sequence[str] | str | None = None
    per_rh: Sequence[str] | str = ()
    start: Mapping | str | None = None
    bounds: Mapping | str | None = None
    n_starts: int | None = None
    keep_starts: int | None = None
    seed: int = 0
    n_modes: int = 4
    settings: ParallelSettings | None = None

    #: Keyword names accepted by :meth:`merged` besides the fields (their older spellings).
    ALIASES = {"frf_options": "frf"}

    @classmethod
    def merged(cls, options: "FitOptions | None", **given) -> "FitOptions":
        """``options`` (or the defaults) with the keyword values in ``given`` replacing
        theirs (``None`` values of ``free`` leave it unset); unknown names are refused."""
        opts = options if options is not None else cls()
        names = {f.name for f in dataclasses.fields(cls)}
        out = {}
        for k, v in given.items():
            k = cls.ALIASES.get(k, k)
            if k not in names:
                raise InputError(f"unknown option {k!r}; known: {', '.join(sorted(names))}")
            if k == "frf" and v is None:
                continue
            out[k] = v
        new = dataclasses.replace(opts, **out)
        if not (new.rh_tolerance >= 0):
            raise InputError(f"rh_tolerance={new.rh_tolerance!r} must be a non-negative number of % RH")
        k = new.keep_starts
        if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 1):
            raise InputError(f"keep_starts={new.keep_starts!r} must be a whole number ≥ 1 (or None: every start "
                             "runs to convergence)")
        return new

    def describe(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("settings", "frf")}
        d["frf"] = vars(self.frf).copy()
        return d


@dataclass(frozen=True)
class LsqOptions:
    """The multi-start least-squares search of ``identify`` (:func:`~physics.identify.fitting.fit_lsq`):
    the Latin-hypercube starts lie within ``start_spread`` decades of the start; ``max_nfev``
    caps the model evaluations of each start (None: SciPy's default)."""

    start_spread: float = 1.0
    max_nfev: int | None = None
