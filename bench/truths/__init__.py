"""Truth families for judging ``eap diagnose`` on physics it was not tuned on.

    from bench.truths import FAMILIES, truths, make_case
    case = make_case("pnp_fd", "solvent", seed=0)      # deterministic for (family, truth, seed)
    files = case.write("runs/truths/pnp_fd_solvent_s0")  # CSV + YAML sidecars
    case.effects, case.param_args(), case.truth.expected, case.true_error(), case.true_offsets()

Families:

* ``pnp_fd`` (:mod:`.pnp_fd`) — a tapered strip from our own finite-volume PNP, ladder and
  diffusion lines and a Hermite finite-element beam; the user's model is the bare device;
* ``circuit_lab`` (:mod:`.circuit_lab`) — an equivalent-circuit model with a two-mode beam,
  exported like a lab; the user's model is the device's default effects;
* ``lab`` and ``perturbed`` (:mod:`.package`) — the package's own test beds.

The independent families import nothing of the package under test (``physics``); their truths
and expected answers are in :mod:`.truthset`.
"""
from __future__ import annotations

from . import package
from .case import Case, Record, Truth
from .truthset import TRUTHS

INDEPENDENT = ("pnp_fd", "circuit_lab")
FAMILIES = INDEPENDENT + package.FAMILIES


def _independent(family: str):
    if family == "pnp_fd":
        from . import pnp_fd as mod
    else:
        from . import circuit_lab as mod
    return mod


def truths(family: str) -> tuple[str, ...]:
    """The truths a family covers."""
    _check(family)
    return tuple(TRUTHS) if family in INDEPENDENT else package.truths(family)


def truth(family: str, name: str) -> Truth:
    """The :class:`Truth` (kind and expected answer) of ``name`` in ``family``."""
    _check(family)
    if family in INDEPENDENT:
        if name not in TRUTHS:
            raise ValueError(f"truth {name!r} is not one of {family}'s: {', '.join(TRUTHS)}")
        return TRUTHS[name]
    return package.truth_of(name)


def make_case(family: str, name: str, seed: int = 0) -> Case:
    """The case (records, the user's command-line choices, the answer) of (family, truth, seed)."""
    _check(family)
    if name not in truths(family):
        raise ValueError(f"truth {name!r} is not one of {family}'s: {', '.join(truths(family))}")
    if family in INDEPENDENT:
        return _independent(family).make_case(name, seed)
    return package.make_case(family, name, seed)


def _check(family: str) -> None:
    if family not in FAMILIES:
        raise ValueError(f"family {family!r}: choose one of {', '.join(FAMILIES)}")


__all__ = ["FAMILIES", "INDEPENDENT", "truths", "truth", "make_case", "Case", "Record", "Truth", "TRUTHS"]
