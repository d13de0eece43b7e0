"""Safe file input and output.

Output: every result is written to a temporary file in the target folder and renamed
into place, so a crash never leaves a half-written file that looks complete, and inputs
are never overwritten by accident (the ownership rules of user-named outputs are in
:mod:`physics.outputs`).  Input: JSON written by a user or an attacker (``dataset.json``,
bundle cards) is read by :func:`load_json` with a size and nesting limit, refusing NaN and
repeated keys, each fault one :class:`~physics.errors.InputError` naming the file."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import InputError, arg


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


def write_text(path: str | os.PathLike, text: str, **kw) -> Path:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    with atomic_path(path, **kw) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path: str | os.PathLike, obj, **kw) -> Path:
    """Atomically write ``obj`` as indented JSON (NaN/inf are refused: not valid JSON)."""
    return write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n", **kw)


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
        obj = json.loads(text, object_pairs_hook=_no_repeats, parse_constant=_no_constant)
    except RecursionError:
        raise InputError(f"{p}: the {what} is nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as exc:
        raise InputError(f"{p}: the {what} is not valid JSON ({exc})") from None
    check_depth(obj, str(p), what)
    return obj
