"""The Examples sections of the public API's docstrings run and print what they show.

The names are those of the API reference, ``docs/public_api.py``: a name added there has its
examples run here.  Examples run in a scratch folder holding ``examples/`` (the creep effect
file) and a small network bundle at ``runs/train/models/ff``, so that they read as a user in a
clone would type them."""
import doctest
import importlib
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
from public_api import PAGES  # noqa: E402


def _object(name: str):
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def _doctests():
    finder = doctest.DocTestFinder(recurse=True)
    out = {}
    for _, _, names in PAGES.values():
        for name in names:
            obj = _object(name)
            if not callable(obj):
                continue
            for test in finder.find(obj, name):
                if test.examples:
                    out[test.name] = test
    return out


DOCTESTS = _doctests()


def test_the_public_api_has_examples():
    """Every function and class of the reference shows how it is called."""
    documented = {n for _, _, names in PAGES.values() for n in names if callable(_object(n))}
    without = sorted(n for n in documented if not any(t == n or t.startswith(n + ".") for t in DOCTESTS))
    assert not without, f"no Examples section: {without}"


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """A folder like a clone's root: examples/ and a small trained bundle in runs/train/models/ff."""
    from nnmodel.bundle import save
    from nnmodel.models.check import _records
    from nnmodel.recipes import make_model
    d = tmp_path_factory.mktemp("examples")
    shutil.copytree(ROOT / "examples", d / "examples")
    recs = _records(300)
    model = make_model("ff", {"max_epochs": 1, "hidden": 4, "nb": 5, "memory_filters": 2, "structures": None,
                              "progress_bar": False})
    model.fit(recs, recs[1:])
    save(model, d / "runs" / "train" / "models" / "ff")
    return d


@pytest.mark.parametrize("name", sorted(DOCTESTS))
def test_docstring_example(name, scratch, monkeypatch, capsys):
    monkeypatch.chdir(scratch)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    result = runner.run(DOCTESTS[name], out=sys.stdout.write)
    assert result.failed == 0, capsys.readouterr().out
