"""Classes that installed packages declare under an entry-point group (``eap.effects``,
``eap.networks``), loaded and registered in one way for every kind of plug-in."""
from __future__ import annotations

from typing import Callable

from ..errors import InputError

__all__ = ["load_entry_points"]


def load_entry_points(group: str, register: Callable) -> list:
    """Load every entry point of ``group`` (``NAME = module:Class``) and pass each class to
    ``register``; returns what ``register`` returned, in order.  A class that fails to import
    is a one-line :class:`InputError` naming the entry point; importing it runs contained (exit calls
    caught, a time limit: :mod:`physics.execution.usercode`) — a plug-in is code, as an effect file is."""
    from importlib.metadata import entry_points

    from .usercode import IMPORT_LIMIT_S, running_user_code
    out = []
    for ep in entry_points(group=group):
        try:
            with running_user_code(f"entry point {ep.name!r} ({ep.value}) of group {group}", IMPORT_LIMIT_S):
                cls = ep.load()
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"entry point {ep.name!r} ({ep.value}) of group {group}: {exc}") from None
        out.append(register(cls))
    return out
