"""The effect interface: the one contract every effect, built in or added by a user, follows.

An effect is a switchable piece of physics with a stable ``id``.  It declares, in its own
module, everything the rest of the package needs:

* its parameters (``params``, ``tables``, ``requires``; validated by the device loader);
* its contribution to the solvers, through the hooks below.  Both solvers
  (:mod:`physics.solvers.frequency`, :mod:`physics.solvers.timedomain`) call the hooks through the model
  (:meth:`physics.model.ActuatorModel.hook`, :meth:`~physics.model.ActuatorModel.product`)
  and never name an effect;
* a plain-data ``diagnosis`` spec (:data:`DIAGNOSIS_KEYS`), read by ``identify``/``diagnose``;
* ``reference``: how the reference solver (:mod:`physics.reference`) treats it (:data:`REFERENCE`).

:func:`physics.effects.check_effect` runs this contract on any effect class.

**Stages** (one provider each).  The model chain is a fixed list of stages, each with a
"no effect" default variant living in the module of the effect that replaces it
(:data:`physics.effects.CHAIN`; the default's ``stage`` names the stage).  An effect
*replaces* a stage by subclassing its default and overriding the stage's hooks (typed in
:mod:`physics.effects.stages`):

=================  ==========================================================================
stage (default)    hooks
=================  ==========================================================================
double_layer       ``props(p, T)``, ``realize(d, w_hi, law)`` (linearised PNP, always present)
charge_law         ``small_signal(s, d, p)``, ``realized_charge(d, p)``, ``compiled(d, p)`` → ``evaluate(Q)``,
                   ``excess(Q)``
line               ``distribution(s, Yp, p, z)``, ``series_conductances(p, edges)``
solvent            ``solvent_factor(s, p)``, ``solvent_diffusivity(p)``
coupling           ``kf(s, p)``; roles: ``gain_equivalent(p, w)``, ``gain_start(value, p, w)``
modulus            ``polymer_modulus(p, layered)``; roles: ``modulus_equivalent(p, f, layered)``,
                   ``modulus_start(value, p, f, layered)``
section            ``section(p, polymer, y_factor)``, ``layer_modulus(p)``, attribute ``layered``
humidity           ``params_at(base, rh)``, ``stiffness_factor(rh)``, ``coupling_factor(rh)``,
                   ``electrochemistry_varies()``
temperature        ``network(p, edges)`` (None: isothermal)
=================  ==========================================================================

**Factor hooks** (any number of effects, multiplied in chain order; absent = no effect):

* ``load_factor(s, p)``: a factor on the bending load (after kf and the solvent factor);
  the time solver realises the product with real poles over the band
  (:class:`LoadEffect`: give ``load_tf``);
* ``output_response(s, p)`` with ``filter_output(y, fs, p)``: a factor on the tip
  deflection (:class:`OutputEffect`: give ``output_tf`` and both follow).  ``filter_output``
  may be nonlinear (hysteresis, saturation); the frequency solver then uses
  ``output_response`` as its small-signal form.
* ``filter_input(v, fs, p)`` with ``input_response(s, p)``: a map of the drive voltage before
  the electrochemistry (:class:`InputEffect`: an amplifier that clips, a contact that conducts
  only beyond a threshold); the time solver drives the strip with the mapped voltage, the
  frequency solver multiplies by ``input_response``, the map's small-signal form.

Effects with internal state (creep, a sensor's dynamics) are rational factors: their
states live in the time solver's realisation (``output_tf``: a Tustin filter).
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..errors import InputError
from ..limits import MAX_TF_ORDER
from ..parameters import ParamSpec, TableSpec


#: Keys of an effect's ``diagnosis`` spec (all optional except ``free`` for a candidate):
#: ``free`` its parameters to fit; ``bounds`` {name: (lo, hi)} or (lo, hi, scale) with scale a
#: device parameter name, optionally ``name^k`` (the bounds are multiplied by its value^k);
#: ``starts`` a list of {name: value or (value, scale)} start points; ``nested`` True when some
#: parameter value switches the effect off, ``off`` those values {name: value or (value, scale)}
#: (the contract tests check that the model is then exactly the one without it); ``excitation`` the excitation that reveals it
#: (text); ``reveal`` the rule that says whether records can show it (:data:`REVEAL_RULES`);
#: ``signature`` [(residual feature, weight)] it leaves in a base model's residual;
#: ``roles`` {"gain" | "stiffness": (parameter, rank)}: the parameter that takes over the
#: base's coupling gain ``kf`` or stiffness ``Y`` when the effect is on (highest rank wins);
#: ``per_rh`` parameters fitted once per RH level instead of shared ones; ``shape`` parameters fitted
#: with the effect that shape its law but do not decide whether it is there (no quality flag when the
#: records leave them undetermined, e.g. a low-frequency corner below what a record resolves);
#: ``refine`` parameters of its law fitted only once the chain has picked it, on the final model
#: (freed while the candidates compete, they would let it stand in for other effects); ``describing_function``
#: True for a large-signal effect fitted through the describing function; ``by_default`` False
#: to try it only on request (``--candidates``).  An effect may also define a classmethod
#: ``diagnosis_start(device) -> {name: value}`` for starts derived from the device (e.g. a table).
#: Further optional class hooks, read by the diagnosis, its demos and test beds: ``draw_truth(device,
#: rng) -> (device, values)`` draws a plausible hidden truth of the effect; ``draw_twin(device, rng)``
#: a near twin outside its own parametrisation; ``describing_grid(device) -> (parameter, coordinates,
#: scale)`` the large-signal parameter of a ``describing_function`` effect and its grid (c = scale /
#: parameter); ``hints`` {parameter: sentence}: why a parameter may have no effect.
DIAGNOSIS_KEYS = ("free", "shape", "refine", "bounds", "starts", "nested", "off", "excitation", "reveal", "signature",
                  "roles", "per_rh", "describing_function", "by_default", "shows_as")
#: ``reveal`` rules: {"f_hi_min": Hz}, {"decades_min": n}, {"f_lo_max": Hz, "hold_s": s} (either),
#: {"spans_resonance": True}, {"rh_levels": n}, {"amplitude_levels": n}; absent: always revealable.
REVEAL_RULES = ("f_hi_min", "decades_min", "f_lo_max", "hold_s", "spans_resonance", "rh_levels", "amplitude_levels")
#: ``reference`` values: "reproduced" (the reference solver solves it itself, through the stage's
#: hooks), "shared" (it acts downstream of the electrochemistry, on the load or the beam, which the
#: reference shares with the reduced model), "unsupported" (the reference refuses a model with it;
#: ``reference_note`` says why).  A "reproduced" claim is never inherited: an effect replacing a stage
#: the reference solves must say so itself (:meth:`Effect.reference_support`).
REFERENCE = ("reproduced", "shared", "unsupported")


class Effect:
    """Base class of all effect variants (the "on" variants carry an ``id``)."""

    id: ClassVar[str | None] = None
    #: the stage of the chain this variant fills (set on the defaults of ``CHAIN``)
    stage: ClassVar[str]
    summary: ClassVar[str] = ""
    explanation: ClassVar[str] = ""
    params: ClassVar[tuple[ParamSpec, ...]] = ()     # parameters owned by this effect (own section)
    tables: ClassVar[tuple[TableSpec, ...]] = ()
    requires: ClassVar[tuple[str, ...]] = ()         # further parameter names needed (any section)
    linear: ClassVar[bool] = True                   # False: large-signal behaviour in the time domain only
    #: True when the effect makes the model need a relative humidity (the ``humidity`` stage).
    needs_rh: ClassVar[bool] = False
    #: Plain-data diagnosis spec (keys in :data:`DIAGNOSIS_KEYS`); None: not a diagnosis candidate.
    diagnosis: ClassVar[dict | None] = None
    #: how the reference solver treats the effect (:data:`REFERENCE`), and why when unsupported.
    reference: ClassVar[str] = "shared"
    reference_note: ClassVar[str] = ""
    #: parameter values under which a large-signal effect is exactly the law the reference solver
    #: computes (the validation report, :mod:`physics.reference.validate`, compares both there)
    reference_limit: ClassVar[dict] = {}

    def __init__(self, device):
        self.device = device
        missing = [n for n in self.needed() if not device.has(n)]
        if missing:
            where = f"section {self.id!r}" if self.id else "the device file"
            raise InputError(f"{type(self).__name__} needs {', '.join(missing)} in {where} of device "
                             f"{device.name!r} ({device.path or 'in memory'})")

    @classmethod
    def needed(cls) -> list[str]:
        """Parameters and tables the device must give: those declared without a default and
        not optional, the required tables, and ``requires``."""
        return [p.name for p in cls.params if not p.optional and p.default is None] \
            + [t.name for t in cls.tables if not t.optional] + list(cls.requires)

    @classmethod
    def reference_support(cls) -> str:
        """"reproduced", "shared" or "unsupported" (:data:`REFERENCE`).  An inherited
        "reproduced" does not count: the reference reproduces what the class it was declared
        on computes, not a subclass's other physics."""
        own = cls.__dict__.get("reference")
        value = own if own is not None else cls.reference
        if value not in REFERENCE:
            raise InputError(f"effect {cls.id!r}: reference must be one of {', '.join(REFERENCE)}, got {value!r}")
        return "unsupported" if own is None and value == "reproduced" else value

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    @property
    def label(self) -> str:
        return self.id if self.id else f"{type(self).__name__} (off)"

    def value(self, p: dict, name: str) -> float:
        """Parameter ``name`` from the parameters ``p`` (SI), else its declared default."""
        if name in p:
            return float(p[name])
        spec = next((s for s in self.params if s.name == name), None)
        if spec is None or spec.default is None:
            raise InputError(f"effect {self.id!r}: no value for {name!r} (add it to section {self.id!r} of the "
                             "device file or declare a default)")
        return float(spec.default)


def rational(effect, hook: str, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """The (numerator, denominator) that ``effect.<hook>(p)`` (``output_tf``, ``load_tf``)
    returns, as float arrays, their order checked against :data:`~physics.limits.MAX_TF_ORDER`
    before anything evaluates them (the roots, the discretisation and the filter's start
    state cost order² to order³)."""
    where = f"effect {getattr(effect, 'id', type(effect).__name__)!r}: {hook}"
    tf = getattr(effect, hook)(p)
    if not (isinstance(tf, (tuple, list)) and len(tf) == 2):
        raise InputError(f"{where} must return (numerator, denominator), two lists of coefficients in s; got "
                         f"{type(tf).__name__}")
    out = []
    for name, poly in zip(("numerator", "denominator"), tf):
        if isinstance(poly, (str, bytes)) or not (hasattr(poly, "__len__") or isinstance(poly, (int, float))):
            raise InputError(f"{where}: the {name} is not a list of numbers ({type(poly).__name__})")
        size = len(poly) if hasattr(poly, "__len__") else 1
        if size > MAX_TF_ORDER + 1:
            raise InputError(f"{where} returns a {name} of order {size - 1}; at most {MAX_TF_ORDER} is accepted "
                             "(a physical factor has a few poles and zeros)")
        try:
            arr = np.atleast_1d(np.asarray(poly, dtype=float))
        except (TypeError, ValueError):
            raise InputError(f"{where}: the {name} is not a list of numbers ({type(poly).__name__})") from None
        if arr.ndim != 1 or arr.size > MAX_TF_ORDER + 1:
            raise InputError(f"{where}: the {name} must be a flat list of at most {MAX_TF_ORDER + 1} coefficients")
        out.append(arr)
    return out[0], out[1]


class OutputEffect(Effect):
    """Base class of an effect acting on the tip deflection: the simplest way to add physics.

    Subclass it in one file (``--effects-path FILE.py``, or an installed package's entry point
    ``eap.effects``) with the class attributes below and :meth:`output_tf`, the transfer
    function multiplying the deflection.  Both solvers use it: the frequency solver multiplies
    the response by it, the time solver filters the simulated deflection with its Tustin
    discretisation (accurate well below the sampling rate).  ``examples/effects/creep.py`` is
    a complete example.

    Attributes
    ----------
    id : str
        The effect's stable name, used in ``--effects`` (``default,+id``).
    summary : str
        One line saying what it adds.
    params : tuple of ParamSpec
        Its parameters, ``ParamSpec(name, unit, low, high, description, optional=True,
        default=value)`` (``physics.parameters``); a device file may override them in a
        section named like the id.  Read them with ``self.value(p, name)``.
    diagnosis : dict, optional
        Makes it a candidate of ``eap diagnose``: ``free`` (parameters to fit), ``bounds``
        ({name: (low, high)}), ``starts`` (a list of {name: value}), ``nested`` (True when
        some values switch it off) and ``off`` (those values), ``excitation`` (text: what
        reveals it), ``reveal`` (a rule on the records), ``signature`` (the residual features
        it leaves).

    Examples
    --------
    A displacement sensor slower than stated, 1/(1 + sτ), and the quick checks of the effect
    contract:

    >>> from physics.effects import OutputEffect, check_effect
    >>> from physics.parameters import ParamSpec
    >>> class SensorLag(OutputEffect):
    ...     id = "sensor_lag"
    ...     summary = "a first-order lag of the displacement sensor"
    ...     params = (ParamSpec("lag_tau", "s", 1e-5, 1.0, "time constant of the sensor",
    ...                         optional=True, default=2e-3),)
    ...     def output_tf(self, p):
    ...         return [1.0], [self.value(p, "lag_tau"), 1.0]       # 1 / (tau s + 1)
    >>> check_effect(SensorLag, fast=True).ok
    True
    """

    stage = "output"
    summary = "user-defined output effect"

    @classmethod
    def needed(cls) -> list[str]:
        return [p.name for p in cls.params if not p.optional and p.default is None] + list(cls.requires)

    def output_tf(self, p: dict) -> tuple[list[float], list[float]]:
        """The factor on the deflection as a rational function of s.

        Parameters
        ----------
        p : dict
            The model's parameters in SI units (read yours with ``self.value(p, name)``).

        Returns
        -------
        tuple of list
            (numerator, denominator): coefficients in s [rad/s], highest power first.
        """
        raise NotImplementedError

    def output_response(self, s: np.ndarray, p: dict) -> np.ndarray:
        """The factor at complex frequencies ``s`` [rad/s] (from :meth:`output_tf`; override it
        with :meth:`filter_output` for a factor that is not rational)."""
        num, den = rational(self, "output_tf", p)
        return np.polyval(num, s) / np.polyval(den, s)

    def filter_output(self, y: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The deflection ``y`` [m] sampled at ``fs`` [Hz] through the factor, started in the
        steady state of the first sample (as the rest of the chain).  Override it for a
        nonlinear output map (a play, a saturation), with :meth:`output_response` as its
        small-signal description."""
        from scipy.signal import bilinear, lfilter, lfilter_zi
        num, den = rational(self, "output_tf", p)
        b, a = bilinear(num, den, fs)
        if len(a) == 1:
            return b[0] / a[0] * np.asarray(y, float)
        return lfilter(b, a, y, zi=lfilter_zi(b, a) * y[0])[0]


class LoadEffect(Effect):
    """Base class of an effect acting on the bending load, before the beam.

    For physics between the interface traction and the bending: a coupling that saturates
    slowly, a relaxation of the traction.  Subclass it with the class attributes of
    :class:`OutputEffect` and :meth:`load_tf` (or :meth:`load_factor` for any causal factor).
    The frequency solver multiplies the load by it exactly; the time solver realises
    kf(s)·B(s)·factor with real poles over the band, so the factor must be stable and smooth
    there (:func:`check_effect` checks that both solvers agree).

    Examples
    --------
    A traction that relaxes by a fraction r with time constant τ, (τs + 1 − r)/(τs + 1), checked
    quickly:

    >>> from physics.effects import LoadEffect, check_effect
    >>> from physics.parameters import ParamSpec
    >>> class TractionRelaxation(LoadEffect):
    ...     id = "traction_relaxation"
    ...     summary = "the interface traction relaxes by r with time constant tau"
    ...     params = (ParamSpec("relax_r", "1", 0.0, 0.9, "relaxed fraction", optional=True, default=0.2),
    ...               ParamSpec("relax_tau", "s", 1e-3, 1e3, "time constant", optional=True, default=5.0))
    ...     def load_tf(self, p):
    ...         r, tau = self.value(p, "relax_r"), self.value(p, "relax_tau")
    ...         return [tau, 1.0 - r], [tau, 1.0]       # (tau s + 1 - r) / (tau s + 1)
    >>> check_effect(TractionRelaxation, fast=True).ok
    True
    """

    summary = "user-defined load effect"

    def load_tf(self, p: dict) -> tuple[list[float], list[float]]:
        """The factor on the load as a rational function of s.

        Parameters
        ----------
        p : dict
            The model's parameters in SI units.

        Returns
        -------
        tuple of list
            (numerator, denominator): coefficients in s [rad/s], highest power first.
        """
        raise NotImplementedError

    def load_factor(self, s: np.ndarray, p: dict) -> np.ndarray:
        """The factor at complex frequencies ``s`` [rad/s] (from :meth:`load_tf`)."""
        num, den = rational(self, "load_tf", p)
        return np.polyval(num, s) / np.polyval(den, s)


class InputEffect(Effect):
    """Base class of an effect acting on the drive voltage, before the electrochemistry.

    For a static (or slow) map of the voltage the strip actually sees: an amplifier that
    clips, a contact or a driver with a dead-zone.  Subclass it with the class attributes of
    :class:`OutputEffect` and :meth:`filter_input`.  The time solver drives the whole chain with
    the mapped voltage; the frequency solver, which has no amplitude, multiplies the response by
    :meth:`input_response`, the map's small-signal form (1 by default: small signals pass, as
    through a clip; a dead-zone has no small-signal gain at rest, and the diagnosis fits what
    passes beyond it with the coupling gain, the map's parameters on the time records).

    Examples
    --------
    A drive clipped at ±1.5 V, and the quick checks of the effect contract:

    >>> import numpy as np
    >>> from physics.effects import InputEffect, check_effect
    >>> from physics.parameters import ParamSpec
    >>> class DriveClip(InputEffect):
    ...     id = "drive_clip"
    ...     summary = "the amplifier clips the drive at ±clip_level"
    ...     params = (ParamSpec("clip_level", "V", 0.0, 1e3, "clipping level", optional=True, default=1.5),)
    ...     def filter_input(self, v, fs, p):
    ...         level = self.value(p, "clip_level")
    ...         return np.clip(v, -level, level)
    >>> check_effect(DriveClip, fast=True).ok
    True
    """

    stage = "input"
    summary = "user-defined input effect"
    #: the reference solver drives its PNP slab with the voltage as given
    reference = "unsupported"
    reference_note = "the reference solver drives its PNP slab with the voltage as given: pre-distort the voltage"

    @classmethod
    def needed(cls) -> list[str]:
        return [p.name for p in cls.params if not p.optional and p.default is None] + list(cls.requires)

    def filter_input(self, v: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The drive voltage ``v`` [V] sampled at ``fs`` [Hz] as the strip sees it [V].

        Parameters
        ----------
        v : ndarray
            The voltage at the clamp [V].
        fs : float
            Its sampling rate [Hz].
        p : dict
            The model's parameters in SI units (read yours with ``self.value(p, name)``).
        """
        raise NotImplementedError

    def input_response(self, s: np.ndarray, p: dict) -> np.ndarray:
        """The map's small-signal factor at complex frequencies ``s`` [rad/s] (default 1)."""
        return np.ones(np.shape(s), dtype=complex)
