"""Safe file input and output.

Output: every result is written to a temporary file in the target folder and renamed
into place, so a crash never leaves a half-written file that looks complete, and inputs
are never overwritten by accident (the ownership rules of user-named outputs are in
:mod:`physics.io.outputs`).  Input: JSON written by a user or an attacker (``dataset.json``,
bundle cards) is read by :func:`load_json` with a size and nesting limit, refusing NaN and
repeated keys, each fault one :class:`~physics.errors.InputError` naming the file."""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterator, Mapping

from ..errors import InputError, arg


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True,
                protect: tuple[str | os.PathLike, ...] = ()) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it to ``path``.

    ``protect`` lists input files that must never be the target (raises
    :class:`InputError`).  With ``overwrite=False`` an existing target is an error.
    On an exception the temporary file is removed and the target is untouched.
    """
    target = Path(path)
    if target.is_dir():
        raise InputError(f"{target} is a folder; give a file path")
    for p in protect:
        if Path(p).resolve() == target.resolve():
            raise InputError(f"refusing to overwrite the input file {target}; choose another output path")
    if target.exists() and not overwrite:
        raise InputError(f"{target} already exists; choose another output path or pass {arg('overwrite')}")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    except OSError as exc:
        raise InputError(f"{target}: cannot write in {target.parent} ({exc.strerror}); choose a writable "
                         "path") from None
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())   # mkstemp creates 0600; outputs get the usual mode
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def file_kind(path: str | os.PathLike) -> str | None:
    """What ``path`` is when it exists but is not a regular file (links followed): ``"a
    folder"``, ``"a named pipe (FIFO)"``, ``"a device"``, ``"a socket"``; None for a regular
    file or nothing there.  Reading a pipe or a device never ends (``/dev/zero``) or blocks."""
    import stat
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a socket" if stat.S_ISSOCK(mode) else "not a regular file"


def check_regular(path: str | os.PathLike, what: str) -> None:
    """Refuse ``path`` (``what`` it should be, e.g. "the sidecar") when it exists but is not a
    regular file (:func:`file_kind`), naming it."""
    kind = file_kind(path)
    if kind is not None:
        raise InputError(f"{path}: {what} is {kind}, not a regular file; eap reads only regular files here — "
                         "move it away or give a file")


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's content (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_TMP_NAME = re.compile(r"\.([^/\\\s'\"<>]+?)\.eap-tmp-\d+")
_TMP_FILES = re.compile(r"\.eap-tmp-\d+-[A-Za-z0-9_]+/")
_PART = re.compile(r"/\.([^/\\\s'\"<>]+?)\.[A-Za-z0-9_]{8}\.part\b")


def final_text(text: str) -> str:
    """``text`` with every path through the temporary folder of an output being written
    (``…/.NAME.eap-tmp-PID/…``, the staging folder ``…/.eap-tmp-PID-XXXX/FILE`` of single
    files, an atomic write's ``.FILE.XXXXXXXX.part``) written as the path it will have
    (``…/NAME/…``, ``…/FILE``): what a page, a message, a JSON file or a suggested command
    shows (:mod:`physics.io.outputs` writes outputs aside and renames them at the end)."""
    text = _TMP_NAME.sub(r"\1", str(text))
    return _PART.sub(r"/\1", _TMP_FILES.sub("", text))


def write_text(path: str | os.PathLike, text: str, **kw) -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    with atomic_path(path, **kw) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path: str | os.PathLike, obj, **kw) -> Path:
    """Atomically write ``obj`` as indented JSON (NaN/inf are refused: not valid JSON), every
    path through an output's temporary folder written as its final path (:func:`final_text`)."""
    return write_text(path, final_text(json.dumps(obj, indent=2, allow_nan=False)) + "\n", **kw)


#: Largest JSON file read (bytes): dataset descriptions and cards are a few MB at most.
MAX_JSON_BYTES = 64 << 20
#: Deepest nesting of lists and mappings accepted in JSON and YAML inputs (ours nest < 8).
MAX_DEPTH = 32


def check_depth(obj, where: str, what: str) -> None:
    """Refuse ``obj`` (parsed JSON/YAML) nested deeper than :data:`MAX_DEPTH` (iterative:
    a deep document never exhausts the stack of the code that walks it later)."""
    stack = [(obj, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, (dict, list)):
            if depth > MAX_DEPTH:
                raise InputError(f"{where}: the {what} is nested more than {MAX_DEPTH} levels deep; "
                                 "expected a plain description (a few levels)")
            children = node.values() if isinstance(node, dict) else node
            stack.extend((c, depth + 1) for c in children)


_FLOAT_MAX = sys.float_info.max
_MAX_DIGITS = 309


class OutOfRange:
    """A number in a JSON/YAML text that no float holds (a 5000-digit integer, 1e999), kept
    as a marker by the parser so that :func:`check_numbers` can name its key."""

    def __init__(self, text: str):
        self.text = text


def check_numbers(obj, where: str) -> None:
    """Refuse an :class:`OutOfRange` number anywhere in ``obj``, naming its key path
    (``sensor.noise_rms_um``, ``files[0].samples``)."""
    stack = [(obj, "")]
    while stack:
        node, key = stack.pop()
        if isinstance(node, OutOfRange):
            raise InputError(f"{where}: {key or 'the document'}: {node.text} lies outside the range of a float "
                             f"(±{_FLOAT_MAX:.3g}); give a plausible number")
        if isinstance(node, dict):
            stack.extend((v, f"{key}.{k}" if key else str(k)) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, f"{key}[{i}]") for i, v in enumerate(node))


def _json_int(text: str):
    digits = sum(c.isdigit() for c in text)
    if digits > _MAX_DIGITS:
        return OutOfRange(f"a whole number of {digits} digits")
    value = int(text)
    return value if abs(value) <= _FLOAT_MAX else OutOfRange(f"{text[:12]}…")


def _json_float(text: str):
    value = float(text)
    return OutOfRange(text[:24]) if math.isinf(value) else value


def _no_repeats(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"key {k!r} appears twice in one object")
        out[k] = v
    return out


def _no_constant(name):
    raise ValueError(f"{name} is not a number JSON allows")


def load_json(path, what: str = "JSON file"):
    """Parse the JSON file ``path``: UTF-8, at most :data:`MAX_JSON_BYTES`, nesting at most
    :data:`MAX_DEPTH`, no NaN/Infinity, no key twice in an object."""
    p = Path(path)
    check_regular(p, f"the {what}")
    try:
        size = p.stat().st_size
        if not p.is_file():
            raise InputError(f"{p}: the {what} is not a file")
        if size > MAX_JSON_BYTES:
            raise InputError(f"{p}: the {what} is {size} bytes; at most {MAX_JSON_BYTES} bytes are read")
        text = p.read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InputError(f"{p}: cannot read the {what} ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{p}: the {what} is not UTF-8 text (byte {exc.object[exc.start]:#x} at position "
                         f"{exc.start})") from None
    try:
        obj = json.loads(text, object_pairs_hook=_no_repeats, parse_constant=_no_constant, parse_int=_json_int,
                         parse_float=_json_float)
    except RecursionError:
        raise InputError(f"{p}: the {what} is nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as exc:
        raise InputError(f"{p}: the {what} is not valid JSON ({exc})") from None
    check_depth(obj, str(p), what)
    check_numbers(obj, f"{p}: the {what}")
    return obj


def jsonable(obj: Any) -> Any:
    """``obj`` with numpy types converted and non-finite floats replaced by ``None`` (JSON
    has no NaN/inf); tuples become lists, paths strings."""
    import numpy as np
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, complex):
        return {"re": jsonable(obj.real), "im": jsonable(obj.imag)}
    if isinstance(obj, os.PathLike):
        return str(obj)
    return obj
