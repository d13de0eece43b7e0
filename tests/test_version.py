"""One version, in physics/_version.py: the package metadata reads it, `eap --version` prints it,
and the changelog has a section for it."""
import subprocess
import sys
from pathlib import Path

import pytest

import nnmodel
import physics

ROOT = Path(__file__).resolve().parents[1]


def test_the_version_has_one_source():
    tomllib = pytest.importorskip("tomllib")       # Python 3.11+
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" not in meta["project"] and "version" in meta["project"]["dynamic"]
    assert meta["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "physics._version.__version__"}
    assert nnmodel.__version__ == physics.__version__


def test_eap_version_prints_it():
    out = subprocess.run([sys.executable, "-m", "nnmodel.app.cli", "--version"], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == f"eap-model {physics.__version__}"


def test_the_changelog_covers_this_version():
    assert f"\n## {physics.__version__}\n" in (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
