"""One output policy for every command that writes: nothing a user owns is replaced.

Ownership, not folders: eap replaces only what it wrote.

* An output **folder** (:func:`output_folder`) gets a marker :data:`MARKER` listing every
  file eap wrote in it with its SHA-256.  ``--overwrite`` replaces the folder only when
  everything in it is such a file, unchanged; a file the user added or edited, an empty
  folder they made, a link — anything else — makes it refuse, naming the file.
* An output **file** (:func:`output_files`: ``frf --json/--csv/--plot``, ``predict --out``,
  ``sweep --out``) is recorded in the hidden registry :data:`REGISTRY` of its folder with its
  SHA-256; ``--overwrite`` replaces only a file recorded there and unchanged.  The sidecar
  ``NAME.yaml`` of a CSV output follows the same rule (a user's ``NAME.yaml`` beside a new
  ``NAME.csv`` would be read as its metadata).
* **Inputs** are never targets: every file or folder a run reads (measurements and their
  sidecars, device YAML, configuration, effect files, datasets, bundles; the command line
  declares them with :func:`protecting`) may not be an output, lie in an output folder, or
  hold an output.  ``.``, the home folder, ``/`` and parents of the current folder are
  refused as output folders.
* Writing is atomic: a folder is written into a hidden sibling ``.NAME.eap-tmp-PID`` and
  files into a hidden temporary folder, renamed into place at the end, so an interrupted
  or failed run leaves nothing that looks complete.  A lock next to an output folder
  (:data:`LOCK_SUFFIX`) makes a second writer fail at once, naming the first (pid,
  command); locks and temporary folders of killed runs are detected and removed.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterable, Iterator, Sequence

from .errors import InputError, arg
from .fileio import sha256_file

#: File written into every output folder: the files eap wrote there, with their SHA-256.
MARKER = ".eap-output.json"
#: Hidden registry, in a folder holding single-file outputs, of the files eap wrote there.
REGISTRY = ".eap-files.json"
#: Suffix of the lock file written beside an output folder while it is being written.
LOCK_SUFFIX = ".eap-lock"
_TMP = ".eap-tmp-"
_OLD = ".eap-old-"
_PARTIAL = ".eap-partial"
_OUT = arg("out")   # how messages name an output path by default (the CLI: --out)
_PROTECTED: set[Path] = set()


@contextlib.contextmanager
def protecting(paths: Iterable) -> Iterator[None]:
    """Within the block, ``paths`` (files or folders the run reads) are inputs of every
    output: none may be, hold or lie in them (a CSV's or .mat's sidecar included)."""
    added = {Path(p).expanduser().resolve() for p in paths
             if p is not None and str(p) != "" and Path(p).expanduser().exists()} - _PROTECTED
    _PROTECTED.update(added)
    try:
        yield
    finally:
        _PROTECTED.difference_update(added)


def _inputs_with_sidecars(inputs: Iterable) -> list[Path]:
    out = set(_PROTECTED)
    for p in inputs:
        if p is not None:
            out.add(Path(p).expanduser().resolve())
    for q in list(out):
        if q.suffix.lower() in (".csv", ".mat"):
            out.add(q.with_suffix(".yaml"))
    return sorted(out)


_TMP_NAME = re.compile(r"\.([^/\\\s'\"<>]+?)\.eap-tmp-\d+")


def final_text(text: str) -> str:
    """``text`` with every path through the temporary folder of an output being written
    (``…/.NAME.eap-tmp-PID/…``) written as the path it will have (``…/NAME/…``): what a
    page or a suggested command shows."""
    return _TMP_NAME.sub(r"\1", str(text))


def final_path(path) -> Path:
    """The path ``path`` (inside the temporary folder of an output) will have once written."""
    return Path(final_text(str(path)))


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _command() -> str:
    return " ".join(["eap"] + sys.argv[1:]) if sys.argv else "eap"


def _stamp() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


# --------------------------------------------------------------------------- ownership

def _listing(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder`` (the marker excluded)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        for name in sorted(files):
            p = Path(root) / name
            rel = p.relative_to(folder).as_posix()
            if rel not in (MARKER, _PARTIAL):
                out[rel] = sha256_file(p)
    return out


def _owned_files(folder: Path) -> dict[str, str] | None:
    """The files the marker of ``folder`` lists (None: no marker, or one that lists none)."""
    try:
        files = json.loads((folder / MARKER).read_text(encoding="utf-8")).get("files")
    except (OSError, ValueError, AttributeError):
        return None
    return files if isinstance(files, dict) else None


def foreign_entry(folder: Path) -> str | None:
    """The first entry of the eap output folder ``folder`` that eap did not write (or that
    changed since), as a path relative to it (a folder eap did not make is named by its
    first file, or as ``NAME/`` when empty); ``None`` when the folder holds only its files."""
    owned = _owned_files(folder)
    if owned is None:
        return f"{MARKER} (missing, or from an older eap that did not list its files)"
    dirs = {p.as_posix() for rel in owned for p in Path(rel).parents}
    for root, subdirs, files in os.walk(folder):
        subdirs.sort()
        base = Path(root).relative_to(folder)
        for name in sorted(files):
            p = Path(root) / name
            rel = (base / name).as_posix()
            if rel != MARKER and (p.is_symlink() or owned.get(rel) != sha256_file(p)):
                return rel
        for name in list(subdirs):
            rel = (base / name).as_posix()
            if (Path(root) / name).is_symlink():
                return rel
            if rel not in dirs:   # not made by eap: name what it holds
                inside = sorted(q for q in (Path(root) / name).rglob("*") if not q.is_dir())
                return inside[0].relative_to(folder).as_posix() if inside else rel + "/"
    return None


def _refuse_foreign(folder: Path, flag: str, out) -> None:
    entry = foreign_entry(folder)
    if entry is not None:
        raise InputError(f"{flag} {out} holds {entry}, which eap did not write (or which changed since); refusing "
                         f"to replace the folder even with {arg('overwrite')} — move that file out, or choose another {flag}")


# --------------------------------------------------------------------------- folders

def check_target(out: Path, inputs: Iterable = (), *, flag: str = _OUT) -> Path:
    """Resolve ``out`` and refuse targets that could destroy the user's files."""
    out = Path(out).expanduser()
    res = out.resolve()
    forbidden = {Path("/").resolve(), Path.home().resolve()}
    cwd = Path.cwd().resolve()
    if res in forbidden or res == cwd or res in cwd.parents:
        raise InputError(f"{flag} {out}: refusing to write into {res} (the current folder, a parent of it, "
                         f"the home folder or /); choose a new sub-folder, e.g. {flag} runs/NAME")
    if res.exists() and not res.is_dir():
        raise InputError(f"{flag} {out} exists and is not a folder; choose a folder path")
    for q in _inputs_with_sidecars(inputs):
        if q == res or res in q.parents:
            raise InputError(f"{flag} {out} contains the input {q}; writing there could replace it — "
                             f"choose another {flag}")
        if q.is_dir() and q in res.parents:
            raise InputError(f"{flag} {out} lies inside the input folder {q}; choose another {flag}")
    return res


def _clean_stale(parent: Path, name: str) -> None:
    """Remove temporary/old folders of killed runs into ``parent/name`` (only ours)."""
    for prefix in (f".{name}{_TMP}", f".{name}{_OLD}"):
        for p in parent.glob(prefix + "*"):
            pid = p.name[len(prefix):].split("-")[0]
            if p.is_dir() and pid.isdigit() and not _pid_alive(int(pid)) \
                    and ((p / MARKER).is_file() or (p / _PARTIAL).is_file()):
                shutil.rmtree(p, ignore_errors=True)


def _lock_holder(lock: Path) -> dict | None:
    """The lock's content when a live process other than this one holds it, else None."""
    try:
        other = json.loads(lock.read_text(encoding="utf-8"))
        pid = int(other.get("pid", 0))
    except (OSError, ValueError, TypeError, AttributeError):
        return None
    return other if pid != os.getpid() and _pid_alive(pid) else None


def _busy(target: Path, other: dict, flag: str) -> str:
    return (f"{flag} {target} is being written by another run (pid {other.get('pid')}: "
            f"{other.get('command', '?')}, started {other.get('started', '?')}); wait for it to finish "
            f"or choose another {flag}")


@contextlib.contextmanager
def _lock(parent: Path, name: str, flag: str) -> Iterator[None]:
    lock = parent / f".{name}{LOCK_SUFFIX}"
    info = {"pid": os.getpid(), "command": _command(), "started": _stamp()}
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            other = _lock_holder(lock)
            if other:
                raise InputError(_busy(parent / name, other, flag)) from None
            lock.unlink(missing_ok=True)  # stale: its run was killed
            continue
        except OSError as exc:
            raise InputError(f"{flag} {parent / name}: cannot write in {parent} ({exc.strerror}); choose "
                             f"a writable {flag}") from None
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(info, fh)
        break
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def _writable_parent(parent: Path, flag: str, out) -> None:
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{flag} {out}: cannot create {parent} ({exc.strerror}); choose a writable "
                         f"{flag}") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {out}: {parent} is not writable; choose a writable {flag}")


def preflight(out, *, inputs: Iterable = (), overwrite: bool = False, flag: str = _OUT) -> Path:
    """Every check of :func:`output_folder` that can be made before any work (target, existing
    content, ownership, writability); returns the resolved target.  Commands call it first."""
    res = check_target(Path(out), inputs, flag=flag)
    if res.is_dir() and any(res.iterdir()):
        if not overwrite:
            raise InputError(f"{flag} {out} already exists and is not empty; choose another {flag} "
                             f"or pass {arg('overwrite')} to replace a folder written by eap")
        if not (res / MARKER).is_file():
            raise InputError(f"{flag} {out} holds files eap did not write (no {MARKER}); refusing to "
                             f"replace it even with {arg('overwrite')} — choose another {flag}")
        _refuse_foreign(res, flag, out)
    other = _lock_holder(res.parent / f".{res.name}{LOCK_SUFFIX}")
    if other:
        raise InputError(_busy(res, other, flag))
    _writable_parent(res.parent, flag, out)
    return res


@contextlib.contextmanager
def output_folder(out, *, inputs: Iterable = (), overwrite: bool = False,
                  flag: str = _OUT) -> Iterator[Path]:
    """Yield a fresh temporary folder; on success it replaces ``out`` atomically.

    ``inputs``: files (and folders) read by the run, never to be replaced (besides those
    declared with :func:`protecting`).  ``flag`` names the option in messages.  On any
    exception (Ctrl-C included) the temporary folder is removed and ``out`` is untouched.
    """
    res = preflight(out, inputs=inputs, overwrite=overwrite, flag=flag)
    parent, name = res.parent, res.name
    with _lock(parent, name, flag):
        _clean_stale(parent, name)
        tmp = parent / f".{name}{_TMP}{os.getpid()}"
        if tmp.exists():
            shutil.rmtree(tmp)
        try:
            tmp.mkdir()
            (tmp / _PARTIAL).write_text(_command() + "\n", encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{flag} {out}: cannot write in {parent} ({exc.strerror}); choose a "
                             f"writable {flag}") from None
        try:
            yield tmp
            (tmp / MARKER).write_text(json.dumps({"command": _command(), "pid": os.getpid(), "written": _stamp(),
                                                  "files": _listing(tmp)}, indent=1) + "\n", encoding="utf-8")
            (tmp / _PARTIAL).unlink()
            _promote(tmp, res, overwrite, flag, out)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _promote(tmp: Path, res: Path, overwrite: bool, flag: str, out) -> None:
    if res.exists() and res.is_dir() and not any(res.iterdir()):
        res.rmdir()
    if res.exists():
        if not (overwrite and res.is_dir() and (res / MARKER).is_file()):
            raise InputError(f"{flag} {out} appeared while this run was writing and eap did not write it "
                             f"(or {arg('overwrite')} was not given); nothing was written — choose another "
                             f"{flag}")
        _refuse_foreign(res, flag, out)   # checked again: files may have been added meanwhile
        old = res.parent / f".{res.name}{_OLD}{os.getpid()}"
        os.replace(res, old)
        os.replace(tmp, res)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, res)


# --------------------------------------------------------------------------- files

def _registry(parent: Path) -> dict[str, dict]:
    try:
        files = json.loads((parent / REGISTRY).read_text(encoding="utf-8")).get("files")
    except (OSError, ValueError, AttributeError):
        return {}
    return files if isinstance(files, dict) else {}


def _owned_file(p: Path) -> bool:
    entry = _registry(p.parent).get(p.name)
    return isinstance(entry, dict) and not p.is_symlink() and p.is_file() and entry.get("sha256") == sha256_file(p)


def check_file_target(path, *, overwrite: bool = False, flag: str = _OUT, inputs: Iterable = ()) -> Path:
    """Refuse an output file that is a folder, an input (or its sidecar), lies in an input
    folder, or exists without ``overwrite`` or without eap having written it; returns it resolved."""
    p = Path(path).expanduser()
    res = p.parent.resolve() / p.name if p.name not in ("", ".", "..") else p.resolve()
    if res.is_dir():
        raise InputError(f"{flag} {path} is a folder; give a file path")
    for q in _inputs_with_sidecars(inputs):
        if q == res:
            raise InputError(f"{flag} {path} is an input of this run; refusing to overwrite it — choose another "
                             f"{flag}")
        if q.is_dir() and q in res.parents:
            raise InputError(f"{flag} {path} lies inside the input folder {q}; choose another {flag}")
    if res.exists() or res.is_symlink():
        if not overwrite:
            raise InputError(f"{flag} {path} already exists; choose another {flag} or pass {arg('overwrite')}")
        if not _owned_file(res):
            raise InputError(f"{flag} {path} was not written by eap (or changed since); refusing to replace it "
                             f"even with {arg('overwrite')} — choose another {flag}")
    return res


def preflight_files(paths: Sequence, *, overwrite: bool = False, flags: Sequence[str] | str = _OUT,
                    inputs: Iterable = ()) -> list[Path | None]:
    """Every check of :func:`output_files` that can be made before any work; returns the
    resolved targets (``None`` for ``None``)."""
    flags = [flags] * len(paths) if isinstance(flags, str) else list(flags)
    targets: list[Path | None] = []
    for path, flag in zip(paths, flags):
        if path is None:
            targets.append(None)
            continue
        res = check_file_target(path, overwrite=overwrite, flag=flag, inputs=inputs)
        if res in targets:
            raise InputError(f"{flag} {path}: another output of this run is the same file; give distinct paths")
        if res.suffix.lower() == ".csv" and res.with_suffix(".yaml").exists():
            check_file_target(res.with_suffix(".yaml"), overwrite=overwrite, flag=flag, inputs=inputs)
        _writable_parent(res.parent, flag, path)
        targets.append(res)
    return targets


@contextlib.contextmanager
def output_files(paths: Sequence, *, overwrite: bool = False, flags: Sequence[str] | str = _OUT,
                 inputs: Iterable = ()) -> Iterator[list[Path]]:
    """Write single output files atomically under the ownership rules (module doc).

    Yields one temporary path per target (``None`` targets give ``None``); whatever the
    block writes beside them (e.g. a CSV's sidecar) is an output too.  On success every
    file is checked again, renamed into place and recorded in its folder's
    :data:`REGISTRY`; a CSV target's stale sidecar (written by eap) is removed.
    """
    flags = [flags] * len(paths) if isinstance(flags, str) else list(flags)
    targets = preflight_files(paths, overwrite=overwrite, flags=flags, inputs=inputs)
    staging: dict[Path, Path] = {}
    try:
        for res, flag, path in zip(targets, flags, paths):
            if res is not None and res.parent not in staging:
                _clean_stale_files(res.parent)
                try:
                    staging[res.parent] = Path(tempfile.mkdtemp(prefix=f"{_TMP}{os.getpid()}-", dir=res.parent))
                except OSError as exc:
                    raise InputError(f"{flag} {path}: cannot write in {res.parent} ({exc.strerror}); choose a "
                                     f"writable {flag}") from None
        yield [None if res is None else staging[res.parent] / res.name for res in targets]
        for parent, tmp in staging.items():
            _promote_files(parent, tmp, [t for t in targets if t is not None and t.parent == parent],
                           overwrite, flags[0], inputs)
    finally:
        for tmp in staging.values():
            shutil.rmtree(tmp, ignore_errors=True)


def _clean_stale_files(parent: Path) -> None:
    """Remove staging folders of killed single-file writers in ``parent`` (their pid is gone)."""
    for p in parent.glob(f"{_TMP}*"):
        pid = p.name[len(_TMP):].split("-")[0]
        if p.is_dir() and pid.isdigit() and not _pid_alive(int(pid)):
            shutil.rmtree(p, ignore_errors=True)


def _promote_files(parent: Path, tmp: Path, targets: list[Path], overwrite: bool, flag: str, inputs) -> None:
    written = sorted(p.name for p in tmp.iterdir())
    stale = [t.with_suffix(".yaml") for t in targets if t.suffix.lower() == ".csv"
             and t.with_suffix(".yaml").name not in written and t.with_suffix(".yaml").exists()]
    for name in written:
        check_file_target(parent / name, overwrite=overwrite, flag=flag, inputs=inputs)
    for side in stale:
        check_file_target(side, overwrite=True, flag=flag, inputs=inputs)
    with _dir_lock(parent):
        reg = {k: v for k, v in _registry(parent).items() if (parent / k).is_file()}
        for name in written:
            digest = sha256_file(tmp / name)
            os.replace(tmp / name, parent / name)
            reg[name] = {"sha256": digest, "command": _command(), "written": _stamp()}
        for side in stale:
            side.unlink()
            reg.pop(side.name, None)
        fd, reg_tmp = tempfile.mkstemp(prefix=f".{REGISTRY}.", dir=parent)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump({"files": reg}, fh, indent=1)
        os.replace(reg_tmp, parent / REGISTRY)


@contextlib.contextmanager
def _dir_lock(folder: Path) -> Iterator[None]:
    """An exclusive lock on ``folder`` (its registry is read-modified-written under it)."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
