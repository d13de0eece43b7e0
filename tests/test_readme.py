"""The README is a front page: its first code block is the two commands CI runs, its Python
example prints what it shows, and it stays short."""
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"^```(\w*)\n(.*?)^```", README, flags=re.S | re.M)


def test_the_first_block_is_the_two_commands_and_ci_runs_the_second():
    lang, body = BLOCKS[0]
    lines = body.strip().splitlines()
    assert lines == ['pip install -c constraints.txt -e ".[test]" && eap run --out runs/quickstart',
                     "python -m pytest -q"]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert lines[1] in [line.strip() for line in ci], ".ci/run must run the README's test command"


def test_the_readme_is_a_front_page():
    assert len(README.splitlines()) <= 150


def test_the_python_example_prints_what_the_readme_shows(tmp_path):
    code = next(body for lang, body in BLOCKS if lang == "python")
    shown = next(body for lang, body in BLOCKS if lang == "text")
    assert len(code.strip().splitlines()) <= 10
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == shown.split()


def test_the_readme_states_the_pooled_calibration_of_the_labels():
    """The front page's figures for what the labels have meant are the pooled calibration table's
    (:func:`physics.diagnose.confidence.calibration_pooled`): a new draw there must update them here."""
    from physics.diagnose.confidence import calibration_pooled
    pool = calibration_pooled()
    text = " ".join(README.split())
    assert f"the {pool['draws']} draws of the calibration table ({pool['cases']} strips" in text
    for lab, x in pool["labels"].items():
        assert f"\"{lab}\" {x['n']} picks" in text
    high, medium, low = (pool["labels"][lab] for lab in ("high", "medium", "low"))
    wrong = "none wrong" if not high["wrong"] else f"{high['wrong']} wrong"
    assert f"{wrong} ({high['right']} right, {high['acceptable']} a near twin's relative)" in text
    for x in (medium, low):
        assert f"{x['n']} picks, {round(100 * (x['right'] + x['acceptable']) / x['n'])} %" in text
