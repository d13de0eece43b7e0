"""Truth families for judging ``eap diagnose`` on physics it was not tuned on.

    from bench.truths import FAMILIES, truths, make_case
    case = make_case("pnp_fd", "solvent", seed=0)      # deterministic for (family, truth, seed)
    files = case.write("runs/truths/pnp_fd_solvent_s0")  # CSV + YAML sidecars
    case.effects, case.param_args(), case.truth.expected, case.true_error(), case.true_offsets()

Families:

* ``pnp_fd`` (:mod:`.pnp_fd`) — a tapered strip from our own finite-volume PNP, ladder and
  diffusion lines and a Hermite finite-element beam; the user's model is the bare device;
* ``pnp_sweep`` (:mod:`.pnp_fd` too) — the same physics recorded as a user with two records
  does: a 120 s log sweep and a square pulse train at one RH, 1 µm noise (the truths an RH
  dependence needs are left out);
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

INDEPENDENT = ("pnp_fd", "circuit_lab", "pnp_sweep")
FAMILIES = INDEPENDENT + package.FAMILIES


def _independent(family: str):
    """(the family's truths, its ``make_case(truth, seed)``)."""
    if family == "circuit_lab":
        from . import circuit_lab
        return tuple(TRUTHS), circuit_lab.make_case
    from . import pnp_fd
    design = pnp_fd.DESIGNS[family]
    return pnp_fd.truths_of(design), lambda name, seed: pnp_fd.make_case(name, seed, design)


def truths(family: str) -> tuple[str, ...]:
    """The truths a family covers."""
    _check(family)
    return _independent(family)[0] if family in INDEPENDENT else package.truths(family)


def truth(family: str, name: str) -> Truth:
    """The :class:`Truth` (kind and expected answer) of ``name`` in ``family``."""
    _check(family)
    if family in INDEPENDENT:
        if name not in truths(family):
            raise ValueError(f"truth {name!r} is not one of {family}'s: {', '.join(truths(family))}")
        return TRUTHS[name]
    return package.truth_of(name)


def make_case(family: str, name: str, seed: int = 0) -> Case:
    """The case (records, the user's command-line choices, the answer) of (family, truth, seed)."""
    _check(family)
    if name not in truths(family):
        raise ValueError(f"truth {name!r} is not one of {family}'s: {', '.join(truths(family))}")
    if family in INDEPENDENT:
        return _independent(family)[1](name, seed)
    return package.make_case(family, name, seed)


def _check(family: str) -> None:
    if family not in FAMILIES:
        raise ValueError(f"family {family!r}: choose one of {', '.join(FAMILIES)}")


__all__ = ["FAMILIES", "INDEPENDENT", "truths", "truth", "make_case", "Case", "Record", "Truth", "TRUTHS"]
