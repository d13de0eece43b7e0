"""What the tutorial scripts share: the repository root as the working folder, an output
folder per tutorial, ``eap`` run in this process exactly as the shell runs it, and checks
that stop the script when a claim of the tutorial does not hold."""
from __future__ import annotations

import json
import os
import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
os.chdir(ROOT)      # the commands read as you would type them in the repository root


def out(name: str) -> Path:
    """The tutorial's output folder, ``runs/tutorials/NAME`` (never committed)."""
    return Path("runs") / "tutorials" / name


def eap(*args) -> None:
    """Run ``eap ARGS`` (what typing it in a shell does) and stop if it fails."""
    from nnmodel.app.cli import main
    argv = [str(a) for a in args]
    print("\n$ eap " + shlex.join(argv), flush=True)
    rc = main(argv)
    sys.stdout.flush()
    sys.stderr.flush()
    if rc != 0:
        raise SystemExit(f"eap {argv[0]} exited with status {rc}")


def check(condition: bool, claim: str) -> None:
    """A claim of the tutorial, checked on what was just computed: printed when it holds,
    the script stops (exit status 1) when it does not."""
    if not condition:
        raise SystemExit(f"CHECK FAILED: {claim}")
    print(f"check: {claim}", flush=True)


def read_json(path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))
