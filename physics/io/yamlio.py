"""Reading user YAML (sidecars, device files, dataset and training configs) safely.

``yaml.safe_load`` never runs code, but it still expands aliases: a few hundred bytes of
nested ``&a [*b, *b, ...]`` grow into gigabytes (a "billion laughs" file); it recurses once
per level of nesting (``[[[[…]]]]`` 400 deep, under 1 kB, exhausts the stack); and it keeps
the last of two equal keys without a word.  Files read here are limited in size
(:data:`MAX_YAML_BYTES`) and nesting (:data:`~physics.io.fileio.MAX_DEPTH`) and may not use
anchors, aliases or a key twice in one mapping; every problem is an
:class:`~physics.errors.InputError` naming the file.
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml

from ..errors import InputError
from .fileio import _FLOAT_MAX, _MAX_DIGITS, MAX_DEPTH, OutOfRange, check_numbers, check_regular

#: Largest YAML file read (bytes); metadata and configs are a few kB.
MAX_YAML_BYTES = 1 << 20


class _NoAliasLoader(yaml.SafeLoader):
    """SafeLoader that refuses anchors and aliases (no expansion bombs), nesting deeper than
    :data:`~physics.io.fileio.MAX_DEPTH` and repeated keys."""

    def compose_node(self, parent, index):
        self._depth = getattr(self, "_depth", 0) + 1
        try:
            return self._compose_checked(parent, index)
        finally:
            self._depth -= 1

    def _compose_checked(self, parent, index):
        if self._depth > MAX_DEPTH:
            raise yaml.constructor.ConstructorError(
                None, None, f"nested more than {MAX_DEPTH} levels deep", self.peek_event().start_mark)
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.constructor.ConstructorError(
                None, None, f"aliases (*{event.anchor}) are not allowed", event.start_mark)
        event = self.peek_event()
        if getattr(event, "anchor", None):
            raise yaml.constructor.ConstructorError(
                None, None, f"anchors (&{event.anchor}) are not allowed", event.start_mark)
        return super().compose_node(parent, index)

    def construct_yaml_int(self, node):
        digits = sum(c.isdigit() for c in str(node.value))
        if digits > _MAX_DIGITS:           # beyond any float (and Python's int-string limit)
            return OutOfRange(f"a whole number of {digits} digits")
        value = super().construct_yaml_int(node)
        return value if abs(value) <= _FLOAT_MAX else OutOfRange(f"{str(node.value)[:12]}…")

    def construct_yaml_float(self, node):
        value = super().construct_yaml_float(node)
        if math.isinf(value) and "inf" not in str(node.value).lower():   # 1e999: not the spelling .inf
            return OutOfRange(str(node.value)[:24])
        return value

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, (str, int, float, bool)) and key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} appears twice in one mapping", key_node.start_mark)
            seen.add(key) if isinstance(key, (str, int, float, bool)) else None
        return super().construct_mapping(node, deep=deep)


_NoAliasLoader.add_constructor("tag:yaml.org,2002:int", _NoAliasLoader.construct_yaml_int)
_NoAliasLoader.add_constructor("tag:yaml.org,2002:float", _NoAliasLoader.construct_yaml_float)
def load_yaml(path, what: str = "YAML file"):
    """Parse the YAML file ``path`` (UTF-8, at most :data:`MAX_YAML_BYTES`, no aliases)."""
    p = Path(path)
    check_regular(p, f"the {what}")
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
        obj = yaml.load(text, Loader=_NoAliasLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        text = " ".join(str(exc).replace('in "<unicode string>", ', "at ").split())
        raise InputError(f"{where}: invalid YAML in the {what} ({text})") from None
    check_numbers(obj, where)
    return obj
