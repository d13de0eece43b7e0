"""Safe file output: every result is written to a temporary file in the target folder
and renamed into place, so a crash never leaves a half-written file that looks complete,
and inputs are never overwritten by accident."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import InputError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True,
                protect: tuple[str | os.PathLike, ...] = ()) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success rename it to ``path``.

    ``protect`` lists input files that must never be the target (raises
    :class:`InputError`).  With ``overwrite=False`` an existing target is an error.
    On an exception the temporary file is removed and the target is untouched.
    """
    target = Path(path)
    for p in protect:
        if Path(p).resolve() == target.resolve():
            raise InputError(f"refusing to overwrite the input file {target}; choose another output path")
    if target.exists() and not overwrite:
        raise InputError(f"{target} already exists; choose another output path or pass --overwrite")
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
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
