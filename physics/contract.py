"""The effect contract as a function: :func:`check_effect` runs it on any effect class
(also :func:`physics.effects.check_effect`, which calls it: the checks run the model, the solvers,
``diagnose`` and ``identify``, layers above :mod:`physics.effects`, so they live here and this
module installs itself there when it is first imported).

Checks (each passes, fails with a one-line reason, or is skipped with the reason):

=================  ==========================================================================
declaration        an id, a stage replaced or factors added, parameters declared (a user
                   effect: each with a default), a well-formed ``diagnosis`` spec and
                   ``reference`` (what :func:`physics.effects.register` also refuses)
builds             the model ``none,+id`` builds on the device
protocol           the hooks of the stage it replaces (:mod:`physics.effects.stages`), or a
                   factor hook; a charge law's ``compiled`` law evaluates with the right shapes
finite             frequency response (1 mHz–1 kHz) and a short time simulation are finite
stable             a rational factor (``output_tf``/``load_tf``) is proper with poles in the
                   left half-plane
passive            Re Y_in ≥ 0 (the strip absorbs electrical power), no negative material loss
spec               the diagnosis spec is complete: bounds and starts inside them, roles, off
                   values, signature features (skipped: not a diagnosis candidate)
solvers            frequency and time solvers agree within 1 % / 1° over 0.1–20 Hz (linear; the
                   time response to no input, e.g. an additive drift, subtracted; skipped for a
                   map of the deflection that is nonlinear or changes along the record)
off                the spec's ``off`` values give exactly the model without the effect
identify           identification on its own noise-free FRF recovers the free parameters
                   within 2 % (linear, not fitted through a describing function); parameters
                   the FRF cannot see (:func:`time_only_params`, e.g. an additive drift) are
                   recovered on a noise-free 60 s time record instead
=================  ==========================================================================

``fast=True`` runs the first six (about 0.1 s for the creep example; what loading a user effect file
checks); the full contract takes seconds per effect.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field

import numpy as np

from . import effects, signals
from .device import all_param_specs, load_device
from .effects import BUILT_IN, EFFECTS, Effect, InputEffect, LoadEffect, OutputEffect, register, stage_of, unregister
from .effects.base import rational
from .effects.declaration import declaration_problems
from .execution.usercode import UserCodeError
from .effects.stages import STAGE_PROTOCOLS, CompiledChargeLaw, InputFactor, LoadFactor, OutputFactor
from .errors import InputError, ModelError
from .solvers.frequency import frequency_response
from .model import ActuatorModel
from .solvers.timedomain import simulate

#: Checks run by :func:`check_effect`, in order; ``FAST_CHECKS`` with ``fast=True``.
CHECKS = ("declaration", "builds", "protocol", "finite", "stable", "passive", "spec", "solvers", "off", "identify")
FAST_CHECKS = CHECKS[:6]
DEVICE = "ipmc_pt_eg"
#: The solvers check repeats its 20 s multisine period until the last two periods of an added output
#: filter's response agree to this share of its peak (a slow pole settles over several of its time
#: constants), at most :data:`MAX_PERIODS` periods (~43 min).
SETTLED, MAX_PERIODS = 1e-4, 128


@dataclass
class Check:
    """One check: ``status`` "pass", "fail" or "skip", ``detail`` what was found."""

    name: str
    status: str
    detail: str = ""
    seconds: float = 0.0


@dataclass
class ContractReport:
    """The result of :func:`~physics.effects.check_effect`: one entry per check of the effect contract.

    ``str(report)`` gives a header and one line per check (``PASS``, ``FAIL`` or ``SKIP``, the
    check's name, what was found); ``report["passive"]`` is one check.

    Attributes
    ----------
    effect, device : str
        The effect checked and the device it was added to.
    checks : list
        The checks, each with ``name``, ``status`` (``"pass"``, ``"fail"`` or ``"skip"``),
        ``detail`` and ``seconds``.

    Examples
    --------
    >>> from physics.effects import check_effect
    >>> report = check_effect("solvent_diffusion", fast=True)
    >>> report.ok, report.failures, report["passive"].status
    (True, [], 'pass')
    """

    effect: str
    device: str
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no check failed."""
        return not self.failures

    @property
    def failures(self) -> list[Check]:
        """The checks that failed."""
        return [c for c in self.checks if c.status == "fail"]

    def __getitem__(self, name: str) -> Check:
        return next(c for c in self.checks if c.name == name)

    def __str__(self) -> str:
        n = {s: sum(c.status == s for c in self.checks) for s in ("pass", "fail", "skip")}
        head = (f"effect {self.effect} on {self.device}: contract {'passed' if self.ok else 'FAILED'} "
                f"({n['pass']} passed, {n['fail']} failed, {n['skip']} skipped)")
        width = max(len(c.name) for c in self.checks)
        return "\n".join([head] + [f"  {c.status.upper():4s}  {c.name:{width}s}  {c.detail}" for c in self.checks])

    def raise_on_failure(self, where: str = "") -> None:
        """Raise :class:`~physics.InputError` naming the first failed check (and ``where``)."""
        if self.failures:
            c = self.failures[0]
            raise InputError(f"{where + ': ' if where else ''}effect {self.effect!r} fails the contract check "
                             f"{c.name!r}: {c.detail}")


@contextlib.contextmanager
def _registered(cls):
    """``cls`` registered for the duration (unless it already is); a class registered under
    the same id before (the same effect loaded from another copy of its file, e.g. a kept
    draft checked where it is written) is registered again afterwards."""
    before = EFFECTS.get(cls.id)
    if before is cls:
        yield
        return
    register(cls)
    try:
        yield
    finally:
        unregister(cls.id)
        if before is not None:
            EFFECTS[cls.id] = before


def check_effect(cls, device=DEVICE, *, fast: bool = False, rh: float = 60.0) -> ContractReport:
    """Run the effect contract on effect class ``cls`` (or a registered id) with ``device``
    (name, path or Device) at ``rh`` [%]; ``fast``: the quick checks only (:data:`FAST_CHECKS`).
    Returns a :class:`ContractReport`; a check that raises fails with the exception's message."""
    if isinstance(cls, str):
        if cls not in EFFECTS:
            raise InputError(f"check_effect: unknown effect {cls!r}; known: {', '.join(EFFECTS)}")
        cls = EFFECTS[cls]
    dev = load_device(device)
    report = ContractReport(str(getattr(cls, "id", cls)), dev.name)
    user = not (getattr(cls, "id", None) in BUILT_IN and EFFECTS.get(cls.id) is cls)
    problems = declaration_problems(cls, user=user)
    report.checks.append(Check("declaration", "fail" if problems else "pass",
                               "; ".join(problems) or "id, hooks, parameters, diagnosis spec and reference"))
    if problems:
        report.checks += [Check(n, "skip", "the declaration failed") for n in (FAST_CHECKS if fast else CHECKS)[1:]]
        return report
    ctx = _Context(cls, dev, rh)
    with _registered(cls):
        for name in (FAST_CHECKS if fast else CHECKS)[1:]:
            t0 = time.perf_counter()
            if name != "builds" and ctx.model is None:
                status, detail = "skip", "the model did not build"
            else:
                try:
                    status, detail = getattr(ctx, name)()
                except UserCodeError as exc:   # an exit or an overrun: its own sentence
                    status, detail = "fail", str(exc)
                except Exception as exc:   # a user's hook: report what went wrong, one line
                    status, detail = "fail", f"{type(exc).__name__}: {exc}".splitlines()[0]
            report.checks.append(Check(name, status, detail, time.perf_counter() - t0))
    return report


def _rational_poles(num, den) -> tuple[str, str]:
    num, den = np.atleast_1d(np.asarray(num, float)), np.atleast_1d(np.asarray(den, float))
    num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
    if den.size == 0 or not np.all(np.isfinite(den)) or not np.all(np.isfinite(num)):
        return "fail", "its transfer function has a zero or non-finite denominator"
    if num.size > den.size:
        return "fail", f"improper transfer function (numerator degree {num.size - 1} > denominator {den.size - 1})"
    poles = np.roots(den)
    if np.any(poles.real >= 0):
        worst = poles[np.argmax(poles.real)]
        return "fail", f"unstable: pole at s = {worst:.4g} rad/s (right half-plane or on the axis)"
    return "pass", (f"poles {', '.join(f'{p:.3g}' for p in poles)} rad/s in the left half-plane" if poles.size
                    else "a constant gain")


def _outside(v: float, lo: float, hi: float) -> str | None:
    """None when ``v`` lies in [lo, hi] up to rounding (1e-9 relative: a start clipped to its
    bound is on it), else ``"v outside [lo, hi]"`` with as many digits as tell ``v`` from them."""
    tol = 1e-9 * max(abs(lo), abs(hi), abs(v))
    if lo - tol <= v <= hi + tol:
        return None
    digits = next((k for k in range(4, 18) if float(f"{v:.{k}g}") not in (float(f"{lo:.{k}g}"),
                                                                         float(f"{hi:.{k}g}"))), 17)
    return f"{v:.{digits}g} outside [{lo:.{digits}g}, {hi:.{digits}g}]"


class _Context:
    """State shared by the checks of one effect (the model built once)."""

    def __init__(self, cls, dev, rh):
        self.cls, self.dev, self.rh = cls, dev, rh
        self.model = None

    def builds(self):
        self.model = ActuatorModel(self.dev, f"none,+{self.cls.id}")
        return "pass", f"ActuatorModel({self.dev.name!r}, 'none,+{self.cls.id}')"

    def _bounds(self, name) -> tuple[float, float]:
        """The search range of ``name``: the spec's bounds, else the parameter's admissible range."""
        from .diagnose.specs import param_bounds
        b = param_bounds(name, self.dev)
        if b is None:
            spec = all_param_specs()[name]
            b = (spec.lo, spec.hi)
        return b

    def _instance(self) -> Effect:
        return next(e for e in self.model.effects if type(e) is self.cls)

    def protocol(self):
        e = self._instance()
        default = stage_of(self.cls)
        if default is None:
            kinds = [p.__name__ for p in (LoadFactor, OutputFactor, InputFactor) if isinstance(e, p)]
            if not kinds:
                return "fail", ("adds no factor: define load_factor(s, p), output_response and filter_output, or "
                                "filter_input")
            return "pass", f"adds factors: {', '.join(kinds)}"
        proto = STAGE_PROTOCOLS[default.stage]
        if not isinstance(e, proto):
            missing = [n for n in dir(proto) if not n.startswith("_") and not hasattr(e, n)]
            return "fail", f"stage {default.stage!r}: missing {', '.join(missing)} ({proto.__name__})"
        if default.stage == "charge_law":
            p = self.model.params_at(self.rh)
            try:
                law = e.compiled(self.model.double_layer_props(p), p)
            except ModelError as exc:          # a linear law the stepper cannot carry, said plainly
                if not e.linear:
                    raise
                return "pass", f"stage {default.stage!r} ({proto.__name__}); the time stepper refuses it: {exc}"
            if not isinstance(law, CompiledChargeLaw):
                return "fail", "compiled(d, p) must return an object with evaluate(Q) and excess(Q)"
            Q = np.linspace(-1e-3, 1e-3, 6).reshape(2, 3)
            shapes = [np.shape(a) for a in (*law.evaluate(Q), *law.excess(Q))]
            if any(s != Q.shape for s in shapes) or not all(np.all(np.isfinite(a)) for a in law.evaluate(Q)):
                return "fail", f"compiled law: evaluate/excess must return finite arrays shaped like Q, got {shapes}"
        return "pass", f"stage {default.stage!r} ({proto.__name__})"

    def finite(self):
        f = np.geomspace(1e-3, 1e3, 61)
        fr = frequency_response(self.model, None, f, rh=self.rh)
        bad = f[~(np.isfinite(fr.deflection) & np.isfinite(fr.current))]
        if bad.size:
            return "fail", f"non-finite frequency response at {bad[0]:.3g} Hz ({bad.size} of {f.size} frequencies)"
        sig = signals.tone(0.5, 1.0, 3.0, 100.0)
        y = simulate(self.model, None, sig.t, sig.v, rh=self.rh).deflection
        if not np.all(np.isfinite(y)):
            return "fail", "non-finite deflection in a 3 s, 0.5 V, 1 Hz simulation"
        gain = float(np.max(np.abs(fr.deflection)))
        return "pass", f"1 mHz–1 kHz peak gain {gain:.3g} m/V; 3 s simulation peak {np.max(np.abs(y)):.3g} m"

    def stable(self):
        e, p = self._instance(), self.model.params_at(self.rh)
        for base, name in ((OutputEffect, "output_tf"), (LoadEffect, "load_tf")):
            if isinstance(e, base) and getattr(type(e), name) is not getattr(base, name):
                return _rational_poles(*rational(e, name, p))
        return "skip", "no rational factor (output_tf/load_tf) to check; 'finite' and 'solvers' cover the rest"

    def passive(self):
        m = self.model
        f = np.logspace(-4, 3, 50)
        for rh in ((40.0, 100.0) if m.needs_rh else (self.rh,)):
            fr = frequency_response(m, None, f, rh=rh)
            worst = int(np.argmin(fr.current.real))
            if fr.current.real[worst] < -1e-12 * np.max(np.abs(fr.current)):
                return "fail", f"Re Y_in < 0 at {f[worst]:.3g} Hz, RH {rh:g} % (the strip would deliver power)"
            EI, _ = m.section(m.params_at(rh), float(m.hook("stiffness_factor")(rh)))
            S = 2j * np.pi * f
            if not (np.all(EI(S).imag >= 0) and np.all(EI(S).real > 0)):
                return "fail", f"negative stiffness or material loss at RH {rh:g} %"
        return "pass", "Re Y_in ≥ 0 and EI*(s) with non-negative loss over 0.1 mHz–1 kHz"

    def spec(self):
        spec = self.cls.diagnosis
        if spec is None:
            return "skip", "no diagnosis spec: not a diagnosis candidate"
        from .diagnose.signatures import FEATURE_TEXT
        from .diagnose.specs import start_points
        problems = []
        if "nested" not in spec or not spec.get("excitation"):
            problems.append("needs 'nested' and 'excitation'")
        feats = spec.get("signature") or []
        if not feats or not all(f in FEATURE_TEXT and w > 0 for f, w in feats):
            problems.append(f"signature must list residual features of {sorted(FEATURE_TEXT)} with weights > 0")
        declared = {p.name for p in self.cls.params} | set(self.cls.requires) | set(self.dev.params)
        for name in spec["free"]:
            lo, hi = self._bounds(name)
            if not lo < hi:
                problems.append(f"bounds of {name}: {lo:g} ≥ {hi:g}")
        for st in start_points(self.cls.id, self.dev):
            for name, v in st.items():
                outside = _outside(v, *self._bounds(name))
                if outside:
                    problems.append(f"start {name} = {outside}")
        for role, (name, _rank) in spec.get("roles", {}).items():
            if role not in ("gain", "stiffness") or name not in declared:
                problems.append(f"role {role!r}: {name!r}")
        problems += [f"off value for unknown parameter {n!r}" for n in spec.get("off", {}) if n not in declared]
        return ("fail", "; ".join(problems)) if problems else \
            ("pass", f"free {', '.join(spec['free']) or '(per RH)'}; bounds and starts consistent")

    def _periodic_frf(self, model):
        fs, period = 200.0, 20.0
        sig = signals.multisine(rms=0.02, f_start=0.1, f_stop=20.0, period=period, fs=fs, seed=3)
        n = sig.t.size
        if model.outputs:             # added output filters start from rest: repeat periods until the last
            periods = 8               # two agree (a slow pole settles over several of its time constants),
            while True:               # keep the last; minus the response to no input (a drift is no response)
                v = np.tile(sig.v, periods)
                t = np.arange(v.size) / fs
                y = (simulate(model, None, t, v, rh=self.rh).deflection
                     - simulate(model, None, t, np.zeros_like(v), rh=self.rh).deflection)
                settled = np.max(np.abs(y[-n:] - y[-2 * n:-n])) <= SETTLED * np.max(np.abs(y[-n:]))
                if settled or periods >= MAX_PERIODS:
                    break
                periods *= 2
            y = y[-n:]
        else:
            y = simulate(model, None, sig.t, sig.v, rh=self.rh, periodic=True).deflection
        k = np.arange(int(np.ceil(0.1 * period)), int(20.0 * period) + 1)
        return k / period, np.fft.rfft(y)[k] / np.fft.rfft(sig.v)[k]

    def solvers(self):
        if not self.cls.linear:
            return "skip", "large-signal effect: the frequency solver gives its small-signal form only"
        if issubclass(self.cls, InputEffect) and not self._linear_input_map():
            return "skip", "a nonlinear map of the voltage: the frequency solver gives its small-signal form only"
        if issubclass(self.cls, OutputEffect) and (why := self._output_map_not_lti()):
            return "skip", f"{why}: the frequency solver gives the response at the drive's own lines only"
        f, H = self._periodic_frf(self.model)
        ratio = H / frequency_response(self.model, None, f, rh=self.rh).deflection
        mag, ph = np.max(np.abs(np.abs(ratio) - 1)), np.max(np.abs(np.degrees(np.angle(ratio))))
        detail = f"time vs closed form over 0.1–20 Hz: {100 * mag:.3g} % and {ph:.3g}° at most"
        return ("pass" if mag < 0.01 and ph < 1.0 else "fail"), detail + " (limits 1 %, 1°)"

    def _output_map_not_lti(self) -> str:
        """Why the effect's ``filter_output``, less its response to no input (an additive drift), is
        no linear time-invariant map of the deflection ("" when it is one): superposition on two
        tones, and the response to a tone shifted by a second against the shifted response (an
        even map of the output, a gain that drifts along the record)."""
        e, p = self._instance(), self.model.params_at(self.rh)
        a, b = signals.tone(0.3, 0.7, 8.0, 100.0).v, signals.tone(0.2, 3.0, 8.0, 100.0).v
        zero = np.asarray(e.filter_output(np.zeros_like(a), 100.0, p), float)

        def out(x):
            return np.asarray(e.filter_output(x, 100.0, p), float) - zero
        fa, fb, fab = out(a), out(b), out(2.0 * a + b)
        tol = 1e-9 * np.max(np.abs(fab))
        if not np.allclose(fab, 2.0 * fa + fb, rtol=1e-9, atol=tol):
            return "a nonlinear map of the deflection"
        shifted = out(np.concatenate([np.zeros(100), a[:-100]]))
        if not np.allclose(shifted[400:], fa[300:-100], rtol=1e-6, atol=1e-6 * np.max(np.abs(fa))):
            return "a map of the deflection that changes along the record"
        return ""

    def _linear_input_map(self) -> bool:
        """True when the effect's ``filter_input`` is linear (superposition on two tones)."""
        e, p = self._instance(), self.model.params_at(self.rh)
        a, b = signals.tone(0.3, 0.7, 4.0, 100.0).v, signals.tone(0.2, 3.0, 4.0, 100.0).v
        fa, fb, fab = (np.asarray(e.filter_input(x, 100.0, p), float) for x in (a, b, 2.0 * a + b))
        return bool(np.allclose(fab, 2.0 * fa + fb, rtol=1e-9, atol=1e-12 * np.max(np.abs(fab))))

    def _base_ids(self) -> list[str]:
        """The linear built-in effects, without the one filling the same stage."""
        own = stage_of(self.cls)
        return [e for e in BUILT_IN if EFFECTS[e].linear and e != self.cls.id
                and (own is None or not issubclass(EFFECTS[e], own))]

    def off(self):
        from .diagnose.specs import _scaled
        spec = self.cls.diagnosis or {}
        if not spec.get("off"):
            return "skip", "the spec gives no 'off' values"
        off = {k: _scaled(v, self.dev) for k, v in spec["off"].items()}
        ids = self._base_ids()
        without = ActuatorModel(self.dev, ids)
        with_off = ActuatorModel(self.dev.with_params(**off), ids + [self.cls.id])
        f = np.geomspace(0.01, 50, 40)
        a = frequency_response(with_off, None, f, rh=self.rh).deflection
        b = frequency_response(without, None, f, rh=self.rh).deflection
        err_f = float(np.max(np.abs(a - b) / np.abs(b)))
        sig = signals.tone(0.5, 1.0, 4.0, 200.0)
        ya = simulate(with_off, None, sig.t, sig.v, rh=self.rh).deflection
        yb = simulate(without, None, sig.t, sig.v, rh=self.rh).deflection
        err_t = float(np.max(np.abs(ya - yb)) / np.max(np.abs(yb)))
        # a large-signal effect runs the implicit stepper instead of the exact LTI solution: the
        # two discretisations agree to ~1e-4 of the range, not to rounding
        tol_t = 1e-9 if self.cls.linear else 1e-3
        ok = err_f <= 1e-12 and err_t <= tol_t
        return ("pass" if ok else "fail"), (f"{', '.join(f'{k} = {v:g}' for k, v in off.items())}: frequency "
                                            f"{err_f:.1e}, time {err_t:.1e} from the model without it "
                                            f"(limits 1e-12, {tol_t:g})")

    def identify(self):
        spec = self.cls.diagnosis or {}
        if not (self.cls.linear and spec.get("free") and not spec.get("describing_function")):
            return "skip", "only linear effects with free parameters fitted on the FRF"
        from .diagnose.specs import _scaled, start_points
        from .identify import IdentificationProblem, fit_lsq
        from .identify.problem import FRFTarget
        off = {k: _scaled(v, self.dev) for k, v in spec.get("off", {}).items()}
        starts = start_points(self.cls.id, self.dev)
        truth = {}
        for name in spec["free"]:           # a point inside the bounds, away from the off value and the starts
            lo, hi = self._bounds(name)
            truth[name] = float(np.sqrt(lo * hi)) if lo > 0 else 0.5 * (lo + hi)
            avoid = [off[name]] if name in off else []
            avoid += [st[name] for st in starts if name in st]
            if any(np.isclose(truth[name], a, rtol=1e-6, atol=0) for a in avoid):
                truth[name] = float(np.sqrt(truth[name] * hi)) if lo > 0 else 0.5 * (truth[name] + hi)
        dev = self.dev.with_params(**truth)
        ids = f"none,+{self.cls.id}"
        model = ActuatorModel(dev, ids)
        start = {}
        for n in truth:
            lo, hi = self._bounds(n)
            start[n] = float(np.clip(truth[n] * 1.6 if truth[n] else 0.2 * (hi - lo), lo, hi))
        extra = [{**start, **st} for st in starts]
        blind = time_only_params(model, list(truth), model.params_at(self.rh))
        names = [n for n in truth if n not in blind]
        got = self._identify_in_time(dev, blind, start, extra) if blind else {}
        if names:
            f = np.geomspace(1e-3, 50.0, 120)
            H = frequency_response(model, None, f, rh=self.rh).deflection
            target = FRFTarget("synthetic", f, H, np.ones(f.size), self.rh, None, None, {})
            prob = IdentificationProblem(dev, ids, [target], names, start={n: start[n] for n in names},
                                         bounds={n: self._bounds(n) for n in names})
            fit = fit_lsq(prob, n_starts=2, seed=0, extra_starts=[[st[n] for n in names] for st in extra])
            got.update(zip(prob.labels, fit.theta))
        names = list(truth)
        errs = {n: abs(got[n] - truth[n]) / max(abs(truth[n]), 1e-300) for n in names}
        ok = all(abs(got[n] - truth[n]) <= max(0.02 * abs(truth[n]), 1e-12) for n in names)
        return ("pass" if ok else "fail"), ", ".join(f"{n} {got[n]:.4g} for {truth[n]:.4g} ({100 * errs[n]:.2g} %)"
                                                     for n in names) + " (limit 2 %" \
            + (f"; {', '.join(blind)} on a time record" if blind else "") + ")"

    def _identify_in_time(self, dev, names, start, extra) -> dict:
        """``names`` (parameters the FRF cannot see) fitted by least squares on a noise-free 60 s
        multisine record at 100 Hz of the model with ``dev``'s values: for an output effect the
        rest of the chain is simulated once and each evaluation only filters it; an input effect's
        voltage is mapped and the chain simulated at each evaluation.  The record reaches twice the
        largest threshold in volts among ``names`` (0.3 V RMS at least): a drafted clip of the drive
        checked at 3.79 V under a drive peaking near 1 V was never reached, and the check failed
        a valid effect."""
        from scipy.optimize import least_squares
        units = {q.name: q.unit for q in self.cls.params}
        levels = [abs(float(dev.params[n])) for n in names if units.get(n) == "V" and n in dev.params]
        sig = signals.multisine(rms=0.3, f_start=0.1, f_stop=20.0, period=60.0, fs=100.0, seed=3)
        peak = float(np.max(np.abs(sig.v)))
        if levels and 2.0 * max(levels) > peak:
            sig = signals.multisine(rms=0.3 * 2.0 * max(levels) / peak, f_start=0.1, f_stop=20.0, period=60.0,
                                    fs=100.0, seed=3)
        model = ActuatorModel(dev, f"none,+{self.cls.id}")
        y = simulate(model, None, sig.t, sig.v, rh=self.rh).deflection
        core_model = ActuatorModel(dev, "none")
        core = simulate(core_model, None, sig.t, sig.v, rh=self.rh).deflection
        e, p = self._instance(), model.params_at(self.rh)
        scale = 1.0 / (np.std(y) or 1.0)

        def resid(theta):
            q = {**p, **dict(zip(names, theta))}
            if isinstance(e, InputEffect):
                return (simulate(core_model, None, sig.t, e.filter_input(sig.v, 100.0, q), rh=self.rh).deflection
                        - y) * scale
            return (e.filter_output(core, 100.0, q) - y) * scale

        lo, hi = np.array([self._bounds(n) for n in names], float).T
        best = None
        for st in [start] + list(extra):
            x0 = np.clip([st[n] for n in names], lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
            sol = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", xtol=1e-12, ftol=1e-12, max_nfev=400)
            if best is None or sol.cost < best.cost:
                best = sol
        return dict(zip(names, best.x.tolist()))


def time_only_params(model, names, p: dict) -> list[str]:
    """Of ``names``, the parameters of ``model``'s output and input effects that leave the
    frequency response unchanged (an additive drift acting in ``filter_output`` only, the
    threshold of a dead-zone in ``filter_input``): an FRF cannot determine them, a time record
    can.  ``p``: the model's parameter values [SI]."""
    s = 2j * np.pi * np.array([0.1, 1.0, 10.0])
    out = []
    for e in model.outputs + model.inputs:
        response = e.output_response if e in model.outputs else e.input_response
        own = {q.name for q in e.params}
        for n in names:
            if n in own and n not in out:
                v = float(p.get(n) or 0.0)
                moved = {**p, n: v * 1.5 if v else 1e-3}
                if np.allclose(response(s, p), response(s, moved), rtol=1e-12, atol=0):
                    out.append(n)
    return out


effects._CONTRACT.append(check_effect)      # physics.effects.check_effect runs this
