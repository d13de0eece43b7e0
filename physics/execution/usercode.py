"""Running a user's code contained: an effect file (``--effects-path FILE.py``) is Python
that runs with the user's rights, when it is imported and each time the model calls one of
its hooks.  eap cannot sandbox it; it contains the two mistakes that would otherwise end or
freeze a run without a word:

* an exit call (``sys.exit``, ``os._exit``) made while importing the file or inside a hook
  is caught and becomes one error naming the file and the hook (nothing is written);
* importing the file may take at most :data:`IMPORT_LIMIT_S`, one call of a hook at most
  :data:`HOOK_LIMIT_S`; past that the call is stopped with an error naming it.  The limit
  is a timer in the main thread of the process: it stops Python code (an endless loop), not
  a single long call into compiled code, and a hook called from another thread or a worker
  process of a parallel run has its exit calls caught but no time limit.

:func:`contain_class` wraps the hooks of a class defined in a user's file;
:func:`running_user_code` is the context for any other call into user code.
"""
from __future__ import annotations

import contextlib
import functools
import inspect
import os
import signal
import threading
from pathlib import Path
from typing import Iterator

from ..errors import InputError

#: Longest time [s] importing one effect file may take (defining classes takes milliseconds).
IMPORT_LIMIT_S = 10.0
#: Longest time [s] one call of a user effect's hook may take (a transfer function or a
#: factor over a frequency grid takes milliseconds, filtering a 2·10⁷-sample record ~1 s);
#: a hook that legitimately needs longer (a Python loop over a long record) runs with the
#: environment variable ``EAP_HOOK_LIMIT_S`` set to the seconds it needs.
HOOK_LIMIT_S = 20.0
_HOOK_ENV = "EAP_HOOK_LIMIT_S"


def hook_limit() -> float:
    """:data:`HOOK_LIMIT_S`, or ``$EAP_HOOK_LIMIT_S`` when set to a positive number of seconds."""
    try:
        value = float(os.environ.get(_HOOK_ENV, ""))
    except ValueError:
        return HOOK_LIMIT_S
    return value if 0 < value < 1e6 else HOOK_LIMIT_S


class UserCodeError(InputError):
    """User code (an effect file, a plug-in) exited or ran past its time limit."""


_REAL_EXIT = os._exit
_OWNER = [os.getpid()]
_DEPTH = threading.local()
_LOCK = threading.Lock()
_ACTIVE = [0]     # threads running user code now
#: Files whose code exited or overran: {file name: the error}; their hooks are not called again.
_FAILED: dict[str, str] = {}


class _OsExit(SystemExit):
    """``os._exit`` called by user code (caught in this process)."""


def _refused_exit(code=0):
    """``os._exit`` while user code runs: an exception in this process, the real exit in a
    child process (a forked worker ends with it)."""
    if os.getpid() != _OWNER[0]:
        _REAL_EXIT(code)
    raise _OsExit(code)


class _Timeout(BaseException):
    """Raised by the timer inside the user's code (a BaseException: the code's own
    ``except Exception`` does not swallow it)."""


def _alarm(signum, frame):
    raise _Timeout()


@contextlib.contextmanager
def running_user_code(where: str, limit_s: float) -> Iterator[None]:
    """Run the block as user code: ``sys.exit``/``os._exit`` inside it become a
    :class:`UserCodeError` naming ``where`` (e.g. ``"eff.py: Creep.output_tf"``), and in the
    main thread the block is stopped after ``limit_s`` seconds.  Nested blocks run under the
    outermost one."""
    depth = getattr(_DEPTH, "n", 0)
    if depth:
        _DEPTH.n = depth + 1
        try:
            yield
        finally:
            _DEPTH.n = depth
        return
    timed = threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer") \
        and signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    previous = signal.signal(signal.SIGALRM, _alarm) if timed else None
    with _LOCK:                    # os._exit is one for the process: replaced while any thread runs user code
        _OWNER[0] = os.getpid()
        _ACTIVE[0] += 1
        os._exit = _refused_exit
    _DEPTH.n = 1
    try:
        try:
            if timed:
                signal.setitimer(signal.ITIMER_REAL, limit_s)
            yield
        finally:               # the timer off first: a late alarm still lands in the except below
            if timed:
                signal.setitimer(signal.ITIMER_REAL, 0.0)
    except _Timeout:
        raise UserCodeError(f"{where} ran longer than {limit_s:g} s (eap's limit on one call into user code; "
                            f"an endless loop? a hook that needs longer runs with {_HOOK_ENV}=SECONDS) and was "
                            "stopped; nothing was written") from None
    except SystemExit as exc:
        call = "os._exit" if isinstance(exc, _OsExit) else "sys.exit"
        raise UserCodeError(f"{where} called {call}({exc.code!r}); user code must not end the program — nothing "
                            "was written") from None
    finally:
        _DEPTH.n = 0
        if timed:
            signal.signal(signal.SIGALRM, previous)
        with _LOCK:
            _ACTIVE[0] -= 1
            if not _ACTIVE[0]:
                os._exit = _REAL_EXIT


def _contained(fn, where: str, key: str):
    @functools.wraps(fn)
    def call(*args, **kwargs):
        if key in _FAILED:     # one overrun or exit per file, not one per call
            raise UserCodeError(_FAILED[key])
        try:
            with running_user_code(where, hook_limit()):
                return fn(*args, **kwargs)
        except UserCodeError as exc:
            _FAILED.setdefault(key, str(exc))
            raise
    call.__eap_contained__ = True
    return call


def contain_class(cls, path) -> None:
    """Wrap every method ``cls`` (defined in the file ``path``) defines itself (plain, class and
    static methods) so that each call runs under :func:`running_user_code`, named
    ``FILE: Class.method``; after one overrun or exit no method of the file runs again."""
    path = Path(path)
    for name, value in list(vars(cls).items()):
        if name.startswith("__"):
            continue
        where, key = f"{path.name}: {cls.__name__}.{name}", str(path.resolve())
        if isinstance(value, (staticmethod, classmethod)) and inspect.isfunction(value.__func__):
            setattr(cls, name, type(value)(_contained(value.__func__, where, key)))
        elif inspect.isfunction(value) and not getattr(value, "__eap_contained__", False):
            setattr(cls, name, _contained(value, where, key))


def import_limited(exec_module, module, where: str) -> None:
    """``exec_module(module)`` (importing a user's file) under :func:`running_user_code` with
    :data:`IMPORT_LIMIT_S`."""
    with running_user_code(where, IMPORT_LIMIT_S):
        exec_module(module)


__all__ = ["IMPORT_LIMIT_S", "HOOK_LIMIT_S", "UserCodeError", "hook_limit", "running_user_code", "contain_class",
           "import_limited"]
