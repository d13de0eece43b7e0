"""The actuator model: a device plus a list of effects, assembled into one chain.

Chain (each stage is one entry of :data:`physics.effects.CHAIN`, filled by its default
variant or by the switched-on effect that replaces it)::

    Vin ─▶ double layer / charge law (per area) ─▶ line (voltage along the strip)
        ─▶ interface cation excess ─▶ solvent factor × kf × added load factors
        ─▶ couple along the strip ─▶ beam section (EI*(s), ρA)
        ─▶ modal cantilever + quasi-static residual ─▶ tip ─▶ added output factors

Both solvers (:mod:`physics.solvers.frequency`, :mod:`physics.solvers.timedomain`) walk this chain through
the same effect objects, by the hooks of :mod:`physics.effects.base` (:meth:`ActuatorModel.hook`,
:meth:`ActuatorModel.product`), so they cannot drift apart and never name an effect.  This
module does not import the solvers (the layering is one way: effects ← model ← solvers).
"""
from __future__ import annotations

import numpy as np

from .solvers.beam import CantileverModes
from .device import Device, load_device
from .effects import CHAIN, CORE, EFFECTS, Effect, stage_of
from .effects.double_layer import DoubleLayerProps
from .errors import InputError, arg
from .limits import MAX_MODES, check_count


_GROUPS = ("default", "all", "linear", "none")


def _group(key: str, device: Device) -> list[str]:
    if key == "default":
        return list(device.default_effects)
    if key == "all":
        return list(EFFECTS)
    if key == "linear":
        return [k for k, v in EFFECTS.items() if v.linear]
    return []


def resolve_effects(effects, device: Device) -> tuple[str, ...]:
    """Effect ids from a list or a comma-separated string: ids, the groups ``default`` (the
    device's ``default_effects``), ``all``, ``linear``, ``none``, and ``+id`` / ``-id`` to add or
    remove (e.g. ``default,+creep,-thermal``); the core (the double layer) is always included."""
    if effects is None:
        effects = "default"
    if isinstance(effects, str):
        if not effects.strip():
            raise InputError("effects: an empty list is ambiguous; give 'none' for the bare double-layer "
                             "model, 'default', or comma-separated ids (see `eap effects`)")
        tokens = [e.strip() for e in effects.split(",") if e.strip()]
    else:
        tokens = [e.id if isinstance(e, Effect) else str(e) for e in effects]
    ids: list[str] = []
    for tok in tokens:
        sign, name = (tok[0], tok[1:].strip()) if tok[:1] in "+-" else ("+", tok)
        names = _group(name, device) if name in _GROUPS else [name]
        if sign == "-" and name in _GROUPS:
            raise InputError(f"effects: cannot remove the group {name!r}; remove single effects, e.g. -thermal")
        unknown = [e for e in names if e not in EFFECTS]
        if unknown:
            load = arg("effects_path", "physics.effects.load_effects_file")
            raise InputError(f"unknown effect(s) {', '.join(unknown)}; known effects: {', '.join(EFFECTS)} "
                             f"(a user effect is registered from its file: {load} FILE.py)")
        if sign == "-":
            if name in CORE:
                raise InputError(f"effects: {name} cannot be removed (it is the model's core)")
            ids = [e for e in ids if e != name]
        else:
            ids += [e for e in names if e not in ids]
    ids_set = set(ids) | set(CORE)
    return tuple(k for k in EFFECTS if k in ids_set)


class ActuatorModel:
    """A device with a set of effects switched on: every stage of the chain filled by its
    default variant or by the effect replacing it, then the added effects (factors)."""

    def __init__(self, device, effects=None, *, n_modes: int = 4):
        self.device: Device = load_device(device)
        self.effect_ids = resolve_effects(effects, self.device)
        self.n_modes = check_count(n_modes if isinstance(n_modes, int) else int(n_modes), 1, MAX_MODES,
                                   arg("n_modes"), "higher modes lie far above any measured band; the rest is "
                                   "kept quasi-statically")
        on = [EFFECTS[e] for e in self.effect_ids]
        #: the chain: each stage's name → the effect filling it (its default or the one replacing it)
        self.stages: dict[str, Effect] = {}
        for default in CHAIN:
            chosen = [c for c in on if issubclass(c, default)]
            if len(chosen) > 1:
                raise InputError(f"effects {' and '.join(c.id for c in chosen)} both replace the {default.stage!r} "
                                 "stage; switch one of them off")
            self.stages[default.stage] = (chosen[0] if chosen else default)(self.device)
        #: effects that add factors (load or output), in the order given
        self.added: list[Effect] = [cls(self.device) for cls in on if stage_of(cls) is None]
        self._hooks: dict = {}

    # --- the effect list, as the user reads it back --------------------------------------
    @property
    def effects(self) -> list[Effect]:
        """Every effect object of the model: the stages in chain order, then the added ones."""
        return list(self.stages.values()) + self.added

    @property
    def outputs(self) -> list[Effect]:
        """Added effects acting on the tip deflection (``output_response``/``filter_output``)."""
        return [e for e in self.added if callable(getattr(e, "filter_output", None))]

    @property
    def inputs(self) -> list[Effect]:
        """Added effects acting on the drive voltage (``filter_input``/``input_response``)."""
        return [e for e in self.added if callable(getattr(e, "filter_input", None))]

    @property
    def is_linear(self) -> bool:
        return all(type(e).linear for e in self.effects)

    @property
    def needs_rh(self) -> bool:
        """True when an effect makes the response depend on the relative humidity."""
        return any(type(e).needs_rh for e in self.effects)

    def __repr__(self) -> str:
        return f"ActuatorModel({self.device.name!r}, effects={list(self.effect_ids)})"

    # --- the hooks the solvers call (contract: physics.effects.base) ----------------------
    def hook(self, name: str):
        """The stage hook ``name`` (a bound method of the stage that provides it)."""
        fn = self._hooks.get(name)
        if fn is None:
            comp = next((c for c in self.stages.values() if callable(getattr(c, name, None))), None)
            if comp is None:
                raise AttributeError(f"no stage of the chain provides the hook {name!r}")
            fn = self._hooks[name] = getattr(comp, name)
        return fn

    def product(self, name: str, *args):
        """Product of the factor hook ``name`` over the added effects (1.0 when none has it)."""
        out = 1.0
        for e in self.added:
            fn = getattr(e, name, None)
            if callable(fn):
                out = out * fn(*args)
        return out

    # --- geometry and parameters ----------------------------------------------------------
    @property
    def free_length(self) -> float:
        return self.device["L_total"] - self.device["L_clamp"]

    def modes(self) -> CantileverModes:
        return CantileverModes(self.free_length, self.n_modes)

    def check_rh(self, rh, what: str = arg("rh")):
        """Validate RH [%]; None is allowed only when the humidity effect is off."""
        if isinstance(rh, float) and 0.0 <= rh <= 100.0:   # the common case (a scalar), checked without numpy
            return float(rh)
        if rh is None:
            if self.needs_rh:
                raise InputError(f"the humidity effect is on: give {what} (relative humidity, %)")
            return self.device.reference_rh
        arr = np.asarray(rh, dtype=float)
        if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 100):
            raise InputError(f"{what} {float(np.max(arr)) if arr.size else rh!r}: must be finite and within 0–100 %")
        return arr if arr.ndim else float(arr)

    def params_at(self, rh=None) -> dict:
        """Parameters (SI) at relative humidity ``rh`` [%] (Y's factor is applied by the section)."""
        rh = self.check_rh(rh)
        return self.hook("params_at")(dict(self.device.params), rh if isinstance(rh, float) else float(np.mean(rh)))

    def key_at(self, rh, p: dict | None = None) -> tuple | None:
        """What this model's small-signal response and its time response at a constant ``rh``
        [%] depend on besides the input: the effects, the modes, the parameters there (``p``:
        :meth:`params_at` when the caller has them) and the stiffness factor.  Equal keys give
        the same numbers (a memo's key); None for an RH series (no key)."""
        rh = self.check_rh(rh)
        if np.ndim(rh):
            return None
        p = self.params_at(rh) if p is None else p
        return tuple(self.effect_ids), self.n_modes, tuple(sorted(p.items())), float(self.hook("stiffness_factor")(rh))

    def chain_params(self, rh=None) -> dict:
        """Parameters (SI) of the load filters and the beam of a time record at ``rh`` [%] (its
        median): humidity maps applied except the stiffness's and the coupling's, which the
        time solver follows sample by sample."""
        rh = self.check_rh(rh)
        return self.hook("chain_params")(dict(self.device.params), float(np.median(rh)))

    def double_layer_props(self, p: dict, T=None) -> DoubleLayerProps:
        return self.hook("props")(p, T)

    def section(self, p: dict, stiffness_factor: float = 1.0):
        """(EI*(s) Prony series [N m²], ρA [kg/m]) with the humidity stiffness factor."""
        section = self.hook("section")
        polymer = self.hook("polymer_modulus")(p, section.__self__.layered)
        return section(p, polymer, stiffness_factor)

    def load_response(self, s: np.ndarray, p: dict, solvent: bool = True) -> np.ndarray:
        """Bending load per unit interface cation excess at ``s`` [rad/s]: kf(s) [N m/mol] ×
        solvent factor (unless ``solvent`` is False) × the added load factors."""
        out = self.hook("kf")(s, p) * self.product("load_factor", s, p)
        return out * self.hook("solvent_factor")(s, p) if solvent else out

    def describe(self) -> str:
        lines = [repr(self)]
        for stage, e in self.stages.items():
            lines.append(f"  {stage:12s} {e.label:24s} {e.summary}")
        for e in self.added:
            lines.append(f"  {'added':12s} {e.label:24s} {e.summary}")
        return "\n".join(lines)

    def input_response(self, s: np.ndarray, p: dict) -> np.ndarray | float:
        """Product of the added effects' small-signal factors on the voltage at ``s`` [rad/s] (1 if none)."""
        return self.product("input_response", s, p)

    def filter_input(self, v: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The drive voltage ``v`` [V] at ``fs`` [Hz] through the added input effects."""
        for e in self.inputs:
            v = np.asarray(e.filter_input(v, fs, p), dtype=float)
        return v

    def output_response(self, s: np.ndarray, p: dict) -> np.ndarray | float:
        """Product of the added effects' factors on the deflection at ``s`` [rad/s] (1 if none)."""
        return self.product("output_response", s, p)

    def filter_output(self, y: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The simulated deflection ``y`` [m] at ``fs`` [Hz] through the added output effects."""
        for e in self.outputs:
            y = e.filter_output(y, fs, p)
        return y


def as_model(device, effects=None, n_modes: int = 4) -> ActuatorModel:
    if isinstance(device, ActuatorModel):
        if effects is not None and resolve_effects(effects, device.device) != device.effect_ids:
            return ActuatorModel(device.device, effects, n_modes=device.n_modes)
        return device
    return ActuatorModel(device, effects, n_modes=n_modes)
