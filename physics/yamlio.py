"""Reading user YAML (sidecars, device files, dataset and training configs) safely.

``yaml.safe_load`` never runs code, but it still expands aliases: a few hundred bytes of
nested ``&a [*b, *b, ...]`` grow into gigabytes (a "billion laughs" file).  Files read
here are limited in size and may not use anchors or aliases; every problem is an
:class:`~physics.errors.InputError` naming the file.
"""
from __future__ import annotations

from pathlib import Path

import yaml

from .errors import InputError

#: Largest YAML file read (bytes); metadata and configs are a few kB.
MAX_YAML_BYTES = 1 << 20


class _NoAliasLoader(yaml.SafeLoader):
    """SafeLoader that refuses anchors and aliases (no expansion bombs)."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.constructor.ConstructorError(
                None, None, f"aliases (*{event.anchor}) are not allowed", event.start_mark)
        event = self.peek_event()
        if getattr(event, "anchor", None):
            raise yaml.constructor.ConstructorError(
                None, None, f"anchors (&{event.anchor}) are not allowed", event.start_mark)
        return super().compose_node(parent, index)


def load_yaml(path, what: str = "YAML file"):
    """Parse the YAML file ``path`` (UTF-8, at most :data:`MAX_YAML_BYTES`, no aliases)."""
    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what} ({exc.strerror})") from None
    if size > MAX_YAML_BYTES:
        raise InputError(f"{p}: {what} is {size} bytes; at most {MAX_YAML_BYTES} bytes are read "
                         "(metadata and configurations are a few kB)")
    try:
        text = p.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: the {what} is not UTF-8 text (byte {exc.object[exc.start]:#x} at "
                         f"position {exc.start}); save it as UTF-8") from None
    return loads_yaml(text, f"{p}", what)


def loads_yaml(text: str, where: str, what: str = "YAML"):
    """Parse YAML ``text`` (no aliases); errors name ``where``."""
    try:
        return yaml.load(text, Loader=_NoAliasLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        raise InputError(f"{where}: invalid YAML in the {what} ({' '.join(str(exc).split())})") from None
