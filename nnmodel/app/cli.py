"""The ``eap`` command line.

Sub-commands live in :mod:`nnmodel.app.commands`, one module each.  A module defines
``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; it is found
automatically, so adding a command never edits this file.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import signal
import sys
import tempfile
import warnings
from pathlib import Path

import yaml

from physics.errors import InputError, InputNotice, ModelError
from physics.io.fileio import final_text
from physics.io.outputs import INTERRUPTS, os_error_line, protecting, raise_if_interrupted

from . import commands


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, but not "(default: None)" on required or unset options."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False or action.required:
            return action.help
        return super()._get_help_string(action)


def _command_modules():
    mods = []
    for info in pkgutil.iter_modules(commands.__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{commands.__name__}.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return sorted(mods, key=lambda m: m.NAME)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="eap",
        description="Models of ionic electroactive-polymer actuators (IPMC, IP2C): "
        "physics simulation, measurements, identification, diagnosis and neural models.",
    )
    from physics._version import __version__
    parser.add_argument("--version", action="version", version=f"eap-model {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        # argparse %-formats help strings: a literal "%" (e.g. "RH 40–100 %") must be doubled
        p = sub.add_parser(mod.NAME, help=mod.HELP.replace("%", "%%"),
                           description=getattr(mod, "DESCRIPTION", mod.HELP),
                           formatter_class=_HelpFormatter)
        mod.add_arguments(p)
        inputs = tuple(getattr(mod, "INPUTS", ()))
        if "--device" in p._option_string_actions or getattr(mod, "TAKES_PARAMS", False):
            p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                           help="override a device parameter, with its unit, e.g. --param L_total=40mm "
                                "--param width=10mm (repeatable; `eap effects --device D` lists the names, units and values)")
        if "--effects" in p._option_string_actions or getattr(mod, "TAKES_EFFECT_FILES", False):
            inputs += ("effects_path",)
            p.add_argument("--effects-path", action="append", default=[], metavar="FILE.py",
                           help="a Python file defining user effects (physics.effects.OutputEffect subclasses, "
                                "see examples/effects/creep.py); repeatable. The file is CODE: eap imports and "
                                "runs it with your rights (exit calls are caught and each call is time-limited, "
                                "but it is not sandboxed) — use only files you trust (docs/security.md)")
        p.set_defaults(_run=mod.run, _inputs=inputs)
    return parser


def main(argv: list[str] | None = None) -> int:
    INTERRUPTS.clear()
    previous = _handle_signals()    # first: a signal during start-up is clean too
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except (KeyboardInterrupt, Terminated) as exc:
        _restore_signals(previous)
        print("eap: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    if not getattr(args, "_run", None):
        _restore_signals(previous)
        parser.print_help()
        return 2
    shown = warnings.showwarning
    warnings.showwarning = _notice(args.command)
    try:
        _load_effects(getattr(args, "effects_path", []))
        with protecting(_inputs_of(args)), tempfile.TemporaryDirectory(prefix="eap-param-") as tmp:
            _apply_params(args, Path(tmp))
            rc = int(args._run(args) or 0)
            raise_if_interrupted()      # a SIGTERM that Python dropped (raised in a gc callback) still counts
            return rc
    except InputError as exc:   # every message names the user's paths, never eap's temporary ones
        print(f"eap {args.command}: error: {final_text(exc.render(flag_speller(parser, args.command)))}",
              file=sys.stderr)
        return 2
    except ModelError as exc:
        print(f"eap {args.command}: error: {final_text(str(exc))}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Terminated) as exc:
        out = getattr(args, "out", None)
        where = f"; nothing written to {out}" if out else ""
        print(f"eap {args.command}: interrupted{where}", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except MemoryError:
        print(f"eap {args.command}: error: out of memory; use a shorter record (split it) or a machine with "
              "more memory", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`
        sys.stderr.close()
        return 0
    except OSError as exc:   # disk full, file too large, permission, wrong kind of file, name too long
        print(f"eap {args.command}: error: {os_error_line(exc, _target(args))}", file=sys.stderr)
        return 2
    except SystemExit as exc:   # user code (an effect file) called sys.exit: nothing may look complete
        print(f"eap {args.command}: error: user code called sys.exit({exc.code!r}) during the run; nothing was "
              "written (an effect file must not exit)", file=sys.stderr)
        return 2
    finally:
        _restore_signals(previous)
        warnings.showwarning = shown


def _target(args) -> str | None:
    """The output the command writes, as its flag and value (``--out D``), for messages."""
    for name in ("out", "json"):
        value = getattr(args, name, None)
        if value:
            return f"--{name} {value}"
    return None


def _inputs_of(args) -> list[Path]:
    """Existing files and folders named by the options the command declares as its inputs
    (``INPUTS`` of its module; protected from every output; a dataset part
    ``FILE[START:STOP]`` counts as FILE)."""
    out = []
    for name in getattr(args, "_inputs", ()):
        value = getattr(args, name, None)
        for item in value if isinstance(value, list) else [value]:
            if isinstance(item, str) and item:
                path = Path(item.split("[", 1)[0] if item.endswith("]") else item)
                if path.exists():
                    out.append(path)
    return out


def _notice(command: str):
    """``warnings.showwarning`` for the command line: one line per warning, ``eap CMD: note: …``
    for an :class:`~physics.errors.InputNotice`, ``eap CMD: warning: …`` otherwise."""
    said = set()

    def show(message, category, filename, lineno, file=None, line=None):
        kind = "note" if issubclass(category, InputNotice) else "warning"
        text = f"eap {command}: {kind}: {' '.join(str(message).split())}"
        if text not in said:   # a file read twice (two sample ranges of it) says it once
            said.add(text)
            print(text, file=file or sys.stderr)
    return show


def flag_speller(parser: argparse.ArgumentParser, command: str):
    """``spell(name)`` for :meth:`physics.errors.InputError.render`: the flag of ``command``
    whose destination is the argument ``name`` (``fs_Hz`` → ``--fs-Hz``), else the flag a
    command module maps it to in its ``FLAGS`` dict (API argument → flag), else None (the
    Python spelling is kept)."""
    sub = next((a.choices[command] for a in parser._actions if isinstance(a, argparse._SubParsersAction)
                and command in a.choices), None)
    flags = {} if sub is None else {a.dest: max(a.option_strings, key=len) for a in sub._actions if a.option_strings}
    mod = next((m for m in _command_modules() if m.NAME == command), None)
    flags.update(getattr(mod, "FLAGS", {}))
    return flags.get


def parse_quantity(text: str) -> tuple[str, float]:
    """``--param`` ``"NAME=VALUE[UNIT]"`` (e.g. ``L_total=40mm``, ``Y=0.2 GPa``, ``kf=0.004``) →
    (name, value in SI), the unit checked against the parameter's; no unit means SI."""
    import difflib
    import re
    from physics.device import all_param_specs
    from physics.io.units import UnitError, to_si
    name, sep, rest = (s.strip() for s in text.partition("="))
    specs = all_param_specs()
    if not sep or not name:
        raise InputError(f"--param {text!r}: expected NAME=VALUE with a unit, e.g. L_total=40mm")
    if name not in specs:
        close = difflib.get_close_matches(name, list(specs), n=3)
        raise InputError(f"--param {name}: unknown parameter" + (f" (did you mean {', '.join(close)}?)" if close
                                                                  else "; see `eap effects --device D` for names"))
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*)$", rest)
    if not m:
        raise InputError(f"--param {text!r}: {rest!r} is not a number with an optional unit")
    value, unit = float(m.group(1)), m.group(2).strip()
    if not unit:
        return name, value
    try:
        return name, float(to_si(value, unit, specs[name].unit))
    except UnitError as exc:
        raise InputError(f"--param {text!r}: {exc} (the unit of {name} is {specs[name].unit})") from None


def _apply_params(args, tmp: Path) -> None:
    """``--param NAME=VALUE``: the device with these values, as a temporary device file that
    replaces ``--device`` (or a device ``--model``) for this run; a notice names the changes."""
    items = getattr(args, "param", None)
    if not items:
        return
    from physics.device import load_device
    from physics.identify.devicefile import device_to_raw
    attr = "device" if hasattr(args, "device") else "model"
    ref = getattr(args, attr)
    if attr == "model" and Path(ref).is_dir():
        raise InputError("--param changes a device; --model is a neural-model bundle here")
    dev = load_device(ref)
    values: dict[str, float] = {}
    for item in items:
        name, value = parse_quantity(item)
        if name in values:
            given = ", ".join(i for i in items if i.split("=")[0].strip() == name)
            raise InputError(f"--param {name} is given twice ({given}); give each parameter once")
        values[name] = value
    try:
        dev = dev.with_params(**values)
    except InputError as exc:
        raise InputError(f"--param {' '.join(items)}: {exc}") from None
    path = tmp / "device.yaml"        # not the device's own name: a name from a file never becomes a path
    path.write_text(yaml.safe_dump(device_to_raw(dev), sort_keys=False, allow_unicode=True), encoding="utf-8")
    setattr(args, attr, str(path))
    from physics.device import all_param_specs
    specs = all_param_specs()
    print(f"eap {args.command}: device {dev.name} with "
          + ", ".join(f"{k} = {v:g} {specs[k].unit}" for k, v in values.items()) + " (from --param)", file=sys.stderr)


def _load_effects(paths) -> None:
    """Register the effects of installed packages (entry points ``eap.effects``) and of
    the files given with ``--effects-path``."""
    from physics.effects import load_effects_file, load_plugins
    load_plugins()
    for path in paths:
        load_effects_file(path)


class Terminated(BaseException):
    """SIGTERM as an exception, so that output folders are cleaned up like on Ctrl-C."""


def _on_signal(signum, frame):
    INTERRUPTS.append(Terminated() if signum == signal.SIGTERM else KeyboardInterrupt())
    raise INTERRUPTS[-1]   # kept: raised where Python drops exceptions (a gc callback), it still stops the run


def _handle_signals() -> dict:
    """Install :func:`_on_signal` for SIGTERM, and for SIGINT unless it is ignored (a
    background job); returns the previous handlers for :func:`_restore_signals`."""
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _on_signal)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _on_signal)
    return previous


def _restore_signals(previous: dict) -> None:
    for signum, handler in previous.items():
        signal.signal(signum, handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
