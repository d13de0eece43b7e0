"""The diagnosis specs of the registered effects, read in one place.

Every effect declares its ``diagnosis`` spec as plain data in its own module (keys:
:data:`physics.effects.base.DIAGNOSIS_KEYS`).  Nothing in :mod:`physics.diagnose` names an
effect: which parameters to free, their bounds and starts, how the effect nests in the
model, which parameter takes over the base's coupling gain or stiffness, the excitation
that reveals it and the residual signature it leaves all come from here, for built-in and
user effects alike.
"""
from __future__ import annotations

import math

from ..device import Device
from ..effects import EFFECTS

#: The base's coupling gain and stiffness parameters (without an effect taking the role over).
BASE_ROLES = {"gain": "kf", "stiffness": "Y"}


def spec_of(effect: str) -> dict:
    """The diagnosis spec of ``effect`` ({} when it declares none)."""
    cls = EFFECTS.get(effect)
    return dict(getattr(cls, "diagnosis", None) or {})


def shown_as(form: str) -> list[str]:
    """The effects whose physics shows as the residual form ``form`` (a :mod:`.forms` id) when it
    is missing (their spec's ``shows_as``): a kept draft of that form is named by them when they fit
    in its place (:func:`.draft._name_counterparts`)."""
    return [e for e in EFFECTS if form in spec_of(e).get("shows_as", ())]


def default_candidates() -> list[str]:
    """Effects with a spec that are tried by default, in registry order."""
    return [e for e in EFFECTS if spec_of(e) and spec_of(e).get("by_default", True)]


def effect_params(effect: str) -> tuple[str, ...]:
    """The effect's own parameters fitted when it is added."""
    return tuple(spec_of(effect).get("free", ()))


def shape_params(effect: str) -> tuple[str, ...]:
    """Parameters fitted with the effect that shape its law without deciding whether it is there
    (its spec's ``shape``: never a quality flag when the records leave them undetermined)."""
    return tuple(spec_of(effect).get("shape", ()))


def refine_params(effect: str) -> tuple[str, ...]:
    """Parameters of the effect's law fitted only once the chain has picked it, on the final model
    (its spec's ``refine``, :func:`.diagnosis.refine_picks`): freed while the candidates compete, they
    would let the effect stand in for others."""
    return tuple(spec_of(effect).get("refine", ()))


def keeps_spec_range(name: str) -> bool:
    """True when ``name`` is an effect's own parameter in the diagnosis (:func:`effect_params`,
    :func:`shape_params`): it keeps its spec's range in every fit of the diagnosis, the base's
    included — a drafted refit starts from a pick's model with its parameters free, and the
    device check's wider range reaches values the time solver cannot realise (D_solvent of
    1e-18 m²/s, a diffusion time of 10⁹ s)."""
    return any(name in shape_params(e) or name in effect_params(e) or name in refine_params(e) for e in owners(name))


def is_nested(effect: str) -> bool:
    """True when some value of the effect's parameters gives the model without it."""
    return bool(spec_of(effect).get("nested", False))


def role_param(role: str, ids) -> str:
    """The parameter playing ``role`` ("gain" or "stiffness") in a model with effects ``ids``:
    the highest-ranked role declared by one of them, else the base's (``kf``, ``Y``)."""
    best, rank = BASE_ROLES[role], -math.inf
    for e in ids:
        r = spec_of(e).get("roles", {}).get(role)
        if r is not None and r[1] > rank:
            best, rank = r[0], r[1]
    return best


def role_family(role: str) -> set[str]:
    """Every parameter that can play ``role`` (the base's and those of all effects)."""
    return {BASE_ROLES[role]} | {spec_of(e)["roles"][role][0] for e in EFFECTS if role in spec_of(e).get("roles", {})}


def owners(name: str) -> list[str]:
    """Effects that declare parameter ``name`` (their ``params``, or their spec's ``free``/``bounds``)."""
    out = []
    for e, cls in EFFECTS.items():
        sp = spec_of(e)
        if any(p.name == name for p in cls.params) or name in sp.get("free", ()) or name in sp.get("shape", ()) \
                or name in sp.get("refine", ()) or name in sp.get("bounds", {}):
            out.append(e)
    return out


def param_used(name: str, ids) -> bool:
    """Whether parameter ``name`` acts in a model with effects ``ids`` (FRF or time)."""
    for role in BASE_ROLES:
        if name in role_family(role):
            return name == role_param(role, ids)
    own = owners(name)
    return not own or any(e in ids for e in own)


def _scaled(value, device: Device) -> float:
    """A spec value: a number, or (number, scale) with scale a device parameter ``name`` or ``name^k``."""
    if isinstance(value, (tuple, list)):
        v, scale = value
        name, _, k = str(scale).partition("^")
        return float(v) * float(device.params[name]) ** (float(k) if k else 1.0)
    return float(value)


def param_bounds(name: str, device: Device) -> tuple[float, float] | None:
    """Search range of ``name`` from the spec that declares it (None: identify's default)."""
    for e in owners(name):
        b = spec_of(e).get("bounds", {}).get(name)
        if b is not None:
            lo, hi, *scale = b
            return (_scaled((lo, scale[0]), device), _scaled((hi, scale[0]), device)) if scale \
                else (float(lo), float(hi))
    return None


def start_points(effect: str, device: Device) -> list[dict]:
    """The spec's start points of ``effect`` with their device scales applied."""
    return [{k: _scaled(v, device) for k, v in st.items()} for st in spec_of(effect).get("starts", [])]


def off_values(effect: str, device: Device) -> dict:
    """The values of the spec's ``off`` with their device scales applied: those at which the
    model with ``effect`` is the model without it ({} when the spec declares none)."""
    return {k: _scaled(v, device) for k, v in (spec_of(effect).get("off") or {}).items()}


def declared_default(name: str) -> float | None:
    """The documented default of an optional parameter (its ParamSpec ``default``), else None."""
    for cls in EFFECTS.values():
        for p in cls.params:
            if p.name == name and p.default is not None:
                return float(p.default)
    return None


def excitation(effect: str) -> str:
    """The excitation that reveals ``effect`` (text of its spec)."""
    return str(spec_of(effect).get("excitation", ""))


def signature(effect: str) -> list[tuple[str, float]]:
    """[(residual feature, weight)] that ``effect`` leaves in a base model's residual."""
    return [(str(f), float(w)) for f, w in spec_of(effect).get("signature", [])]
