"""Architecture rules read from the sources with :mod:`ast` (issue 26).

1. Physics raises errors that name API arguments, never command-line flags: a flag in a
   ``raise`` of ``physics/`` is allowed only in the modules of :data:`FLAG_ALLOWLIST`, which
   other tracks are converting (the list only ever shrinks).
2. Nothing outside ``physics/effects/`` names an effect id or an effect-owned parameter
   (docstrings and comments aside): see :func:`effect_literals`.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from physics.errors import InputError, arg

ROOT = Path(__file__).resolve().parent.parent

#: physics modules whose raises still name flags, (module, count): physics/diagnose/**,
#: physics/identify/**, physics/compare/** are converted by the `dx` track, the readers and
#: writers (timeseries, outputs, fileio, parallel) by the `io` track.  Only ever shrinks.
FLAG_ALLOWLIST = {
    "physics/compare/comparison.py": 2, "physics/compare/measurements.py": 1,
    "physics/diagnose/demo.py": 2, "physics/diagnose/diagnosis.py": 6, "physics/diagnose/records.py": 1,
    "physics/diagnose/report.py": 1, "physics/identify/parameters.py": 1, "physics/identify/problem.py": 4,
    "physics/fileio.py": 1, "physics/outputs.py": 3, "physics/parallel.py": 2, "physics/timeseries.py": 6,
}
_FLAG = re.compile(r"(?<![\w-])--[A-Za-z][\w-]*")


def flag_raises(root: Path = ROOT) -> dict[str, int]:
    """{module: number of ``raise`` statements whose string constants name a ``--flag``}."""
    out = {}
    for f in sorted((root / "physics").rglob("*.py")):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        n = 0
        for node in ast.walk(tree):
            if isinstance(node, ast.Raise) and node.exc is not None:
                text = " ".join(c.value for c in ast.walk(node.exc)
                                if isinstance(c, ast.Constant) and isinstance(c.value, str))
                n += bool(_FLAG.search(text))
        if n:
            out[f.relative_to(root).as_posix()] = n
    return out


def test_physics_raises_name_arguments_not_flags():
    found = flag_raises()
    new = {m: n for m, n in found.items() if n > FLAG_ALLOWLIST.get(m, 0)}
    assert not new, f"physics raises naming a CLI flag (use physics.errors.arg): {new}"
    stale = {m: (FLAG_ALLOWLIST[m], found.get(m, 0)) for m in FLAG_ALLOWLIST if found.get(m, 0) < FLAG_ALLOWLIST[m]}
    assert not stale, f"converted modules: shrink FLAG_ALLOWLIST (allowed, found) {stale}"


def test_the_flag_rule_can_fail(tmp_path):
    (tmp_path / "physics").mkdir()
    (tmp_path / "physics" / "bad.py").write_text(
        "def f(x):\n    raise ValueError(f'{x}: pass --overwrite')\n\ndef g():\n    raise ValueError('x: ' + 'use --rh')\n")
    assert flag_raises(tmp_path) == {"physics/bad.py": 2}


def test_errors_name_the_argument_in_python_and_the_flag_on_the_command_line(tmp_path, capsys):
    from nnmodel.cli import main
    from physics.sweep import parse_grid
    with pytest.raises(InputError) as info:
        parse_grid(["Yy=1,2"], None)
    assert str(info.value).startswith("grid Yy: unknown parameter") and "--" not in str(info.value)
    assert info.value.params == ("grid",)
    assert info.value.render({"grid": "--grid"}.get).startswith("--grid Yy: unknown parameter")
    assert main(["sweep", "--grid", "Yy=1,2", "--out", str(tmp_path / "s.csv")]) == 2
    assert "error: --grid Yy: unknown parameter" in capsys.readouterr().err
    # an argument whose flag differs from its Python name
    assert main(["frf", "--effects-path", str(tmp_path / "nope.py"), "--json", str(tmp_path / "f.json")]) == 2
    assert "error: --effects-path " in capsys.readouterr().err
    from physics.effects import load_effects_file
    with pytest.raises(InputError, match=r"^path .*nope\.py: expected an existing Python file"):
        load_effects_file(tmp_path / "nope.py")


def test_argument_references_survive_pickling():
    import pickle
    err = pickle.loads(pickle.dumps(InputError(f"give the RH with {arg('rh')} (a number)")))
    assert str(err) == "give the RH with rh (a number)" and err.params == ("rh",)
    assert err.render(lambda name: "--" + name) == "give the RH with --rh (a number)"
