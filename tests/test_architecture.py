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

#: physics modules whose raises still name flags, (module, count): every module is converted
#: (the `dx` and `io` tracks); the list only ever shrinks.
FLAG_ALLOWLIST: dict[str, int] = {}
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
    from nnmodel.app.cli import main
    from physics.solvers.sweep import parse_grid
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


# ------------------------------------------------------------------ effects are named only in physics/effects

#: Offenders in physics/diagnose/** and physics/identify/** (file → literals): emptied by the `dx`
#: track (hooks on the effects replaced them); it stays empty.  It only ever shrinks
#: (an entry that no longer occurs fails the test until it is removed here).
DX_ALLOWLIST: dict = {}
#: Legitimate data, not code that branches on an effect: a scenario's choice of effect, as a
#: device file's default effect list is (file → literals, with the reason).
DATA = {
    "nnmodel/dataset.py": ({"nonlinear_charge"}, "the default configuration's measurement-like records "
                                                 "(the same as configs/datasets/default.yaml)"),
    "nnmodel/app/story.py": ({"solvent_diffusion"}, "the effect the one-page story's loop hides"),
}


def _effect_words() -> tuple[set[str], re.Pattern]:
    """Effect ids and effect-owned parameter/table names of the built-ins, and a pattern for the
    identifier-like ones (with '_' or a digit), which are matched inside any string; plain words
    (``humidity``, ``thermal``, ``dma``) only as a whole literal, since they are also English."""
    from physics.effects import BUILT_IN_EFFECTS, CHAIN
    classes = list(BUILT_IN_EFFECTS) + list(CHAIN)
    words = {c.id for c in classes if c.id} | {p.name for c in classes for p in c.params} \
        | {t.name for c in classes for t in c.tables}
    ident = sorted((w for w in words if re.search(r"[_0-9]", w)), key=len, reverse=True)
    return words, re.compile(r"(?<![A-Za-z0-9_])(" + "|".join(map(re.escape, ident)) + r")(?![A-Za-z0-9_])")


def effect_literals(root: Path = ROOT, packages=("physics", "nnmodel")) -> dict[str, set[str]]:
    """{file: effect ids and effect-owned parameter names in its string literals}, for every
    module of ``packages`` outside ``physics/effects/``; docstrings (and comments) do not count."""
    words, pattern = _effect_words()
    out: dict[str, set[str]] = {}
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            rel = f.relative_to(root).as_posix()
            if rel.startswith("physics/effects/"):
                continue
            tree = ast.parse(f.read_text(encoding="utf-8"))
            doc = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)}
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in doc:
                    found = set(pattern.findall(node.value)) | ({node.value} & words)
                    if found:
                        out.setdefault(rel, set()).update(found)
    return out


def test_no_effect_is_named_outside_physics_effects():
    found = effect_literals()
    allowed = {f: DX_ALLOWLIST.get(f, set()) | DATA.get(f, (set(),))[0] for f in set(DX_ALLOWLIST) | set(DATA)}
    new = {f: sorted(lits - allowed.get(f, set())) for f, lits in found.items() if lits - allowed.get(f, set())}
    assert not new, ("effect ids / effect-owned parameters named outside physics/effects/ (give the effect a hook, "
                     f"or make it data): {new}")
    stale = {f: sorted(lits - found.get(f, set())) for f, lits in DX_ALLOWLIST.items() if lits - found.get(f, set())}
    assert not stale, f"no longer named: remove them from DX_ALLOWLIST (it only shrinks): {stale}"


def test_the_effect_rule_can_fail(tmp_path):
    pkg = tmp_path / "physics"
    (pkg / "effects").mkdir(parents=True)
    (pkg / "effects" / "mine.py").write_text("ID = 'nonlinear_charge'\n")            # inside: allowed
    (pkg / "solver.py").write_text(
        '"""Docstrings may say nonlinear_charge."""\n'
        "# and comments: electrode_resistance\n"
        "def f(model, p):\n"
        "    if 'thermal' in model.effect_ids:\n"                                      # a plain word, whole literal
        "        return p['C_max']\n"                                                   # an effect's parameter
        "    raise ValueError(f'{p} needs solvent_diffusion')\n"                       # inside a message
        "NOTE = 'relative humidity and thermal drift'\n")                              # English: not flagged
    assert effect_literals(tmp_path, ("physics",)) == {"physics/solver.py": {"thermal", "C_max", "solvent_diffusion"}}


# ------------------------------------------------------------------ the layers (issue 37)

#: Rooms of the code base, by module prefix (the longest prefix wins).  Floors, from the ground
#: up: ``ground`` (errors, constants, limits, version) → ``io`` (files, records, units, the
#: output policy), ``analysis`` (signal analysis of records), ``execution`` (workers, threads, progress,
#: user code) → ``core`` (device, parameters, signals, effects, model, solvers) → ``tasks``
#: (compare, identify, diagnose, the reference solver, the effect contract) with ``pages``
#: (presentation) beside them → ``testbeds`` → ``library`` (``nnmodel`` networks, datasets,
#: training) → ``app`` (``nnmodel.app``: the command line and its commands).
ROOMS = {
    "physics": "init", "physics._version": "ground", "physics.errors": "ground",
    "physics.constants": "ground", "physics.limits": "ground",
    "physics.io": "io", "physics.analysis": "analysis", "physics.execution": "execution",
    "physics.device": "core", "physics.parameters": "core", "physics.signals": "core",
    "physics.effects": "core", "physics.model": "core", "physics.solvers": "core",
    "physics.compare": "tasks", "physics.identify": "tasks", "physics.diagnose": "tasks",
    "physics.reference": "tasks", "physics.contract": "tasks",
    "physics.pages": "pages", "physics.testbeds": "testbeds",
    "nnmodel": "library", "nnmodel.app": "app",
}
_BELOW_CORE = {"ground", "io", "analysis", "execution"}
#: Which rooms each room may import (itself included).
ALLOWED = {
    "init": {"init", "ground"},
    "ground": {"ground"},
    "io": {"ground", "io"},
    "analysis": {"ground", "io", "analysis"},
    "execution": {"ground", "execution"},
    "pages": {"ground", "io", "pages"},
    "core": _BELOW_CORE | {"core"},
    "tasks": _BELOW_CORE | {"core", "tasks", "pages"},
    "testbeds": _BELOW_CORE | {"core", "tasks", "pages", "testbeds"},
    "library": _BELOW_CORE | {"init", "core", "tasks", "pages", "library"},
    "app": set(ROOMS.values()),
}
#: Inside ``tasks`` only the page writers import ``pages``: the computations return results,
#: the writers draw them.
PAGE_WRITERS = {"report", "validate"}


def room_of(module: str, rooms=ROOMS) -> str:
    parts = module.split(".")
    for i in range(len(parts), 0, -1):
        if ".".join(parts[:i]) in rooms:
            return rooms[".".join(parts[:i])]
    raise KeyError(f"{module}: in no room of ROOMS (add it)")


def layer_violations(root: Path = ROOT, packages=("physics", "nnmodel"), rooms=ROOMS, allowed=ALLOWED) -> list[str]:
    """Every import (module level or inside a function) that goes to a room its room may not import."""
    from bench.structure import imports_of, module_files
    files = module_files(packages, root)
    out = []
    for m, f in files.items():
        a = room_of(m, rooms)
        for t in sorted(imports_of(m, f, set(files), False)):
            b = room_of(t, rooms)
            if b not in allowed[a]:
                out.append(f"{m} ({a}) imports {t} ({b})")
            elif a == "tasks" and b == "pages" and m.rsplit(".", 1)[-1] not in PAGE_WRITERS:
                out.append(f"{m} (tasks, not a page writer) imports {t} (pages)")
    return out


def test_each_layer_imports_only_the_layers_it_may():
    assert layer_violations() == []


def test_the_layer_rule_can_fail(tmp_path):
    for d in ("physics/io", "physics/solvers", "physics/compare"):
        (tmp_path / d).mkdir(parents=True)
        (tmp_path / d / "__init__.py").write_text("")
    (tmp_path / "physics" / "__init__.py").write_text("")
    (tmp_path / "physics" / "io" / "csv.py").write_text("def f():\n    from ..solvers import run\n")   # io -> core
    (tmp_path / "physics" / "solvers" / "run.py").write_text("from ..io import csv\n")               # allowed
    (tmp_path / "physics" / "compare" / "fit.py").write_text("import nnmodel.app\n")                 # physics -> app
    rooms = {"physics": "init", "physics.io": "io", "physics.solvers": "core", "physics.compare": "tasks",
             "nnmodel": "library", "nnmodel.app": "app"}
    (tmp_path / "nnmodel" / "app").mkdir(parents=True)
    (tmp_path / "nnmodel" / "__init__.py").write_text("")
    (tmp_path / "nnmodel" / "app" / "__init__.py").write_text("")
    found = layer_violations(tmp_path, rooms=rooms)
    assert found == ["physics.compare.fit (tasks) imports nnmodel.app (app)",
                     "physics.io.csv (io) imports physics.solvers.run (core)"]


def test_no_import_cycle_and_a_small_physics_root():
    from bench.structure import cycles, imports_of, module_files
    files = module_files(("physics", "nnmodel"), ROOT)
    graph = {m: imports_of(m, f, set(files), False) for m, f in files.items()}
    assert cycles(graph) == []
    root_modules = sorted(p.name for p in (ROOT / "physics").glob("*.py"))
    assert len(root_modules) <= 10, root_modules


def test_import_physics_and_nnmodel_pull_in_no_heavy_package():
    import subprocess
    import sys
    code = ("import sys, physics, physics.errors, nnmodel, nnmodel.app.cli; "
            "print(sorted(m for m in ('torch', 'matplotlib', 'dask', 'scipy', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_a_command_is_one_module_declaring_its_inputs():
    """Every command module declares the options naming files it reads (``INPUTS``): each is an
    option of its parser, and the command line protects exactly those (no list to edit elsewhere)."""
    from nnmodel.app import cli
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, __import__("argparse")._SubParsersAction))
    for mod in cli._command_modules():
        p = sub.choices[mod.NAME]
        dests = {a.dest for a in p._actions}
        assert set(mod.INPUTS) <= dests, (mod.NAME, set(mod.INPUTS) - dests)
        declared = p.get_default("_inputs")
        assert set(declared) == set(mod.INPUTS) | ({"effects_path"} & dests), mod.NAME
