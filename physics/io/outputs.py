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
  command).
* **Ownership by proof, not by name.**  Every temporary folder carries :data:`PROOF`, naming
  that very folder, the pid and the start time of the process that made it; a leftover of a
  killed run is removed only with that proof and once that process is gone (a pid reused by
  another program does not count).  A folder or lock that is merely *named* like eap's is
  left in place and named in a note.
* **Names never escape.**  A user-given name that becomes a file (``--name``, a record's or a
  model's name) is one plain path component (:func:`component`), checked before any work; an
  output and a sub-output of the same run (``--out`` and ``--draft-effects``) may not be the
  same or lie in one another (:func:`separate`).
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

from ..errors import InputError, arg
from .fileio import final_text, sha256_file

#: File written into every output folder: the files eap wrote there, with their SHA-256.
MARKER = ".eap-output.json"
#: Hidden registry, in a folder holding single-file outputs, of the files eap wrote there.
REGISTRY = ".eap-files.json"
#: Suffix of the lock file written beside an output folder while it is being written.
LOCK_SUFFIX = ".eap-lock"
_TMP = ".eap-tmp-"
_OLD = ".eap-old-"
#: Proof of ownership written into every temporary folder eap makes (JSON: the folder's name,
#: the pid and start time of the process that made it); also what marks the folder unfinished.
PROOF = ".eap-partial"
#: Longest name (bytes, UTF-8) a user-given name may have: a file system allows 255, and eap
#: adds suffixes (``.yaml``, ``_3``, ``.eap-tmp-PID``).
MAX_NAME_BYTES = 200
_OUT = arg("out")   # how messages name an output path by default (the CLI: --out)
#: How messages name the output folder of a library writer (``write_diagnosis(res, out_dir)``):
#: ``out_dir`` in Python, ``--out`` on the command line.
OUT_DIR = arg("out", "out_dir")
_PROTECTED: set[Path] = set()
#: Interrupts raised by the command line's signal handlers (SIGTERM). Python drops an exception
#: raised inside a gc callback or a finaliser (it prints it and carries on): no output is put in
#: place after one.
INTERRUPTS: list[BaseException] = []


def raise_if_interrupted() -> None:
    """Raise the first interrupt of :data:`INTERRUPTS`, if any (even one Python dropped)."""
    if INTERRUPTS:
        raise INTERRUPTS[0]


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


def with_sources(inputs: Iterable, sources: Iterable) -> list:
    """``inputs`` with those of ``sources`` that are existing files: the records a result was
    computed from (``source``: a file's path, or a name for a record made in memory), inputs a
    library writer protects without its caller listing them."""
    out = [p for p in inputs if p is not None]
    for s in sources:
        try:
            if isinstance(s, (str, os.PathLike)) and str(s) and Path(s).is_file():
                out.append(s)
        except (OSError, ValueError):     # a name no file system holds (a NUL, too long)
            continue
    return out


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
    except (PermissionError, OverflowError):
        return pid < 2 ** 31
    return True


def process_start(pid: int) -> str | None:
    """When process ``pid`` started, as an opaque token (Linux: clock ticks since boot, field
    22 of ``/proc/PID/stat``), or None where the system does not say: with the pid it tells
    a process from a later one that reuses its number."""
    try:
        stat = Path(f"/proc/{int(pid)}/stat").read_text()
        return stat[stat.rindex(")") + 2:].split()[19]
    except (OSError, ValueError, IndexError):
        return None


def _running(pid, started) -> bool:
    """Whether the process ``pid`` that started at ``started`` (:func:`process_start`) still runs."""
    if isinstance(pid, bool) or not isinstance(pid, int) or not _pid_alive(pid):
        return False
    now = process_start(pid)
    return started is None or now is None or now == started


def _write_proof(folder: Path) -> None:
    """Write :data:`PROOF` into the temporary folder ``folder`` this process made."""
    pid = os.getpid()
    (folder / PROOF).write_text(json.dumps({"eap": "temporary folder", "folder": folder.name, "pid": pid,
                                            "pid_start": process_start(pid), "command": _command(),
                                            "started": _stamp()}) + "\n",
                                encoding="utf-8")


def _proof_of(folder: Path) -> dict | None:
    """The proof inside ``folder`` when it names that very folder (a real folder, not a link)
    and a pid, else None."""
    proof = folder / PROOF
    try:
        if folder.is_symlink() or not folder.is_dir() or proof.is_symlink() or not proof.is_file() \
                or proof.stat().st_size > 4096:
            return None
        info = json.loads(proof.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(info, dict) or info.get("folder") != folder.name or not isinstance(info.get("pid"), int):
        return None
    return info


def _sweep(candidates: Iterable[Path]) -> None:
    """Remove the leftover temporary folders among ``candidates`` that carry eap's proof and
    whose process is gone; name in a note those that look like eap's but carry no proof."""
    import warnings

    from ..errors import InputNotice
    for p in candidates:
        info = _proof_of(p)
        if info is None:
            warnings.warn(InputNotice(f"{p} is named like a temporary folder of eap but does not carry eap's "
                                      f"proof of ownership ({PROOF} naming it); left in place — remove it "
                                      "yourself if it is not yours to keep"))
        elif not _running(info["pid"], info.get("pid_start")):
            shutil.rmtree(p, ignore_errors=True)


def component(name, flag: str, what: str = "a file name") -> str:
    """``name`` checked as one plain path component (it becomes ``what`` inside an output):
    text, not empty, no ``/`` or ``\\``, not ``.``/``..``, no leading ``.`` (eap's hidden files), no
    control character, at most :data:`MAX_NAME_BYTES` bytes.  Raises :class:`InputError`."""
    text = str(name)
    problem = None
    if not text.strip():
        problem = "is empty"
    elif "/" in text or "\\" in text or text in (".", ".."):
        problem = "is a path, not a name"
    elif text.startswith("."):
        problem = "starts with '.' (a hidden file, like eap's own)"
    elif any(ord(c) < 32 or ord(c) == 127 for c in text):
        problem = "holds a control character"
    elif len(text.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES:
        problem = f"is longer than {MAX_NAME_BYTES} bytes"
    if problem:
        shown = text if len(text) <= 120 else text[:80] + "…" + text[-30:]
        raise InputError(f"{flag} {shown!r}: {problem}; it becomes {what} inside the output, so it must be one "
                         f"plain name (no '/', no leading '.', at most {MAX_NAME_BYTES} bytes)")
    return text


def separate(outputs: dict) -> None:
    """Refuse outputs of one run (``{flag: path}``, None ignored) that are the same path or lie
    one inside another: each is written (and replaced with ``--overwrite``) as a whole."""
    items = [(flag, Path(path).expanduser().resolve()) for flag, path in outputs.items() if path is not None]
    for i, (fa, a) in enumerate(items):
        for fb, b in items[i + 1:]:
            if a == b or a in b.parents or b in a.parents:
                how = "is the same folder as" if a == b else ("contains" if a in b.parents else "lies inside")
                raise InputError(f"{fa} {outputs[fa]} {how} {fb} {outputs[fb]}; each output is written and replaced "
                                 f"as a whole — give {fb} a path outside {fa}")


def _command() -> str:
    return " ".join(["eap"] + sys.argv[1:]) if sys.argv else "eap"


def _stamp() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


# --------------------------------------------------------------------------- OS errors

#: What each operating-system error means for a user, and what to do (by errno name).
_OS_ADVICE = {
    "ENOSPC": "the disk is full; free space or write elsewhere",
    "EDQUOT": "the disk quota is exhausted; free space or write elsewhere",
    "EFBIG": "the file would exceed the file-size limit of this process or file system (ulimit -f); raise it or "
             "write less",
    "EACCES": "permission denied; check the permissions, or choose another path",
    "EPERM": "operation not permitted; check the permissions, or choose another path",
    "EROFS": "the file system is read-only; choose another path",
    "EISDIR": "it is a folder, where a file was expected",
    "ENOTDIR": "a part of the path is a file, where a folder was expected",
    "ENAMETOOLONG": "the name is too long for the file system (255 bytes per name)",
    "ENOENT": "no such file or folder",
    "ELOOP": "too many symbolic links (a loop?)",
    "ENXIO": "it is a device or a pipe without a writer, not a regular file",
    "ESPIPE": "it is a pipe or a device, not a regular file",
    "EMFILE": "too many open files (ulimit -n)",
    "EIO": "an input/output error of the device",
}


def os_error_line(exc: OSError, target: str | None = None) -> str:
    """One line for an operating-system error: the file (as the user named it: never eap's
    temporary path; ``target``, e.g. ``"--out D"``, when the error names none), what went wrong
    and what to do.  Outputs are written aside and renamed at the end: nothing was written."""
    import errno
    code = errno.errorcode.get(exc.errno or 0, "")
    what = _OS_ADVICE.get(code) or (exc.strerror or type(exc).__name__)
    name = exc.filename
    if name is not None:
        shown = final_text(os.fsdecode(name) if isinstance(name, (bytes, str)) else str(name))
        if len(shown) > 160:
            shown = shown[:80] + "…" + shown[-60:]
        where = f"{shown}: "
    else:
        where = f"{target}: " if target else ""
    return f"{where}{what} ({exc.strerror or code}); nothing was written"


# --------------------------------------------------------------------------- ownership

def _listing(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``folder`` (the marker excluded)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        dirs.sort()
        for name in sorted(files):
            p = Path(root) / name
            rel = p.relative_to(folder).as_posix()
            if rel not in (MARKER, PROOF):
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

def _short_name(path: Path, flag: str, out) -> None:
    """Refuse an output whose name leaves no room for eap's temporary and lock names beside it."""
    if len(path.name.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES:
        raise InputError(f"{flag} {str(out)[:60]}…: a name of {len(path.name)} characters; an output's name may have "
                         f"at most {MAX_NAME_BYTES} bytes (a file system allows 255, and eap adds a suffix beside it)")


def check_target(out: Path, inputs: Iterable = (), *, flag: str = _OUT) -> Path:
    """Resolve ``out`` and refuse targets that could destroy the user's files."""
    out = Path(out).expanduser()
    _short_name(out, flag, out)
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
    """Remove temporary/old folders of killed runs into ``parent/name`` (with eap's proof only)."""
    _sweep(p for prefix in (f".{name}{_TMP}", f".{name}{_OLD}") for p in parent.glob(prefix + "*")
           if p.name[len(prefix):].isdigit())


def _lock_holder(lock: Path, flag: str = _OUT) -> dict | None:
    """The lock's content when a live process other than this one holds it, else None (no
    lock, or the lock of a run that is gone).  A lock path that is not eap's lock file (a
    folder, a link, other content) is refused, naming it."""
    if not (lock.exists() or lock.is_symlink()):
        return None
    other = None
    try:
        if lock.is_file() and not lock.is_symlink() and lock.stat().st_size <= 4096:
            other = json.loads(lock.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        other = None
    if not isinstance(other, dict) or isinstance(other.get("pid"), bool) or not isinstance(other.get("pid"), int):
        raise InputError(f"{flag}: {lock} is in the place of eap's lock file but is not one (a folder, a link or "
                         "other content); eap leaves it alone — move it away, or choose another " + flag)
    pid = other["pid"]
    return other if pid != os.getpid() and _running(pid, other.get("pid_start")) else None


def _busy(target: Path, other: dict, flag: str) -> str:
    return (f"{flag} {target} is being written by another run (pid {other.get('pid')}: "
            f"{other.get('command', '?')}, started {other.get('started', '?')}); wait for it to finish or choose "
            f"another {flag}")


@contextlib.contextmanager
def _lock(parent: Path, name: str, flag: str) -> Iterator[None]:
    lock = parent / f".{name}{LOCK_SUFFIX}"
    info = {"pid": os.getpid(), "pid_start": process_start(os.getpid()), "command": _command(), "started": _stamp()}
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            other = _lock_holder(lock, flag)
            if other:
                raise InputError(_busy(parent / name, other, flag)) from None
            lock.unlink(missing_ok=True)  # stale: the lock of a run that is gone
            continue
        except OSError as exc:
            raise InputError(f"{flag} {parent / name}: cannot write in {parent} ({exc.strerror}); choose "
                             f"a writable {flag}") from None
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(info, fh)
        break
    else:
        raise InputError(f"{flag} {parent / name}: another run took the lock {lock} meanwhile; try again")
    try:
        yield
    finally:
        _unlock(lock)


def _unlock(lock: Path) -> None:
    """Remove ``lock`` when it is this process's (a writer nested in :func:`reserve` took it
    over and removed it already; another run may hold it since)."""
    try:
        mine = json.loads(lock.read_text(encoding="utf-8")).get("pid") == os.getpid()
    except (OSError, ValueError, AttributeError):
        mine = False
    if mine:
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
    other = _lock_holder(res.parent / f".{res.name}{LOCK_SUFFIX}", flag)
    if other:
        raise InputError(_busy(res, other, flag))
    _writable_parent(res.parent, flag, out)
    return res


@contextlib.contextmanager
def reserve(out, *, inputs: Iterable = (), overwrite: bool = False, flag: str = _OUT) -> Iterator[Path]:
    """:func:`preflight`, then hold the lock of ``out`` for the block (a second run into ``out``
    fails at once while this one works); the writer called inside the block with the same
    arguments (:func:`output_folder`) takes the lock over and checks everything again."""
    res = preflight(out, inputs=inputs, overwrite=overwrite, flag=flag)
    with _lock(res.parent, res.name, flag):
        yield res


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
        if tmp.exists() or tmp.is_symlink():   # this pid's own leftover (a reused pid): ours only with proof
            if _proof_of(tmp) is None:
                raise InputError(f"{flag} {out}: {tmp} is in the way and does not carry eap's proof of ownership; "
                                 "eap leaves it alone — move it away, or choose another " + flag)
            shutil.rmtree(tmp)
        try:
            tmp.mkdir()
            _write_proof(tmp)
        except OSError as exc:
            raise InputError(f"{flag} {out}: cannot write in {parent} ({exc.strerror}); choose a "
                             f"writable {flag}") from None
        try:
            yield tmp
            (tmp / MARKER).write_text(json.dumps({"command": _command(), "pid": os.getpid(), "written": _stamp(),
                                                  "files": _listing(tmp)}, indent=1) + "\n", encoding="utf-8")
            (tmp / PROOF).unlink()
            _promote(tmp, res, overwrite, flag, out)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _promote(tmp: Path, res: Path, overwrite: bool, flag: str, out) -> None:
    raise_if_interrupted()
    if res.exists() and res.is_dir() and not any(res.iterdir()):
        res.rmdir()
    if res.exists():
        if not (overwrite and res.is_dir() and (res / MARKER).is_file()):
            raise InputError(f"{flag} {out} appeared while this run was writing and eap did not write it "
                             f"(or {arg('overwrite')} was not given); nothing was written — choose another "
                             f"{flag}")
        _refuse_foreign(res, flag, out)   # checked again: files may have been added meanwhile
        old = res.parent / f".{res.name}{_OLD}{os.getpid()}"
        if old.exists() or old.is_symlink():
            raise InputError(f"{flag} {out}: {old} is in the way (not removed: it is not proven to be eap's); move "
                             "it away and run again")
        os.replace(res, old)
        os.replace(tmp, res)
        with contextlib.suppress(OSError):
            _write_proof(old)    # the replaced folder, proven ours for a sweep should the removal be cut short
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
    _short_name(p, flag, path)
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
        _check_registry(res.parent, flag)
        targets.append(res)
    for t in targets:
        side = None if t is None or t.suffix.lower() != ".csv" else t.with_suffix(".yaml")
        if side is not None and side in targets:
            i = targets.index(side)
            raise InputError(f"{flags[i]} {paths[i]} is also the sidecar of the CSV output {t.name} (its metadata, "
                             "written beside it); give distinct names")
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
                    _write_proof(staging[res.parent])
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
    """Remove staging folders of killed single-file writers in ``parent`` (with eap's proof only)."""
    _sweep(p for p in parent.glob(f"{_TMP}*") if re.fullmatch(r"\d+-[A-Za-z0-9_]+", p.name[len(_TMP):]))


def _check_registry(parent: Path, flag: str) -> None:
    """Refuse a registry path that is not a regular file (a folder, a link): eap would fail
    after putting its files in place, or write through the link."""
    reg = parent / REGISTRY
    if reg.is_symlink() or (reg.exists() and not reg.is_file()):
        raise InputError(f"{flag}: {reg} is in the place of eap's registry of the files it wrote there but is not a "
                         "regular file; eap leaves it alone — move it away, or write into another folder")


def _promote_files(parent: Path, tmp: Path, targets: list[Path], overwrite: bool, flag: str, inputs) -> None:
    raise_if_interrupted()
    written = sorted(p.name for p in tmp.iterdir() if p.name != PROOF)
    stale = [t.with_suffix(".yaml") for t in targets if t.suffix.lower() == ".csv"
             and t.with_suffix(".yaml").name not in written and t.with_suffix(".yaml").exists()]
    for name in written:
        check_file_target(parent / name, overwrite=overwrite, flag=flag, inputs=inputs)
    for side in stale:
        check_file_target(side, overwrite=True, flag=flag, inputs=inputs)
    _check_registry(parent, flag)
    with _dir_lock(parent):
        reg = {k: v for k, v in _registry(parent).items() if (parent / k).is_file()}
        for name in written:
            reg[name] = {"sha256": sha256_file(tmp / name), "command": _command(), "written": _stamp()}
        for side in stale:
            reg.pop(side.name, None)
        # the registry is written before any file is put in place: a failure (disk full) leaves the
        # folder as it was; a registry listing a file not yet in place is harmless (checked by hash)
        fd, reg_tmp = tempfile.mkstemp(prefix=f".{REGISTRY}.", dir=tmp)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump({"files": reg}, fh, indent=1)
        for name in written:
            os.replace(tmp / name, parent / name)
        for side in stale:
            side.unlink()
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
