"""One output-folder policy for every command that writes a folder.

:func:`output_folder` is a context manager.  It

* refuses dangerous targets before any work: ``.``, the home folder, ``/``, the current
  folder or one of its parents, a folder that is (or contains, or lies inside) an input
  file or its sidecar;
* refuses an existing non-empty folder unless ``overwrite=True``, and even then replaces
  only a folder this package wrote (it holds the marker :data:`MARKER`), never one holding
  anything else;
* takes a lock next to the folder (:data:`LOCK_SUFFIX`): a second writer fails at once,
  naming the other run's command and pid; a lock left by a killed run is detected (its
  pid is gone) and replaced;
* writes into a fresh hidden sibling ``.NAME.eap-tmp-PID`` (created at once, so an
  unwritable location fails before any work) and renames it into place at the end, so an
  interrupted or failed run leaves nothing that looks complete.  Temporary folders of
  killed runs are removed by the next run into the same place.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import sys
import time
from pathlib import Path
from typing import Iterable, Iterator

from .errors import InputError

#: File written into every output folder; ``--overwrite`` only replaces folders holding it.
MARKER = ".eap-output.json"
#: Suffix of the lock file written beside an output folder while it is being written.
LOCK_SUFFIX = ".eap-lock"
_TMP = ".eap-tmp-"
_OLD = ".eap-old-"


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


def _inputs_with_sidecars(inputs: Iterable) -> list[Path]:
    out = []
    for p in inputs:
        if p is None:
            continue
        q = Path(p).expanduser().resolve()
        out.append(q)
        if q.suffix.lower() in (".csv", ".mat"):
            out.append(q.with_suffix(".yaml"))
    return out


def check_target(out: Path, inputs: Iterable = (), *, flag: str = "--out") -> Path:
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


def _owned(folder: Path) -> bool:
    return (folder / MARKER).is_file()


def _clean_stale(parent: Path, name: str) -> None:
    """Remove temporary/old folders of killed runs into ``parent/name`` (only ours)."""
    for prefix in (f".{name}{_TMP}", f".{name}{_OLD}"):
        for p in parent.glob(prefix + "*"):
            pid = p.name[len(prefix):].split("-")[0]
            if p.is_dir() and pid.isdigit() and not _pid_alive(int(pid)) \
                    and ((p / MARKER).is_file() or (p / ".eap-partial").is_file()):
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
    info = {"pid": os.getpid(), "command": _command(), "started": time.strftime("%Y-%m-%d %H:%M:%S")}
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


def preflight(out, *, inputs: Iterable = (), overwrite: bool = False, flag: str = "--out") -> Path:
    """Every check of :func:`output_folder` that can be made before any work (target, existing
    content, writability); returns the resolved target.  Commands call it first."""
    res = check_target(Path(out), inputs, flag=flag)
    if res.is_dir() and any(res.iterdir()):
        if not overwrite:
            raise InputError(f"{flag} {out} already exists and is not empty; choose another {flag} "
                             "or pass --overwrite to replace a folder written by eap")
        if not _owned(res):
            raise InputError(f"{flag} {out} holds files eap did not write (no {MARKER}); refusing to "
                             f"replace it even with --overwrite — choose another {flag}")
    other = _lock_holder(res.parent / f".{res.name}{LOCK_SUFFIX}")
    if other:
        raise InputError(_busy(res, other, flag))
    try:
        res.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{flag} {out}: cannot create {res.parent} ({exc.strerror}); choose a writable "
                         f"{flag}") from None
    if not os.access(res.parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {out}: {res.parent} is not writable; choose a writable {flag}")
    return res


@contextlib.contextmanager
def output_folder(out, *, inputs: Iterable = (), overwrite: bool = False,
                  flag: str = "--out") -> Iterator[Path]:
    """Yield a fresh temporary folder; on success it replaces ``out`` atomically.

    ``inputs``: files (and folders) read by the run, never to be replaced.  ``flag``
    names the option in messages.  On any exception (Ctrl-C included) the temporary
    folder is removed and ``out`` is untouched.
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
            (tmp / ".eap-partial").write_text(_command() + "\n", encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{flag} {out}: cannot write in {parent} ({exc.strerror}); choose a "
                             f"writable {flag}") from None
        try:
            yield tmp
            (tmp / MARKER).write_text(json.dumps({"command": _command(), "pid": os.getpid(),
                                                  "written": time.strftime("%Y-%m-%d %H:%M:%S")}) + "\n",
                                      encoding="utf-8")
            (tmp / ".eap-partial").unlink()
            _promote(tmp, res, overwrite, flag, out)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)


def _promote(tmp: Path, res: Path, overwrite: bool, flag: str, out) -> None:
    if res.exists() and res.is_dir() and not any(res.iterdir()):
        res.rmdir()
    if res.exists():
        if not (overwrite and res.is_dir() and _owned(res)):
            raise InputError(f"{flag} {out} appeared while this run was writing and eap did not write it "
                             "(or --overwrite was not given); nothing was written — choose another "
                             f"{flag}")
        old = res.parent / f".{res.name}{_OLD}{os.getpid()}"
        os.replace(res, old)
        os.replace(tmp, res)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, res)
