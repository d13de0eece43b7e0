"""Hostile-input audit: runs a long list of careful-user and attacker cases through the
`eap` command line and prints, per case, whether the package held, and the totals
(tried / held / failed / tracebacks).

A case *holds* when the command ends as it should — a refusal is exit 2 with one line
``eap CMD: error: …`` (matching the case's expected words where given), an accepted input is
exit 0, an interrupt is 130/143 with one line (after any warnings) — with no traceback, within the time limit, and
every file that existed before is byte-identical afterwards (outputs the case may write
excepted); a refusal creates nothing.

    python bench/hostile_audit.py                        # this tree
    python bench/hostile_audit.py --tree /work/wt/base   # another checkout (e.g. the base commit)
    python bench/hostile_audit.py --only dataset --verbose

Every case runs in a fresh process (``python -m nnmodel.app.cli …``) in its own folder, with an
address-space cap (``--cap-GB``), a timeout (``--timeout``, a hang counts as a failure) and a
cap on the processes it may start (:data:`MAX_PROCS`, more is unbounded work: stopped, a hang).
A case may run on a nearly full disk (a 16 kB tmpfs in a private mount namespace, ``unshare``:
ENOSPC), under a file-size limit (RLIMIT_FSIZE: EFBIG) or without root's power over file
permissions (``setpriv``: EACCES as root); where the machine lacks the tool the case is skipped.

A failure is counted in one class, the first that applies: **data loss** (a file that existed
is changed or gone), **traceback**, **hang** (past the timeout or the process cap), **silent
acceptance** (exit 0 where a refusal or a note was due), **other** (a wrong exit code or
message).  Round-three cases (issue 38) also require exactly one error line and no path of
eap's temporary folders (``.eap-tmp-``) in what the command prints.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

HERE = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------- fixtures

def _record(path: Path, n: int = 1000, fs: float = 100.0, header=("time_s", "voltage_V", "deflection_m", "rh_pct"),
            y_scale: float = 1e-4, rh: float | None = 60.0, sep: str = ",", decimal: str = ".", y_offset=0.0,
            encoding="utf-8", const: str | None = None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    v = np.sin(2 * np.pi * 1.3 * t) + 0.3 * rng.standard_normal(n)
    from scipy.signal import lfilter
    y = lfilter([0.05], [1, -0.95], v) * y_scale + y_offset
    if const == "voltage":
        v = np.full(n, 0.5)
    if const == "deflection":
        y = np.full(n, 1e-4)
    cols = [t, v, y] + ([np.full(n, rh)] if rh is not None and len(header) > 3 else [])
    lines = [sep.join(header)]
    for row in zip(*cols):
        lines.append(sep.join(repr(float(x)).replace(".", decimal) for x in row))
    path.write_bytes(("\n".join(lines) + "\n").encode(encoding))
    return path


def _linear_record(path: Path, n: int = 2000, fs: float = 100.0) -> Path:
    """A noise-free linear plant (a first-order filter of white noise): a linear model fits it exactly."""
    from scipy.signal import lfilter
    t = np.arange(n) / fs
    v = np.random.default_rng(1).standard_normal(n)
    y = lfilter([0.05], [1, -0.9], v) * 1e-4
    path.write_text("time_s,voltage_V,deflection_m,rh_pct\n" + "".join(
        f"{float(a)!r},{float(b)!r},{float(c)!r},60\n" for a, b, c in zip(t, v, y)))
    return path


def _deep_yaml(depth=3000) -> str:
    return "a: " + "[" * depth + "]" * depth + "\n"


def _deep_json(depth=3000) -> str:
    return '{"a": ' + "[" * depth + "]" * depth + "}"


TINY = """device: ip2c_pedot_water
fs_Hz: 100.0
duration_s: 3.0
train_rh_pct: [60]
heldout_rh_pct: []
excitations: [noise]
f_max_Hz: 20.0
fade_in_s: 0.2
validation_per_rh: 1
test_per_train_rh: 1
test_per_heldout_rh: 0
varying_rh: {train: 0, test: 0, range_pct: [40, 100]}
measurement_like: {effects: [], count: 0, rh_pct: [60]}
"""

CREEP = (HERE / "examples" / "effects" / "creep.py")

EFFECT_TEMPLATE = '''from physics.effects import OutputEffect
from physics.parameters import ParamSpec

class Broken(OutputEffect):
    id = "broken"
    summary = "a broken user effect"
    params = (ParamSpec("broken_k", "1", -1e9, 1e9, "gain", optional=True, default=1.0),)

    def output_tf(self, p):
{body}
'''

EFFECT_BODIES = {
    "nan_gain": "        return [float('nan')], [1.0]",
    "zero_den": "        return [1.0], [0.0]",
    "bad_return": "        return 'not a transfer function'",
    "raises": "        raise ZeroDivisionError('boom')",
    "rhp_pole": "        return [1.0], [1.0, -5.0]",
    "inf_gain": "        return [float('inf')], [1.0]",
    "huge_gain": "        return [1e300], [1.0]",
    "empty": "        return [], []",
    "improper": "        return [1.0, 0.0, 0.0], [1.0]",
}


ROUND3_EFFECTS = {
    "osexit_import": "import os\nos._exit(0)\n",
    "loop_import": "while True:\n    pass\n",
    "loop_hook": EFFECT_TEMPLATE.format(body="        while True:\n            pass"),
    "sysexit_hook": EFFECT_TEMPLATE.format(body="        import sys\n        sys.exit(0)"),
    "osexit_hook": EFFECT_TEMPLATE.format(body="        import os\n        os._exit(0)"),
    "order5000": EFFECT_TEMPLATE.format(body="        return [1.0], [1.0] + [0.0] * 4999 + [1.0]"),   # s^5000 + 1
}


def build_fixtures(fx: Path, tree: Path, env: dict) -> None:
    """Records, a tiny generated dataset, a trained bundle, effect files and a device copy."""
    fx.mkdir(parents=True, exist_ok=True)
    _record(fx / "rec.csv")
    _record(fx / "rec2.csv", n=1200)
    _record(fx / "rec_norh.csv", header=("time_s", "voltage_V", "deflection_m"), rh=None)
    _record(fx / "long.csv", n=3000)
    # a lab plant whose output is a level read as 0-10 V
    _record(fx / "lab.csv", header=("t", "u", "y"), rh=None, y_scale=2.0, y_offset=5.0)
    # a lab export in mm with units in the header
    _record(fx / "tip.csv", header=("Time [s]", "Drive (V)", "Tip (mm)"), rh=None, y_scale=0.1)
    (fx / "tiny.yaml").write_text(TINY)
    # the default preset with records ten times longer: a run still going when a signal comes
    preset = (tree / "configs" / "datasets" / "default.yaml").read_text()
    if "duration_s: 40.0" not in preset:
        sys.exit("fixture: configs/datasets/default.yaml no longer says duration_s: 40.0; update slow.yaml")
    (fx / "slow.yaml").write_text(preset.replace("duration_s: 40.0", "duration_s: 400.0"))
    shutil.copy(tree / "configs" / "devices" / "ip2c_pedot_water.yaml", fx / "mydev.yaml")
    shutil.copy(CREEP, fx / "my_creep.py")
    for name, body in EFFECT_BODIES.items():
        (fx / f"eff_{name}.py").write_text(EFFECT_TEMPLATE.format(body=body))
    (fx / "eff_exit0.py").write_text("import sys\nsys.exit(0)\n")
    (fx / "eff_exit3.py").write_text("import sys\nsys.exit(3)\n")
    (fx / "eff_syntax.py").write_text("def (:\n")
    (fx / "eff_import.py").write_text("import not_a_module_xyz\n")
    (fx / "eff_none.py").write_text("x = 1\n")
    for name, body in ROUND3_EFFECTS.items():
        (fx / f"eff_{name}.py").write_text(body)
    _record(fx / "long20k.csv", n=20000)
    _linear_record(fx / "lin.csv")
    run = lambda *a: subprocess.run([sys.executable, "-m", "nnmodel.app.cli", *a], cwd=fx, env=env,  # noqa: E731
                                    capture_output=True, text=True)
    r = run("generate", "--config", "tiny.yaml", "--out", "G", "--quiet")
    if r.returncode:
        sys.exit(f"fixture: eap generate failed: {r.stderr[-500:]}")
    r = run("train-compare", "G", "--models", "ff", "--set", "ff.max_epochs=1", "--set", "ff.structures=null",
            "--out", "TC", "--quiet")
    if r.returncode:
        sys.exit(f"fixture: eap train-compare failed: {r.stderr[-500:]}")
    r = run("dataset", "--train", "rec.csv", "--test", "rec2.csv", "--out", "DS")
    if r.returncode:
        sys.exit(f"fixture: eap dataset failed: {r.stderr[-500:]}")
    r = run("dataset", "--train", "lin.csv[0:1500]", "--test", "lin.csv[1500:2000]", "--out", "DL")
    if r.returncode:
        sys.exit(f"fixture: eap dataset (noise-free linear) failed: {r.stderr[-500:]}")


# --------------------------------------------------------------------------- cases

@dataclass
class Case:
    name: str
    group: str
    argv: list[str]
    setup: Callable[[Path, Path], None] | None = None
    expect: str = "error"            # error (exit 2) | ok (exit 0) | int (signal: 130 / 143)
    match: str | None = None         # regex the error line must match
    may_change: tuple[str, ...] = () # paths (relative, glob) the case may write or change
    timeout: float | None = None
    env: dict = field(default_factory=dict)
    send: tuple[int, float] | None = None   # (signal, after seconds)
    check: Callable[[Path], str | None] | None = None  # extra check: returns a failure note or None
    disk_kB: int | None = None       # run with full/ a tmpfs of this size (disk full: ENOSPC)
    fsize: int | None = None         # RLIMIT_FSIZE in bytes (file too large: EFBIG)
    unprivileged: bool = False       # without root's power over permissions (EACCES)
    note: str | None = None          # regex a note/warning line must match
    stdout: str | None = None        # regex stdout must match
    strict: bool = False             # exactly one error line; no .eap-tmp- path printed


def cp(*names, into: str = "."):
    def setup(d: Path, fx: Path):
        for n in names:
            src = fx / n
            dst = d / into / Path(n).name
            dst.parent.mkdir(parents=True, exist_ok=True)
            if src.is_dir():
                shutil.copytree(src, dst, symlinks=True)
            else:
                shutil.copy(src, dst)
    return setup


def chain(*setups):
    def setup(d, fx):
        for s in setups:
            s(d, fx)
    return setup


def write(rel: str, text: str | bytes):
    def setup(d, fx):
        p = d / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    return setup


def run_eap(*argv):
    """A setup step that runs eap (e.g. to make a folder eap wrote)."""
    def setup(d, fx):
        r = subprocess.run([sys.executable, "-m", "nnmodel.app.cli", *argv], cwd=d, env=_ENV, capture_output=True,
                           text=True)
        if r.returncode:
            raise RuntimeError(f"setup `eap {' '.join(argv)}` failed: {r.stderr.strip()[-300:]}")
    return setup


def edit_json(rel: str, fn):
    def setup(d, fx):
        p = d / rel
        obj = json.loads(p.read_text())
        fn(obj)
        p.write_text(json.dumps(obj))
    return setup


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def resha(ds: str = "DS"):
    """Recompute the hashes in dataset.json after a change (an attacker's consistent edit)."""
    def setup(d, fx):
        mf = d / ds / "dataset.json"
        meta = json.loads(mf.read_text())
        for e in meta["files"]:
            p = (d / ds / e["path"])
            if p.is_file():
                e["sha256"] = _sha(p)
        mf.write_text(json.dumps(meta))
    return setup


SIM = ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone", "--duration-s", "2",
       "--fs-Hz", "100"]
FRF = ["frf", "--device", "ip2c_pedot_water", "--rh", "60", "--points", "50"]
CMP = ["compare", "rec.csv", "--model", "ip2c_pedot_water"]
IDN = ["identify", "rec.csv", "--device", "ipmc_pt_eg", "--free", "kf"]
PRED = ["predict", "--model", "TC/models/ff", "--input", "rec.csv"]
SWEEP = ["sweep", "--device", "ip2c_pedot_water", "--rh", "60", "--grid", "Y=1e8,2e8"]
GEN = ["generate", "--config", "tiny.yaml", "--quiet"]
TCQ = ["train-compare", "DS", "--models", "ff", "--set", "ff.max_epochs=1", "--set", "ff.structures=null", "--quiet"]
B = "TC/models/ff"


def cases() -> list[Case]:
    C: list[Case] = []
    add = lambda *a, **k: C.append(Case(*a, **k))  # noqa: E731

    # ---------------------------------------------------------------- ownership (--overwrite)
    owned_runs = {
        "simulate": (SIM + ["--out", "D"], cp()),
        "generate": (GEN + ["--out", "D"], cp("tiny.yaml")),
        "dataset": (["dataset", "--train", "rec.csv", "--test", "rec2.csv", "--out", "D"], cp("rec.csv", "rec2.csv")),
        "compare": (CMP + ["--out", "D"], cp("rec.csv")),
        "identify": (IDN + ["--out", "D"], cp("rec.csv")),
    }
    for cmd, (argv, base) in owned_runs.items():
        for extra, rel in (("notes", "D/notes.txt"), ("nested", "D/train/mine.txt")):
            add(f"overwrite-keeps-user-file-{extra}-{cmd}", "ownership", argv + ["--overwrite"],
                chain(base, run_eap(*argv), write(rel, "my notes\n")), match=r"mine\.txt|notes\.txt")
        add(f"overwrite-eap-folder-{cmd}", "ownership", argv + ["--overwrite"], chain(base, run_eap(*argv)),
            expect="ok", may_change=("D/**",))
        add(f"no-overwrite-existing-{cmd}", "ownership", argv, chain(base, run_eap(*argv)), match="--overwrite")
    add("overwrite-refuses-edited-eap-file", "ownership", SIM + ["--out", "D", "--overwrite"],
        chain(run_eap(*SIM, "--out", "D"), lambda d, fx: (d / "D" / "summary.json").write_text("{\"mine\": 1}\n")),
        match="summary.json")
    add("overwrite-user-folder", "ownership", SIM + ["--out", "U", "--overwrite"], write("U/thesis.tex", "x"),
        match="U")
    # inputs inside an eap folder that is the target
    add("input-device-inside-out", "ownership",
        ["simulate", "--device", "D/mydev.yaml", "--rh", "60", "--signal", "tone", "--duration-s", "2", "--fs-Hz",
         "100", "--out", "D", "--overwrite"], chain(run_eap(*SIM, "--out", "D"), cp("mydev.yaml", into="D")),
        match="mydev.yaml")
    add("input-config-inside-out", "ownership", ["generate", "--config", "D/tiny.yaml", "--quiet", "--out", "D",
                                                 "--overwrite"],
        chain(cp("tiny.yaml"), run_eap(*GEN, "--out", "D"), cp("tiny.yaml", into="D")), match="tiny.yaml")
    add("input-effect-inside-out", "ownership",
        SIM + ["--effects", "default,+creep", "--effects-path", "D/my_creep.py", "--out", "D", "--overwrite"],
        chain(run_eap(*SIM, "--out", "D"), cp("my_creep.py", into="D")), match="my_creep.py")
    add("input-record-inside-out", "ownership", ["compare", "D/rec.csv", "--model", "ip2c_pedot_water", "--out", "D",
                                                 "--overwrite"],
        chain(run_eap(*SIM, "--out", "D"), cp("rec.csv", into="D")), match="rec")
    add("input-dataset-is-out", "ownership", ["train-compare", "DS", "--models", "ff", "--set", "ff.max_epochs=1",
                                              "--out", "DS", "--overwrite", "--quiet"], cp("DS", "rec.csv"),
        match="DS")
    add("input-device-is-out-parent", "ownership", SIM[:1] + ["--device", "D/mydev.yaml"] + SIM[3:] +
        ["--out", "D/sub"], cp("mydev.yaml", into="D"), expect="ok", may_change=("D/sub/**", "D/.sub*"))
    add("input-bundle-is-out", "ownership", PRED + ["--out", f"{B}/card.csv"], cp("TC", "rec.csv"),
        match="inside")
    # dangerous targets
    for tgt in (".", "..", "/", "~"):
        add(f"dangerous-out-{tgt}", "ownership", SIM + ["--out", tgt, "--overwrite"], match="refusing")
    # ---------------------------------------------------------------- file outputs
    add("frf-json-existing-user-file", "file-output", FRF + ["--json", "f.json"], write("f.json", "{\"mine\": 1}"),
        match="f.json")
    add("frf-json-own-device", "file-output", ["frf", "--device", "mydev.yaml", "--rh", "60", "--json", "mydev.yaml"],
        cp("mydev.yaml"), match="mydev.yaml")
    add("frf-json-own-device-overwrite", "file-output", ["frf", "--device", "mydev.yaml", "--rh", "60", "--json",
                                                         "mydev.yaml", "--overwrite"], cp("mydev.yaml"),
        match="mydev.yaml")
    add("frf-json-effect-file", "file-output", FRF + ["--effects", "default,+creep", "--effects-path", "my_creep.py",
                                                      "--json", "my_creep.py"], cp("my_creep.py"), match="my_creep.py")
    add("frf-csv-existing", "file-output", FRF + ["--json", "f.json", "--csv", "rec.csv"], cp("rec.csv"),
        match="rec.csv")
    add("frf-csv-existing-overwrite", "file-output", FRF + ["--json", "f.json", "--csv", "rec.csv", "--overwrite"],
        cp("rec.csv"), match="rec.csv")
    add("frf-plot-existing", "file-output", FRF + ["--json", "f.json", "--plot", "pic.png"],
        write("pic.png", b"\x89PNG mine"), match="pic.png")
    add("frf-json-dot", "file-output", FRF + ["--json", "."], match="--json")
    add("frf-json-dir", "file-output", FRF + ["--json", "sub"], write("sub/x", "x"), match="--json")
    add("frf-json-proc", "file-output", FRF + ["--json", "/proc/self/x.json"], match="--json")
    add("frf-json-no-parent", "file-output", FRF + ["--json", "no/such/dir/f.json"], expect="ok",
        may_change=("no/**",))
    add("frf-json-rewrite-own", "file-output", FRF + ["--json", "f.json", "--overwrite"],
        run_eap(*FRF, "--json", "f.json"), expect="ok", may_change=("f.json", ".eap*"))
    add("frf-json-twice-no-overwrite", "file-output", FRF + ["--json", "f.json"], run_eap(*FRF, "--json", "f.json"),
        match="--overwrite")
    add("frf-csv-json-same", "file-output", FRF + ["--json", "f.csv", "--csv", "f.csv"], match="f.csv")
    add("predict-out-is-input", "file-output", PRED + ["--out", "rec.csv"], cp("TC", "rec.csv"), match="rec.csv")
    add("predict-out-is-input-overwrite", "file-output", PRED + ["--out", "rec.csv", "--overwrite"],
        cp("TC", "rec.csv"), match="rec.csv")
    add("predict-out-user-file-overwrite", "file-output", PRED + ["--out", "mine.csv", "--overwrite"],
        chain(cp("TC", "rec.csv"), write("mine.csv", "a,b\n1,2\n")), match="mine.csv")
    add("predict-out-proc", "file-output", PRED + ["--out", "/proc/self/x.csv"], cp("TC", "rec.csv"), match="--out")
    add("predict-out-dir", "file-output", PRED + ["--out", "d.csv"], chain(cp("TC", "rec.csv"), write("d.csv/x", "")),
        match="d.csv")
    add("predict-out-sidecar-user", "file-output", PRED + ["--out", "p.csv", "--overwrite"],
        chain(cp("TC", "rec.csv"), write("p.yaml", "my: notes\n")), match="p.yaml")
    add("predict-rewrite-own", "file-output", PRED + ["--out", "p.csv", "--overwrite"],
        chain(cp("TC", "rec.csv"), run_eap(*PRED, "--out", "p.csv")), expect="ok", may_change=("p.csv", "p.yaml",
                                                                                            ".eap*"))
    add("sweep-out-user-file-overwrite", "file-output", SWEEP + ["--out", "t.csv", "--overwrite"],
        write("t.csv", "mine\n"), match="t.csv")
    add("sweep-out-device", "file-output", ["sweep", "--device", "mydev.csv", "--rh", "60", "--grid", "Y=1e8,2e8",
                                            "--out", "mydev.csv"], write("mydev.csv", "x"), match="mydev.csv")
    add("sweep-rewrite-own", "file-output", SWEEP + ["--out", "t.csv", "--overwrite"],
        run_eap(*SWEEP, "--out", "t.csv"), expect="ok", may_change=("t.csv", ".eap*"))

    # ---------------------------------------------------------------- dataset: a closed world
    def entry0(fn):
        return edit_json("DS/dataset.json", lambda m: fn(m["files"][0]))
    def point_outside(rel):
        def setup(d, fx):
            _record(d / "outside" / "x.csv")
            mf = d / "DS" / "dataset.json"
            meta = json.loads(mf.read_text())
            meta["files"][0]["path"] = rel if not rel.startswith("ABS") else str(d / "outside" / "x.csv")
            meta["files"][0]["sha256"] = _sha(d / "outside" / "x.csv")
            mf.write_text(json.dumps(meta))
        return setup
    for label, rel in (("dotdot", "../outside/x.csv"), ("deep-dotdot", "train/../../outside/x.csv"),
                       ("absolute", "ABS")):
        add(f"dataset-path-{label}-check", "dataset", ["dataset", "--check", "DS"], chain(cp("DS"), point_outside(rel)),
            match="outside|inside")
        add(f"dataset-path-{label}-train", "dataset", TCQ + ["--out", "R"], chain(cp("DS"), point_outside(rel)),
            match="outside|inside")

    def passwd(d, fx):
        mf = d / "DS" / "dataset.json"
        meta = json.loads(mf.read_text())
        meta["files"][0]["path"] = "../../../../../../../../etc/passwd"
        meta["files"][0]["sha256"] = _sha(Path("/etc/passwd"))
        mf.write_text(json.dumps(meta))
    add("dataset-path-etc-passwd", "dataset", ["dataset", "--check", "DS"], chain(cp("DS"), passwd),
        match="inside|outside")

    def symlink_out(d, fx):
        _record(d / "outside" / "x.csv")
        p = d / "DS" / json.loads((d / "DS" / "dataset.json").read_text())["files"][0]["path"]
        p.unlink()
        p.symlink_to(d / "outside" / "x.csv")
    add("dataset-symlink-out", "dataset", ["dataset", "--check", "DS"], chain(cp("DS"), symlink_out, resha()),
        match="symbolic link|symlink|outside")

    def symlink_dir(d, fx):
        _record(d / "outside" / "x.csv")
        shutil.rmtree(d / "DS" / "train")
        (d / "DS" / "train").symlink_to(d / "outside")
        meta = json.loads((d / "DS" / "dataset.json").read_text())
        meta["files"][0]["path"] = "train/x.csv"
        (d / "DS" / "dataset.json").write_text(json.dumps(meta))
    add("dataset-symlink-dir-out", "dataset", ["dataset", "--check", "DS"], chain(cp("DS"), symlink_dir, resha()),
        match="symbolic link|symlink|outside")

    def edit_sidecar(d, fx):
        for side in (d / "G").rglob("*.yaml"):
            side.write_text(side.read_text().replace("noise_floor_m:", "noise_floor_m: 0.5\n  old_noise_floor_m:"))
            break
    add("dataset-sidecar-edited", "dataset", ["dataset", "--check", "G"], chain(cp("G"), edit_sidecar),
        match=r"\.yaml")
    add("dataset-sidecar-added", "dataset", ["dataset", "--check", "DS"],
        chain(cp("DS"), lambda d, fx: [(p.with_suffix(".yaml")).write_text("rh_pct: 10\n")
                                       for p in (d / "DS" / "train").glob("*.csv")]), match=r"\.yaml")
    add("dataset-duplicate-entry", "dataset", ["dataset", "--check", "DS"],
        chain(cp("DS"), edit_json("DS/dataset.json", lambda m: m["files"].append(dict(m["files"][0])))),
        match="twice|duplicate")
    add("dataset-duplicate-entry-train", "dataset", TCQ + ["--out", "R"],
        chain(cp("DS"), edit_json("DS/dataset.json", lambda m: m["files"].append(dict(m["files"][0])))),
        match="twice|duplicate")
    schema_faults = {
        "no-sha256": entry0(lambda e: e.pop("sha256")),
        "no-path": entry0(lambda e: e.pop("path")),
        "path-int": entry0(lambda e: e.update(path=5)),
        "sha-int": entry0(lambda e: e.update(sha256=5)),
        "split-bad": entry0(lambda e: e.update(split="training")),
        "entry-list": edit_json("DS/dataset.json", lambda m: m["files"].__setitem__(0, [1, 2])),
        "files-dict": edit_json("DS/dataset.json", lambda m: m.update(files={"a": 1})),
        "files-missing": edit_json("DS/dataset.json", lambda m: m.pop("files")),
        "files-empty": edit_json("DS/dataset.json", lambda m: m.update(files=[])),
        "fs-negative": edit_json("DS/dataset.json", lambda m: m.update(fs_Hz=-1)),
        "fs-string": edit_json("DS/dataset.json", lambda m: m.update(fs_Hz="fast")),
        "fs-missing": edit_json("DS/dataset.json", lambda m: m.pop("fs_Hz")),
        "fs-wrong": edit_json("DS/dataset.json", lambda m: m.update(fs_Hz=37.0)),
        "schema-wrong": edit_json("DS/dataset.json", lambda m: m.update(schema="eap-dataset/9")),
        "top-list": write("DS/dataset.json", "[1, 2, 3]"),
        "not-json": write("DS/dataset.json", "{not json"),
        "not-utf8": write("DS/dataset.json", b'{"schema": "\xff\xfe"}'),
        "deep-json": write("DS/dataset.json", _deep_json()),
        "huge-json": write("DS/dataset.json", '{"pad": "' + "x" * (40 << 20) + '"}'),
        "val-fraction": edit_json("DS/dataset.json", lambda m: m.update(val_fraction=5)),
        "rh-levels": edit_json("DS/dataset.json", lambda m: m.update(rh_levels="many")),
        "heldout-str": entry0(lambda e: e.update(heldout_rh="yes")),
        "samples-wrong": entry0(lambda e: e.update(samples=-3)),
        "extra-effects": entry0(lambda e: e.update(extra_effects=5)),
        "output-bad": edit_json("DS/dataset.json", lambda m: m.update(output=7)),
        "json-is-dir": lambda d, fx: ((d / "DS" / "dataset.json").unlink(), (d / "DS" / "dataset.json").mkdir()),
        "nan-json": write("DS/dataset.json", '{"schema": "eap-dataset/1", "fs_Hz": NaN, "files": []}'),
    }
    for label, fault in schema_faults.items():
        add(f"dataset-schema-{label}-check", "dataset", ["dataset", "--check", "DS"], chain(cp("DS"), fault),
            match="dataset.json")
    for label in ("no-sha256", "fs-negative", "entry-list", "files-dict", "path-int", "deep-json"):
        add(f"dataset-schema-{label}-train", "dataset", TCQ + ["--out", "R"], chain(cp("DS"), schema_faults[label]),
            match="dataset.json")
    # building: overlap, leaks, maps
    add("dataset-overlap-ranges", "dataset", ["dataset", "--train", "long.csv[0:1500]", "--test", "long.csv[1000:3000]",
                                              "--out", "D"], cp("long.csv"), match="overlap")
    add("dataset-identical-train-test", "dataset", ["dataset", "--train", "rec.csv", "--test", "rec.csv", "--out", "D"],
        cp("rec.csv"), match="overlap|same|twice")
    add("dataset-copy-train-test", "dataset", ["dataset", "--train", "rec.csv", "--test", "copy.csv", "--out", "D"],
        chain(cp("rec.csv"), lambda d, fx: shutil.copy(d / "rec.csv", d / "copy.csv")), match="overlap|same|identical")
    add("dataset-twice-in-train", "dataset", ["dataset", "--train", "rec.csv", "rec.csv", "--out", "D"], cp("rec.csv"),
        match="overlap|twice")
    add("dataset-overlap-allowed", "dataset", ["dataset", "--train", "long.csv[0:1500]", "--test",
                                               "long.csv[1000:3000]", "--allow-overlap", "--out", "D"],
        cp("long.csv"), expect="ok", may_change=("D/**",),
        check=lambda d: None if "overlap" in (d / "D" / "dataset.json").read_text() else "overlap not marked")
    add("dataset-adjacent-ok", "dataset", ["dataset", "--train", "long.csv[0:1500]", "--test", "long.csv[1500:3000]",
                                           "--out", "D"], cp("long.csv"), expect="ok", may_change=("D/**",))
    add("dataset-same-column-twice", "dataset", ["dataset", "--train", "lab.csv", "--columns",
                                                 "time=t,voltage=y,deflection=y", "--out", "D"], cp("lab.csv"),
        match="twice|same column|both")
    add("dataset-quantity-twice", "dataset", ["dataset", "--train", "lab.csv", "--columns",
                                              "voltage=u,voltage=y", "--out", "D"], cp("lab.csv"), match="twice")
    add("dataset-unknown-column", "dataset", ["dataset", "--train", "lab.csv", "--columns",
                                              "time=t,voltage=U,deflection=y", "--out", "D"], cp("lab.csv"),
        match="--columns")
    add("dataset-range-reversed", "dataset", ["dataset", "--train", "long.csv[2000:100]", "--out", "D"],
        cp("long.csv"), match="samples")
    add("dataset-range-junk", "dataset", ["dataset", "--train", "long.csv[a:b]", "--out", "D"], cp("long.csv"),
        match="long.csv")
    add("dataset-val-fraction-nan", "dataset", ["dataset", "--train", "rec.csv", "--val-fraction", "nan", "--out",
                                                "D"], cp("rec.csv"), match="--val-fraction")
    add("dataset-holdout-junk", "dataset", ["dataset", "--train", "rec.csv", "--holdout-rh", "fifty", "--out", "D"],
        cp("rec.csv"), match="--holdout-rh")
    add("dataset-out-inside-input-dir", "dataset", ["dataset", "--train", "data/rec.csv", "--out", "data"],
        cp("rec.csv", into="data"), match="input")
    # ---------------------------------------------------------------- issue 25: any output quantity, lab files
    add("lab-volts-as-metres-refused-at-import", "lab", ["dataset", "--train", "lab.csv", "--columns",
                                                         "time=t,voltage=u,deflection=y", "--out", "D"],
        cp("lab.csv"), match="--output|unit")
    add("lab-output-level-V", "lab", ["dataset", "--train", "lab.csv", "--columns", "time=t,voltage=u,deflection=y",
                                      "--output", "level:V", "--out", "D"], cp("lab.csv"), expect="ok",
        may_change=("D/**",))
    add("lab-map-unit-V", "lab", ["dataset", "--train", "lab.csv", "--columns", "time=t,voltage=u,deflection=y:V",
                                  "--out", "D"], cp("lab.csv"), expect="ok", may_change=("D/**",))
    add("lab-map-unit-mm", "lab", ["dataset", "--train", "tip.csv", "--columns",
                                   "time=Time [s],voltage=Drive (V),deflection=Tip (mm):mm", "--out", "D"],
        cp("tip.csv"), expect="ok", may_change=("D/**",), check=lambda d: _max_abs_defl(d / "D"))
    add("lab-header-unit-mm", "lab", ["dataset", "--train", "tip.csv", "--columns",
                                      "time=Time [s],voltage=Drive (V),deflection=Tip (mm)", "--out", "D"],
        cp("tip.csv"), expect="ok", may_change=("D/**",), check=lambda d: _max_abs_defl(d / "D"))
    add("lab-map-unit-conflict", "lab", ["dataset", "--train", "tip.csv", "--columns",
                                         "time=Time [s],voltage=Drive (V),deflection=Tip (mm):um", "--out", "D"],
        cp("tip.csv"), match="mm")
    add("lab-map-bad-unit", "lab", ["dataset", "--train", "lab.csv", "--columns",
                                    "time=t,voltage=u,deflection=y:furlong", "--out", "D"], cp("lab.csv"),
        match="furlong")
    add("predict-columns", "lab", ["predict", "--model", B, "--input", "lab.csv", "--columns", "time=t,voltage=u",
                                   "--rh", "60", "--out", "p.csv"], cp("TC", "lab.csv"), expect="ok",
        may_change=("p.csv", "p.yaml", ".eap*"))
    add("predict-no-columns-advice", "lab", ["predict", "--model", B, "--input", "lab.csv", "--rh", "60", "--out",
                                             "p.csv"], cp("TC", "lab.csv"), match="--columns")
    add("compare-unknown-column-names-flag", "lab", ["compare", "lab.csv", "--columns", "time=t,voltage=U,deflection=y",
                                                     "--rh", "60", "--model", "ip2c_pedot_water", "--out", "O"],
        cp("lab.csv"), match="--columns")
    add("sidecar-free-text-sensor", "lab", CMP + ["--out", "O"],
        chain(cp("rec.csv"), write("rec.yaml", "sensor: laser triangulation sensor, Keyence LK-G\n")), expect="ok",
        may_change=("O/**",))
    add("sidecar-common-spellings", "lab", CMP + ["--out", "O"],
        chain(cp("rec.csv"), write("rec.yaml", "sensor:\n  model: Keyence LK-G5001\n  bandwidth_Hz: 1000\n"
                                               "  noise_rms_um: 0.5\n")), expect="ok", may_change=("O/**",))
    add("sidecar-noise-reaches-dataset", "lab", ["dataset", "--train", "rec.csv", "--out", "D"],
        chain(cp("rec.csv"), write("rec.yaml", "sensor:\n  noise_rms_um: 0.5\n")), expect="ok", may_change=("D/**",),
        check=lambda d: None if json.loads((d / "D" / "dataset.json").read_text()).get("noise_floor_m")
        else "noise_floor_m is null")
    # ---------------------------------------------------------------- resources
    for cmd_argv, label in ((GEN + ["--out", "D"], "generate"), (SWEEP + ["--out", "t.csv"], "sweep")):
        for w, m in (("1000", "--workers"), ("0", "--workers"), ("-1", "--workers"), ("64", "--workers")):
            add(f"workers-{w}-{label}", "resources", cmd_argv + ["--workers", w], cp("tiny.yaml"), match=m,
                timeout=60)
    for addr, m in (("not a url", "--scheduler"), ("tcp://", "--scheduler"), ("tcp://host:99999", "--scheduler"),
                    ("http://example.com", "--scheduler"), ("tcp://127.0.0.1:1", "--scheduler"),
                    ("tcp://10.255.255.1:8786", "--scheduler"), ("SILENT", "--scheduler")):
        add(f"scheduler-{addr[:24]}", "resources", SWEEP + ["--out", "t.csv", "--scheduler", addr], match=m,
            timeout=90)
    add("scheduler-env-garbage", "resources", SWEEP + ["--out", "t.csv"], env={"EAP_SCHEDULER": "::garbage::"},
        match="EAP_SCHEDULER|scheduler", timeout=90)
    for n in ("1000000", "0", "-3", "100000"):
        add(f"frf-n-modes-{n}", "resources", FRF + ["--n-modes", n, "--json", "f.json"], match="--n-modes",
            timeout=60)
    add("simulate-n-modes-huge", "resources", SIM + ["--n-modes", "1000000", "--out", "D"], match="--n-modes",
        timeout=60)
    for pts in ("1000000000", "1", "-5"):
        add(f"frf-points-{pts}", "resources", ["frf", "--device", "ip2c_pedot_water", "--rh", "60", "--points", pts,
                                               "--json", "f.json"], match="--points", timeout=60)
    add("sweep-grid-huge", "resources", ["sweep", "--device", "ip2c_pedot_water", "--rh", "60", "--grid",
                                         "Y=log:1e7:1e9:1000000000", "--out", "t.csv"], match="grid", timeout=60)
    add("sweep-grid-product-huge", "resources", ["sweep", "--device", "ip2c_pedot_water", "--rh", "60", "--grid",
                                                 "Y=log:1e7:1e9:5000", "--grid", "rh=lin:40:100:5000", "--out",
                                                 "t.csv"], match="grid", timeout=60)
    for flag, val in (("--amplitude-V", "1e6"), ("--rms-V", "1e6"), ("--duration-s", "1e9"), ("--fs-Hz", "1e9"),
                      ("--fs-Hz", "1e300"), ("--fs-Hz", "1e-300"), ("--duration-s", "1e-9"),
                      ("--amplitude-V", "inf"), ("--frequency-Hz", "1e300")):
        sig = "multisine" if flag == "--rms-V" else "tone"
        argv = ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", sig, "--duration-s", "2",
                "--fs-Hz", "100", flag, val, "--out", "D"]
        add(f"simulate{flag}-{val}", "resources", argv, match=flag, timeout=60)
    for flag, val in (("--f-max-Hz", "1e300"), ("--f-min-Hz", "1e-300"), ("--f-max-Hz", "inf"), ("--rh", "1e300"),
                      ("--rh", "nan")):
        add(f"frf{flag}-{val}", "resources", FRF + [flag, val, "--json", "f.json"], match=flag, timeout=60)
    for p in ("L_total=1e300m", "width=0mm", "Y=-5GPa", "L_total=nan", "kf=1e308"):
        add(f"param-{p}", "resources", FRF + ["--param", p, "--json", "f.json"], match="--param|" + p.split("=")[0],
            timeout=60)
    for where, setup, argv in (
            ("sidecar", chain(cp("rec.csv"), write("rec.yaml", _deep_yaml())), CMP + ["--out", "O"]),
            ("device", write("deep.yaml", _deep_yaml()), ["frf", "--device", "deep.yaml", "--rh", "60", "--json",
                                                          "f.json"]),
            ("config", write("deep.yaml", _deep_yaml()), ["generate", "--config", "deep.yaml", "--out", "D"]),
            ("set", cp("DS"), TCQ + ["--set", "ff.hidden=" + "[" * 3000 + "]" * 3000, "--out", "R"]),
            ("card", cp("TC", "rec.csv"), PRED + ["--out", "p.csv"]),
            ("dataset", chain(cp("DS"), write("DS/dataset.json", _deep_json())), ["dataset", "--check", "DS"])):
        if where == "card":
            setup = chain(setup, write(f"{B}/card.json", _deep_json()))
        add(f"deep-nesting-{where}", "resources", argv, setup, match="nest|deep|depth", timeout=60)
    for key, val in (("layers", 100000000), ("hidden", 100000000), ("nb", 100000000), ("memory_filters", 100000000)):
        add(f"card-{key}-huge", "resources", PRED + ["--out", "p.csv"],
            chain(cp("TC", "rec.csv"), edit_json(f"{B}/card.json", lambda c, k=key, v=val:
                                                 c["hyper_parameters"].update({k: v}))), match=key, timeout=60)
    add("csv-million-columns", "resources", CMP + ["--out", "O"],
        write("rec.csv", ",".join(f"c{i}" for i in range(300000)) + "\n" + ",".join("1" for _ in range(300000))),
        match="column", timeout=60)
    add("csv-one-huge-line", "resources", CMP + ["--out", "O"], write("rec.csv", "time_s," + "9" * (50 << 20)),
        timeout=60)
    # ---------------------------------------------------------------- tracebacks and non-finite results
    add("csv-step-1e288", "numerics", CMP + ["--out", "O"],
        write("rec.csv", "time_s,voltage_V,deflection_m,rh_pct\n" + "".join(
            f"{i * 1e288!r},{np.sin(i / 5):.6f},{1e-4 * np.sin(i / 5 - .2):.6e},60\n" for i in range(400))),
        match="rec.csv|time|step|sampling")
    add("csv-step-1e-302", "numerics", CMP + ["--out", "O"],
        write("rec.csv", "time_s,voltage_V,deflection_m,rh_pct\n" + "".join(
            f"{i * 1e-302!r},{np.sin(i / 5):.6f},{1e-4 * np.sin(i / 5 - .2):.6e},60\n" for i in range(400))),
        match="rec.csv|time|step|sampling")
    for fs in ("1e-300", "1e300"):
        add(f"compare-fs-{fs}", "numerics", ["compare", "u.csv", "--fs-Hz", fs, "--rh", "60", "--model",
                                             "ip2c_pedot_water", "--out", "O"],
            write("u.csv", "voltage_V,deflection_m\n" + "".join(f"{np.sin(i / 5):.6f},{1e-4 * np.sin(i / 5):.6e}\n"
                                                                for i in range(400))), match="--fs-Hz|sampling")
    for name in EFFECT_BODIES:
        for cmd, argv in (("frf", FRF + ["--json", "f.json"]), ("simulate", SIM + ["--out", "D"])):
            add(f"effect-{name}-{cmd}", "effects", argv + ["--effects", "default,+broken", "--effects-path",
                                                           f"eff_{name}.py"], cp(f"eff_{name}.py"),
                match=f"eff_{name}.py|broken", timeout=60)
    for name in ("exit0", "exit3", "syntax", "import", "none"):
        add(f"effect-file-{name}", "effects", FRF + ["--json", "f.json", "--effects-path", f"eff_{name}.py"],
            cp(f"eff_{name}.py"), match=f"eff_{name}.py")
    add("effect-path-dir", "effects", FRF + ["--json", "f.json", "--effects-path", "."], match="--effects-path")
    add("effect-rhp-compare", "effects", CMP + ["--effects", "default,+broken", "--effects-path", "eff_rhp_pole.py",
                                                "--out", "O"], cp("rec.csv", "eff_rhp_pole.py"), match="eff_rhp_pole")

    def frf_file(d, fx):
        f = np.logspace(-1, 1, 30)
        rows = "".join(f"{x!r},{1e297!r},-10.0\n" for x in f)
        (d / "h.csv").write_text("freq_Hz,mag_m_per_V,phase_deg\n" + rows)
    add("frf-file-1e297", "numerics", ["compare", "h.csv", "--model", "ip2c_pedot_water", "--rh", "60", "--out", "O"],
        frf_file, match="h.csv")
    # ---------------------------------------------------------------- readers
    add("csv-latin1-after-64k", "readers", CMP + ["--out", "O"],
        lambda d, fx: (_record(d / "rec.csv", n=4000), d.joinpath("rec.csv").write_bytes(
            d.joinpath("rec.csv").read_bytes() + b"1.0,0.1,1e-5,60 \xe9\n")), match="rec.csv")
    add("csv-binary-after-64k", "readers", CMP + ["--out", "O"],
        lambda d, fx: (_record(d / "rec.csv", n=4000), d.joinpath("rec.csv").write_bytes(
            d.joinpath("rec.csv").read_bytes() + b"\x00\x01\x02\n")), match="rec.csv")
    add("csv-utf16", "readers", CMP + ["--out", "O"], lambda d, fx: _record(d / "rec.csv", encoding="utf-16"),
        match="rec.csv")
    add("csv-constant-deflection", "readers", CMP + ["--out", "O"],
        lambda d, fx: _record(d / "rec.csv", const="deflection"), match="rec.csv")
    add("csv-constant-voltage", "readers", IDN + ["--out", "O"], lambda d, fx: _record(d / "rec.csv", const="voltage"),
        match="rec.csv")
    add("dataset-constant-deflection", "readers", ["dataset", "--train", "rec.csv", "--out", "D"],
        lambda d, fx: _record(d / "rec.csv", const="deflection"), match="rec.csv")
    add("csv-comma-sep-decimal-comma", "readers", CMP + ["--out", "O"],
        write("rec.csv", "time_s,voltage_V,deflection_m,rh_pct\n" + "".join(
            f"0,{i},0,5,0,0001,60\n" for i in range(50))), match="decimal comma|separator")
    for dialect, kw in (("semicolon-decimal-comma", dict(sep=";", decimal=",")), ("tab", dict(sep="\t")),
                        ("latin1", dict(encoding="latin-1"))):
        add(f"csv-dialect-{dialect}", "readers", CMP + ["--out", "O"], lambda d, fx, kw=kw: _record(d / "rec.csv", **kw),
            expect="ok", may_change=("O/**",))
    add("sidecar-kind-own-word", "readers", CMP + ["--out", "O"],
        chain(cp("rec.csv"), write("rec.yaml", "excitation: {kind: chirp}\n")), expect="ok", may_change=("O/**",))
    for label, text in (("kind-5", "excitation: {kind: 5}\n"), ("kind-list", "excitation: {kind: [a, b]}\n"),
                        ("dup-keys", "rh_pct: 60\nrh_pct: 20\n"), ("python-tag", "x: !!python/object/apply:os.system [ls]\n"),
                        ("sensor-list", "sensor: [1, 2]\n"), ("rh-string", "rh_pct: wet\n"),
                        ("signal-negative", "signal: {kind: sweep, f_start_Hz: -1}\n"),
                        ("sensor-noise-negative", "sensor: {noise_rms_um: -2}\n"),
                        ("sensor-bandwidth-str", "sensor: {bandwidth_Hz: fast}\n")):
        add(f"sidecar-{label}", "readers", CMP + ["--out", "O"], chain(cp("rec.csv"), write("rec.yaml", text)),
            match="rec.yaml")
    add("device-dup-keys", "readers", ["frf", "--device", "dev.yaml", "--rh", "60", "--json", "f.json"],
        lambda d, fx: (d / "dev.yaml").write_text((fx / "mydev.yaml").read_text() + "\nname: other\nname: again\n"),
        match="dev.yaml")
    add("config-dup-keys", "readers", ["generate", "--config", "c.yaml", "--out", "D"],
        write("c.yaml", TINY + "seed: 1\nseed: 2\n"), match="c.yaml")
    add("config-python-tag", "readers", ["generate", "--config", "c.yaml", "--out", "D"],
        write("c.yaml", "seed: !!python/object/apply:os.system [ls]\n"), match="c.yaml")
    add("device-alias-bomb", "readers", ["frf", "--device", "dev.yaml", "--rh", "60", "--json", "f.json"],
        write("dev.yaml", "a: &a [x,x,x,x,x,x,x,x,x]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n"), match="dev.yaml")
    add("bundle-pickle", "readers", PRED + ["--out", "p.csv"],
        chain(cp("TC", "rec.csv"), lambda d, fx: _pickle_bomb(d / B / "weights.pt")), match="weights")
    add("predict-nan-input", "readers", PRED + ["--out", "p.csv"],
        chain(cp("TC"), write("rec.csv", "time_s,voltage_V,rh_pct\n0,nan,60\n0.01,1,60\n0.02,1,60\n")),
        match="rec.csv")
    # ---------------------------------------------------------------- signals
    long_sim = ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "noise", "--duration-s", "3000",
                "--fs-Hz", "2000", "--out", "D"]
    add("sigterm-simulate", "signals", long_sim, expect=143, send=(signal.SIGTERM, 8.0), timeout=60)
    add("sigint-simulate", "signals", long_sim, expect=130, send=(signal.SIGINT, 8.0), timeout=60)
    add("sigterm-generate-workers", "signals", ["generate", "--config", "slow.yaml", "--workers", "2", "--quiet",
                                                "--out", "D"], cp("slow.yaml"), expect=143, send=(signal.SIGTERM, 12.0),
        timeout=60)
    add("sigint-sweep-workers", "signals", ["sweep", "--device", "ip2c_pedot_water", "--rh", "60", "--grid",
                                            "Y=log:1e7:1e9:20000", "--workers", "2", "--quiet", "--out", "t.csv"],
        expect=130, send=(signal.SIGINT, 10.0), timeout=60)
    train_long = ["train-compare", "DS", "--models", "lstm", "--set", "lstm.max_epochs=100000", "--set",
                  "lstm.patience=100000", "--quiet", "--out", "R"]
    add("sigint-train-compare", "signals", train_long, cp("DS"), expect=130, send=(signal.SIGINT, 15.0), timeout=90)
    for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        add(f"{sig.name.lower()}-train-compare-workers", "signals", train_long + ["--workers", "2"], cp("DS"),
            expect=code, send=(sig, 20.0), timeout=90)
    return C + round_three()


def _proof(folder: str, pid: int, pid_start=None):
    """A setup writing eap's proof of ownership into ``folder`` (naming the folder given)."""
    return write(f"{folder}/.eap-partial", json.dumps({"folder": Path(folder).name, "pid": pid, "pid_start": pid_start}))


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _chmod(rel: str, mode: int):
    def setup(d, fx):
        os.chmod(d / rel, mode)
    return setup


def _gone(rel: str):
    return lambda d: None if not (d / rel).exists() else f"{rel} was left behind"


def round_three() -> list[Case]:
    """Issue 38: names never escape, ownership by proof, OS errors one line, every count and size
    bounded, nothing accepted silently, effect files are code, messages name the user's files."""
    C: list[Case] = []

    def add(name, group, argv, setup=None, **kw):
        kw.setdefault("strict", True)
        C.append(Case(name, group, argv, setup, **kw))

    DIAG = ["diagnose", "rec.csv", "--device", "ipmc_pt_eg", "--free", "kf"]
    # ---------------------------------------------------------------- 1. names never escape
    add("name-absolute-identify", "names", IDN + ["--name", "@WORK@/mydevice", "--out", "runs/id"],
        chain(cp("rec.csv"), write("mydevice.yaml", "my device\n")), match="--name")
    add("name-dotdot-identify", "names", IDN + ["--name", "../victim", "--out", "runs/id"],
        chain(cp("rec.csv"), write("runs/victim.yaml", "mine\n")), match="--name")
    for label, name in (("empty", ""), ("hidden", ".eap-output"), ("slash", "a/b"), ("long", "n" * 300),
                        ("newline", "a\nb")):
        add(f"name-{label}-identify", "names", IDN + ["--name", name, "--out", "O"], cp("rec.csv"), match="--name")
    add("name-dotdot-diagnose-apply", "names", DIAG + ["--apply", "--name", "../x", "--out", "O"], cp("rec.csv"),
        match="--name")
    add("draft-effects-is-out-overwrite", "names", DIAG + ["--out", "O", "--draft-effects", "O", "--overwrite"],
        chain(cp("rec.csv"), run_eap(*SIM, "--out", "O")), match="--draft-effects", timeout=120)
    add("draft-effects-is-out", "names", DIAG + ["--out", "O", "--draft-effects", "O"], cp("rec.csv"),
        match="--draft-effects", timeout=120)
    add("draft-effects-inside-out", "names", DIAG + ["--out", "O", "--draft-effects", "O/drafts"], cp("rec.csv"),
        match="--draft-effects", timeout=120)
    add("out-inside-draft-effects", "names", DIAG + ["--out", "X/O", "--draft-effects", "X"], cp("rec.csv"),
        match="--draft-effects", timeout=120)
    add("record-name-hidden-file", "names", ["dataset", "--train", ".hidden.csv", "--out", "D"],
        lambda d, fx: shutil.copy(fx / "rec.csv", d / ".hidden.csv"), expect="ok", may_change=("D/**",),
        check=lambda d: None if (d / "D" / "train" / "hidden.csv").is_file() else "no train/hidden.csv")
    add("record-name-long", "names", ["dataset", "--train", "r" * 240 + ".csv", "--out", "D"],
        lambda d, fx: shutil.copy(fx / "rec.csv", d / ("r" * 240 + ".csv")), expect="ok", may_change=("D/**",))
    add("models-twice", "names", TCQ[:2] + ["--models", "ff,ff", "--out", "R"], cp("DS"), match="twice")

    # ---------------------------------------------------------------- 2. ownership by proof
    thesis = "my thesis\n"
    for label, argv, extra in (("frf", FRF + ["--json", "f.json"], cp()),
                               ("predict", PRED + ["--out", "p.csv"], cp("TC", "rec.csv")),
                               ("sweep", SWEEP + ["--out", "t.csv"], cp())):
        add(f"named-like-staging-{label}", "proof", argv,
            chain(extra, write(".eap-tmp-999999-notes/thesis.tex", thesis)), expect="ok",
            may_change=("f.json", "f.csv", "p.csv", "p.yaml", "t.csv", ".eap-files.json"),
            note=r"\.eap-tmp-999999-notes", strict=False)     # the note names the user's folder
    add("named-like-folder-tmp", "proof", SIM + ["--out", "D"],
        chain(write(".D.eap-tmp-999999/thesis.tex", thesis), write(".D.eap-tmp-999999/.eap-partial", "eap simulate")),
        expect="ok", may_change=("D/**",), note=r"\.D\.eap-tmp-999999", strict=False)
    add("named-like-folder-old", "proof", SIM + ["--out", "D"],
        chain(write(".D.eap-old-999999/thesis.tex", thesis), write(".D.eap-old-999999/.eap-output.json", "{}")),
        expect="ok", may_change=("D/**",), note=r"\.D\.eap-old-999999")
    add("proof-copied-from-another-folder", "proof", SIM + ["--out", "D"],
        lambda d, fx: (write(".D.eap-tmp-999998/thesis.tex", thesis)(d, fx),
                       write(".D.eap-tmp-999998/.eap-partial", json.dumps({"folder": ".D.eap-tmp-1", "pid": 999998}))(d, fx)),
        expect="ok", may_change=("D/**",), note=r"eap-tmp-999998", strict=False)
    add("proven-leftover-removed", "proof", SIM + ["--out", "D"],
        lambda d, fx: (lambda pid: (write(f".D.eap-tmp-{pid}/simulation.csv", "half\n")(d, fx),
                                    _proof(f".D.eap-tmp-{pid}", pid)(d, fx)))(_dead_pid()),
        expect="ok", may_change=("D/**", ".D.eap-tmp-*", ".D.eap-tmp-*/**"),
        check=lambda d: None if not list(d.glob(".D.eap-tmp-*")) else "the proven leftover was kept")
    add("lock-is-a-folder", "proof", SIM + ["--out", "D"], write(".D.eap-lock/mine.txt", "x"), match=r"\.D\.eap-lock")
    add("lock-is-a-users-file", "proof", SIM + ["--out", "D"], write(".D.eap-lock", "my notes\n"),
        match=r"\.D\.eap-lock")
    add("registry-is-a-folder", "proof", FRF + ["--json", "f.json"], write(".eap-files.json/mine.txt", "x"),
        match=r"\.eap-files\.json")
    add("registry-is-a-link", "proof", FRF + ["--json", "f.json"],
        lambda d, fx: (d / ".eap-files.json").symlink_to(d / "elsewhere.json"), match=r"\.eap-files\.json")
    add("json-is-also-csv-sidecar", "proof", FRF + ["--json", "f.yaml", "--csv", "f.csv"], match="sidecar")

    # ---------------------------------------------------------------- 3. every OS error one line
    full = dict(disk_kB=16, match=r"disk is full|No space")
    add("enospc-simulate", "oserror", ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone",
                                       "--duration-s", "20", "--fs-Hz", "100", "--out", "full/D"], **full)
    add("enospc-frf", "oserror", FRF[:-1] + ["500", "--json", "full/f.json"], **full)
    add("enospc-predict", "oserror", PRED + ["--out", "full/p.csv"], cp("TC", "rec.csv"), **full)
    add("enospc-compare", "oserror", CMP + ["--out", "full/O"], cp("rec.csv"), **full)
    add("enospc-dataset", "oserror", ["dataset", "--train", "rec.csv", "--out", "full/D"], cp("rec.csv"), **full)
    add("enospc-sweep", "oserror", ["sweep", "--device", "ip2c_pedot_water", "--rh", "60", "--grid",
                                    "Y=log:1e7:1e9:400", "--out", "full/t.csv"], **full)
    big = dict(fsize=20_000, match=r"file-size limit|too large")
    add("efbig-simulate", "oserror", ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone",
                                      "--duration-s", "20", "--fs-Hz", "100", "--out", "D"], **big)
    add("efbig-frf", "oserror", FRF[:-1] + ["500", "--json", "f.json"], **big)
    add("efbig-predict", "oserror", PRED + ["--out", "p.csv"], cp("TC", "rec.csv"), **big)
    add("eacces-record", "oserror", CMP + ["--out", "O"], chain(cp("rec.csv"), _chmod("rec.csv", 0)),
        unprivileged=True, match=r"rec\.csv")
    add("eacces-predict-input", "oserror", PRED + ["--out", "p.csv"], chain(cp("TC", "rec.csv"), _chmod("rec.csv", 0)),
        unprivileged=True, match=r"rec\.csv")
    add("eacces-device", "oserror", ["frf", "--device", "mydev.yaml", "--rh", "60", "--json", "f.json"],
        chain(cp("mydev.yaml"), _chmod("mydev.yaml", 0)), unprivileged=True, match=r"mydev\.yaml")
    add("eacces-dataset-record", "oserror", ["dataset", "--check", "DS"],
        chain(cp("DS"), lambda d, fx: [os.chmod(q, 0) for q in (d / "DS" / "train").glob("*.csv")]),
        unprivileged=True, match=r"\.csv")
    add("eacces-out-folder", "oserror", SIM + ["--out", "ro/D"], chain(write("ro/x", "x"), _chmod("ro", 0o555)),
        unprivileged=True, match="--out")
    add("eisdir-sidecar", "oserror", CMP + ["--out", "O"], chain(cp("rec.csv"), write("rec.yaml/x", "x")),
        match=r"rec\.yaml")
    add("eisdir-config", "oserror", ["generate", "--config", "c.yaml", "--out", "D"], write("c.yaml/x", "x"),
        match=r"c\.yaml")
    for label, make in (("fifo", lambda d: os.mkfifo(d / "rec.yaml")),
                        ("dev-zero", lambda d: (d / "rec.yaml").symlink_to("/dev/zero"))):
        add(f"sidecar-{label}", "oserror", CMP + ["--out", "O"], chain(cp("rec.csv"), lambda d, fx, m=make: m(d)),
            match=r"rec\.yaml")
    add("record-fifo", "oserror", ["compare", "f.csv", "--model", "ip2c_pedot_water", "--out", "O"],
        lambda d, fx: os.mkfifo(d / "f.csv"), match=r"f\.csv.*(pipe|FIFO)")
    add("record-dev-zero", "oserror", ["compare", "z.csv", "--model", "ip2c_pedot_water", "--out", "O"],
        lambda d, fx: (d / "z.csv").symlink_to("/dev/zero"), match=r"z\.csv")
    add("device-fifo", "oserror", ["frf", "--device", "dev.yaml", "--rh", "60", "--json", "f.json"],
        lambda d, fx: os.mkfifo(d / "dev.yaml"), match=r"dev\.yaml")
    add("dataset-json-fifo", "oserror", ["dataset", "--check", "DS"],
        chain(cp("DS"), lambda d, fx: ((d / "DS" / "dataset.json").unlink(), os.mkfifo(d / "DS" / "dataset.json"))),
        match=r"dataset\.json")

    def long_path(d, fx):
        mf = d / "DS" / "dataset.json"
        meta = json.loads(mf.read_text())
        meta["files"][0]["path"] = "train/" + "a" * 5000 + ".csv"
        mf.write_text(json.dumps(meta))
    add("enametoolong-dataset-check", "oserror", ["dataset", "--check", "DS"], chain(cp("DS"), long_path),
        match="dataset.json")
    add("enametoolong-dataset-train", "oserror", TCQ + ["--out", "R"], chain(cp("DS"), long_path),
        match="dataset.json")
    add("enametoolong-out", "oserror", SIM + ["--out", "o" * 300], match="--out")
    add("enametoolong-json", "oserror", FRF + ["--json", "j" * 300 + ".json"], match="--json|too long")
    add("enametoolong-record", "oserror", ["compare", "m" * 5000 + ".csv", "--model", "ip2c_pedot_water", "--out",
                                           "O"], match="too long|not found")
    add("float-range-sidecar-1e300", "oserror", CMP + ["--out", "O"],
        chain(cp("rec.csv"), write("rec.yaml", "sensor:\n  noise_rms_um: 1e300\n")), match="noise_rms_um")
    add("float-range-sidecar-5000-digits", "oserror", CMP + ["--out", "O"],
        chain(cp("rec.csv"), write("rec.yaml", "rh_pct: " + "9" * 5000 + "\n")), match="rh_pct")
    add("float-range-device-5000-digits", "oserror", ["frf", "--device", "dev.yaml", "--rh", "60", "--json", "f.json"],
        lambda d, fx: (d / "dev.yaml").write_text(re.sub(r"value: 26\b", "value: " + "9" * 5000,
                                                         (fx / "mydev.yaml").read_text(), count=1)),
        match="L_total")
    add("float-range-dataset-1e400", "oserror", ["dataset", "--check", "DS"],
        chain(cp("DS"), lambda d, fx: (d / "DS" / "dataset.json").write_text(
            re.sub(r'"fs_Hz": [0-9.e+]+', '"fs_Hz": 1e400', (d / "DS" / "dataset.json").read_text()))),
        match="fs_Hz")
    add("float-range-card-5000-digits", "oserror", PRED + ["--out", "p.csv"],
        chain(cp("TC", "rec.csv"), lambda d, fx: (d / B / "card.json").write_text(
            re.sub(r'"hidden": \d+', '"hidden": ' + "9" * 5000, (d / B / "card.json").read_text()))), match="hidden")
    add("param-length-below-clamp", "oserror", FRF + ["--param", "L_total=2mm", "--json", "f.json"],
        match="--param.*L_clamp")
    add("noise-free-linear-train-compare", "oserror", ["train-compare", "DL", "--models", "ff", "--set",
                                                       "ff.max_epochs=2", "--set", "ff.structures=null", "--quiet",
                                                       "--out", "R"], cp("DL"), expect="ok", may_change=("R/**",),
        timeout=180)

    # ---------------------------------------------------------------- 4. every count and size bounded
    add("devices-1000", "bounds", TCQ + ["--devices", "1000", "--out", "R"], cp("DS"), match="--devices", timeout=90)
    add("tune-1000000", "bounds", TCQ + ["--tune", "1000000", "--out", "R"], cp("DS"), match="--tune")
    add("starts-1000000-identify", "bounds", IDN + ["--starts", "1000000", "--out", "O"], cp("rec.csv"),
        match="--starts")
    add("starts-1000000-diagnose", "bounds", DIAG + ["--starts", "1000000", "--out", "O"], cp("rec.csv"),
        match="--starts")
    add("steps-ahead-1e12", "bounds", PRED + ["--steps-ahead", str(10 ** 12), "--out", "p.csv"], cp("TC", "rec.csv"),
        match="--steps-ahead")
    add("steps-ahead-beyond-record", "bounds", PRED + ["--steps-ahead", "5000", "--out", "p.csv"],
        cp("TC", "rec.csv"), match="--steps-ahead")
    add("steps-ahead-1e12-20k-samples", "bounds", ["predict", "--model", B, "--input", "long20k.csv",
                                                  "--steps-ahead", str(10 ** 12), "--out", "p.csv"],
        cp("TC", "long20k.csv"), match="--steps-ahead")
    for fs in ("1e-9", "1e-6"):
        add(f"fs-max-{fs}", "bounds", DIAG + ["--fs-max-Hz", fs, "--out", "O"], cp("rec.csv"), match="--fs-max-Hz")
    add("simulate-2e7-samples-1GHz", "bounds", ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal",
                                                "tone", "--frequency-Hz", "1e5", "--duration-s", "0.02", "--fs-Hz",
                                                "1e9", "--out", "D"], match="--fs-Hz", timeout=120)
    add("effect-order-5000-check-fast", "bounds", ["effects", "--check", "eff_order5000.py", "--fast"],
        cp("eff_order5000.py"), expect="ok-or-1", stdout=r"order 5000", timeout=60)
    add("effect-order-5000-frf", "bounds", FRF + ["--json", "f.json", "--effects", "default,+broken",
                                                  "--effects-path", "eff_order5000.py"], cp("eff_order5000.py"),
        match="order 5000", timeout=60)

    # ---------------------------------------------------------------- 5. nothing accepted silently
    add("output-level-V-with-sensor-gain", "silent", ["dataset", "--train", "lab.csv", "--columns",
                                                      "time=t,voltage=u,deflection=y", "--output", "level:V",
                                                      "--sensor-gain", "2.5mm/V", "--out", "D"], cp("lab.csv"),
        match="--sensor-gain")
    add("output-unknown-unit", "silent", ["dataset", "--train", "lab.csv", "--columns", "time=t,voltage=u,deflection=y",
                                          "--output", "level:furlong", "--out", "D"], cp("lab.csv"), expect="ok",
        may_change=("D/**",), note="furlong")
    add("param-repeated", "silent", FRF + ["--param", "L_total=40mm", "--param", "L_total=30mm", "--json", "f.json"],
        match="twice")
    add("slice-clipped", "silent", ["dataset", "--train", "rec.csv[5:5000000]", "--out", "D"], cp("rec.csv"),
        match="5000000")
    add("set-unknown-model", "silent", TCQ + ["--set", "nosuch.x=1", "--out", "R"], cp("DS"), match="nosuch")
    add("set-repeated", "silent", TCQ + ["--set", "ff.hidden=4", "--set", "ff.hidden=8", "--out", "R"], cp("DS"),
        match="twice")
    add("models-empty", "silent", ["train-compare", "DS", "--models", "", "--out", "R"], cp("DS"), match="--models")
    add("dataset-check-samples", "silent", ["dataset", "--check", "DS"],
        chain(cp("DS"), edit_json("DS/dataset.json", lambda m: m["files"][0].update(samples=m["files"][0]["samples"] - 7))),
        match="samples")

    def json_link(d, fx):
        (d / "outside.json").write_text((d / "DS" / "dataset.json").read_text())
        (d / "DS" / "dataset.json").unlink()
        (d / "DS" / "dataset.json").symlink_to(d / "outside.json")
    add("dataset-json-symlink-out", "silent", ["dataset", "--check", "DS"], chain(cp("DS"), json_link),
        match="symbolic link")

    def weights_link(d, fx):
        w = d / B / "weights.pt"
        shutil.copy(w, d / "outside.pt")
        w.unlink()
        w.symlink_to(d / "outside.pt")
    add("bundle-weights-symlink-out", "silent", PRED + ["--out", "p.csv"], chain(cp("TC", "rec.csv"), weights_link),
        match="symbolic link")

    def no_hash(scale=None):
        def setup(d, fx):
            import torch
            if scale is not None:
                w = d / B / "weights.pt"
                state = torch.load(w, weights_only=True)
                state = {k: (v * scale if v.is_floating_point() and not k.endswith(("_mean", "_std")) else v)
                         for k, v in state.items()}
                torch.save(state, w)
            edit_json(f"{B}/card.json", lambda c: c["weights"].pop("sha256"))(d, fx)
        return setup
    add("bundle-card-without-hash", "silent", PRED + ["--out", "p.csv"], chain(cp("TC", "rec.csv"), no_hash()),
        match="sha256")
    add("bundle-card-without-hash-1e30-weights", "silent", PRED + ["--out", "p.csv"],
        chain(cp("TC", "rec.csv"), no_hash(1e30)), match="sha256")
    add("bundle-card-normalisation-std-0", "silent", PRED + ["--out", "p.csv"],
        chain(cp("TC", "rec.csv"), edit_json(f"{B}/card.json",
                                             lambda c: c["normalisation"]["output"].update(std=0.0))), match="std")

    def std_buffer(d, fx):
        import torch
        w = d / B / "weights.pt"
        state = torch.load(w, weights_only=True)
        state["y_std"] = -state["y_std"]
        torch.save(state, w)
        edit_json(f"{B}/card.json", lambda c: c["weights"].update(sha256=_sha(w)))(d, fx)
    add("bundle-weights-std-negative", "silent", PRED + ["--out", "p.csv"], chain(cp("TC", "rec.csv"), std_buffer),
        match="std")
    add("sidecar-is-a-folder", "silent", ["dataset", "--train", "rec.csv", "--out", "D"],
        chain(cp("rec.csv"), write("rec.yaml/notes.txt", "x")), match=r"rec\.yaml")

    # ---------------------------------------------------------------- 6. effect files are code
    add("effect-help-says-code", "usercode", ["frf", "--help"], expect="ok", stdout=r"CODE")
    for name, flags in (("osexit_import", []), ("loop_import", []), ("loop_hook", ["--effects", "default,+broken"]),
                        ("sysexit_hook", ["--effects", "default,+broken"]),
                        ("osexit_hook", ["--effects", "default,+broken"])):
        for cmd, argv in (("frf", FRF + ["--json", "f.json"]), ("simulate", SIM + ["--out", "D"])):
            add(f"effect-{name}-{cmd}", "usercode", argv + flags + ["--effects-path", f"eff_{name}.py"],
                cp(f"eff_{name}.py"), match=f"eff_{name}.py", timeout=60)

    # ---------------------------------------------------------------- 7. messages name the user's files and flags
    add("message-tone-above-nyquist", "messages", ["simulate", "--device", "ip2c_pedot_water", "--rh", "60",
                                                   "--signal", "tone", "--frequency-Hz", "80", "--fs-Hz", "100",
                                                   "--duration-s", "2", "--out", "D"], match="--frequency-Hz 80")
    add("message-sweep-above-nyquist", "messages", ["simulate", "--device", "ip2c_pedot_water", "--rh", "60",
                                                    "--signal", "sweep", "--f-stop-Hz", "80", "--fs-Hz", "100",
                                                    "--duration-s", "2", "--out", "D"], match="--f-stop-Hz 80")

    def flat_tail(d, fx):
        _record(d / "rec.csv")
        lines = (d / "rec.csv").read_text().splitlines()
        out = [lines[0]] + [ln if i < 500 else ",".join(ln.split(",")[:2] + ["0.0001", "60"])
                            for i, ln in enumerate(lines[1:])]
        (d / "rec.csv").write_text("\n".join(out) + "\n")
    add("message-constant-after-skip", "messages", CMP + ["--skip-s", "6", "--out", "O"], flat_tail,
        match=r"rec\.csv.*--skip-s")
    add("message-recipe-yaml-one-line", "messages", TCQ + ["--out", "R"],
        chain(cp("DS"), write("recipes/ff.yaml", "model: ff\nhyper_parameters: {hidden: [1, 2\n")),
        env={"EAP_TRAIN_RECIPES": "recipes"}, match=r"ff\.yaml")
    add("message-param-temporary-device", "messages", FRF + ["--param", "width=0mm", "--json", "f.json"],
        match="--param")
    return C


def _max_abs_defl(folder: Path) -> str | None:
    import csv
    for p in folder.rglob("*.csv"):
        with open(p) as fh:
            rows = list(csv.reader(fh))
        head = rows[0]
        k = next((i for i, h in enumerate(head) if h.startswith("deflection")), None)
        if k is None:
            return f"{p.name}: no deflection column ({head})"
        unit = head[k].split("_", 1)[1]
        peak = max(abs(float(r[k])) for r in rows[1:]) * {"m": 1.0, "mm": 1e-3, "um": 1e-6}.get(unit, 1.0)
        if peak > 0.05:
            return f"{p.name}: tip {peak:g} m — millimetres read as metres"
    return None


def _pickle_bomb(path: Path) -> None:
    import pickle
    import zipfile

    class Evil:
        def __reduce__(self):
            return (os.system, ("touch PWNED",))
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("archive/data.pkl", pickle.dumps(Evil()))
        z.writestr("archive/version", "3\n")


# --------------------------------------------------------------------------- running

_ENV: dict = {}


def _snapshot(d: Path) -> dict[str, str]:
    out = {}
    for p in sorted(d.rglob("*")):
        rel = p.relative_to(d).as_posix()
        if p.is_symlink():
            out[rel] = "link:" + os.readlink(p)
        elif p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        elif p.is_dir():
            out[rel] = "dir"
    return out


def _allowed(rel: str, patterns) -> bool:
    from fnmatch import fnmatch
    return any(fnmatch(rel, pat) or (pat.endswith("/**") and rel == pat[:-3]) for pat in patterns)


class _Silent(threading.Thread):
    """A TCP server that accepts connections and never answers (a non-Dask port)."""

    def __init__(self):
        super().__init__(daemon=True)
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.port = self.sock.getsockname()[1]
        self.held = []

    def run(self):
        while True:
            conn, _ = self.sock.accept()
            self.held.append(conn)


def _limit(cap_bytes: int, fsize: int | None = None):
    def pre():
        os.setsid()
        signal.signal(signal.SIGINT, signal.SIG_DFL)   # as in a terminal (a background job ignores Ctrl-C)
        resource.setrlimit(resource.RLIMIT_AS, (cap_bytes, cap_bytes))
        if fsize is not None:    # Python ignores SIGXFSZ: a write past the limit fails with EFBIG
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
    return pre


#: Processes a case may run at once (the command, its workers, a Dask cluster); more is
#: unbounded work (``--devices 1000``): the case is stopped and counted as a hang.
MAX_PROCS = 32


def _session_size(sid: int) -> int:
    n = 0
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                n += os.getsid(int(d)) == sid
            except OSError:
                pass
    return n


def _watch(proc, stop: threading.Event, flag: list) -> None:
    """Stop ``proc``'s session when it holds more than :data:`MAX_PROCS` processes."""
    while not stop.wait(0.25):
        if _session_size(proc.pid) > MAX_PROCS:
            flag.append(True)
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            return


_TOOLS: dict = {}


def _tool(name: str) -> bool:
    """Whether the wrapper ``name`` (unshare with a private mount, setpriv) works here."""
    if name not in _TOOLS:
        test = {"unshare": ["unshare", "-rm", "true"],
                "setpriv": ["setpriv", "--bounding-set=-dac_override,-dac_read_search", "true"]}[name]
        try:
            _TOOLS[name] = subprocess.run(test, capture_output=True).returncode == 0
        except OSError:
            _TOOLS[name] = False
    return _TOOLS[name]


def _wrapped(case: Case, argv: list[str]) -> list[str] | None:
    """The command line of ``case`` with its wrappers (None: a wrapper this machine lacks)."""
    cmd = [sys.executable, "-m", "nnmodel.app.cli", *argv]
    if case.unprivileged and os.geteuid() == 0:
        if not _tool("setpriv"):
            return None
        cmd = ["setpriv", "--bounding-set=-dac_override,-dac_read_search"] + cmd
    if case.disk_kB:
        if not _tool("unshare"):
            return None
        script = (f'mount -t tmpfs -o size={case.disk_kB}k tmpfs full || exit 99; "$@"; rc=$?; '
                  'ls -A full > full.ls; exit $rc')
        cmd = ["unshare", "-rm", "sh", "-c", script, "sh"] + cmd
    return cmd


def _classify(notes: list[str], case: Case, rc) -> str:
    """The class of a failed case (module doc)."""
    text = "; ".join(notes)
    if "changed/removed" in text or "CODE RAN" in text:
        return "data loss"
    if "traceback" in text:
        return "traceback"
    if "timed out" in text or "more than" in text and "processes" in text:
        return "hang"
    if rc == 0 and (case.expect == "error" or case.note):
        return "silent acceptance"
    return "other"


def run_case(case: Case, root: Path, fx: Path, args, silent_port: int) -> dict:
    d = root / re.sub(r"[^A-Za-z0-9_.-]", "_", case.name)
    d.mkdir(parents=True)
    work = d / "w"
    work.mkdir()
    try:
        if case.setup:
            case.setup(work, fx)
    except Exception as exc:  # a setup that fails on this tree (e.g. a command it lacks)
        return {"case": case.name, "group": case.group, "held": False, "traceback": False,
                "note": f"setup failed: {str(exc)[:200]}", "s": 0.0}
    argv = [a.replace("SILENT", f"tcp://127.0.0.1:{silent_port}").replace("@WORK@", str(work)) for a in case.argv]
    cmd = _wrapped(case, argv)
    if cmd is None:
        shutil.rmtree(d, ignore_errors=True)
        return {"case": case.name, "group": case.group, "held": None, "traceback": False, "class": "skipped",
                "note": "skipped: this machine lacks unshare/setpriv", "s": 0.0}
    if case.disk_kB:
        (work / "full").mkdir(exist_ok=True)
    before = _snapshot(work)
    env = dict(_ENV, **case.env)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_limit(int(args.cap_GB * 2**30), case.fsize))
    stop, too_many = threading.Event(), []
    watcher = threading.Thread(target=_watch, args=(proc, stop, too_many), daemon=True)
    watcher.start()
    timeout = case.timeout or args.timeout
    timed_out = False
    try:
        if case.send:
            sig, after = case.send
            try:
                proc.wait(after)
            except subprocess.TimeoutExpired:
                proc.send_signal(sig)
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
    elapsed = time.perf_counter() - t0
    stop.set()
    rc = proc.returncode
    orphans = False
    try:
        os.killpg(proc.pid, 0)
        orphans = True
        time.sleep(2.0)
        os.killpg(proc.pid, 0)
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        orphans = False
    after = _snapshot(work)
    tb = "Traceback (most recent call last)" in err
    notes = []
    if timed_out:
        notes.append(f"timed out after {timeout:g} s")
    if too_many:
        notes.append(f"started more than {MAX_PROCS} processes (unbounded) and was stopped")
    if tb:
        notes.append("traceback: " + err.strip().splitlines()[-1][:160])
    if orphans:
        notes.append("processes left running after exit")
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    if case.expect == "error":
        errline = [ln for ln in lines if re.match(r"eap [\w-]+: error: ", ln)]
        if rc != 2:
            notes.append(f"exit {rc} (expected 2)" + (f": {lines[-1][:160]}" if lines else ""))
        elif not errline:
            notes.append(f"no one-line error: {(lines[-1] if lines else '')[:160]}")
        elif case.match and not re.search(case.match, errline[-1]):
            notes.append(f"message lacks /{case.match}/: {errline[-1][:200]}")
    elif case.expect == "ok":
        if rc != 0:
            notes.append(f"exit {rc} (expected 0): {(lines[-1] if lines else '')[:200]}")
    elif case.expect == "ok-or-1":      # a verdict command (effects --check): 0 or 1, never a crash
        if rc not in (0, 1):
            notes.append(f"exit {rc} (expected 0 or 1): {(lines[-1] if lines else '')[:200]}")
    else:
        if rc != case.expect:
            notes.append(f"exit {rc} (expected {case.expect}): {(lines[-1] if lines else '')[:160]}")
        elif not lines or not re.match(r"eap [\w-]+: interrupted", lines[-1]) or len(lines) != 1 + sum(
                bool(re.match(r"eap [\w-]+: (warning|note): ", ln)) for ln in lines[:-1]):
            notes.append(f"{len(lines)} lines on stderr (expected the warnings said before and one "
                         f"'interrupted' line): {(lines[-1] if lines else '')[:120]}")
    if case.strict and case.expect == "error" and rc == 2:
        errors = [ln for ln in lines if not re.match(r"eap [\w-]+: (warning|note): ", ln)]
        if len(errors) != 1:
            notes.append(f"{len(errors)} lines on stderr besides notes (expected one error line)")
    if case.strict and ".eap-tmp-" in out + err:
        notes.append("prints a path through eap's temporary folder (.eap-tmp-)")
    if case.note and not any(re.match(r"eap [\w-]+: (warning|note): ", ln) and re.search(case.note, ln)
                             for ln in lines):
        notes.append(f"no note matching /{case.note}/")
    if case.stdout and not re.search(case.stdout, out):
        notes.append(f"stdout lacks /{case.stdout}/")
    may_change = case.may_change + (("full.ls",) if case.disk_kB else ())
    if case.disk_kB:
        left = (work / "full.ls").read_text().split() if (work / "full.ls").is_file() else ["(no listing: mount failed?)"]
        if left:
            notes.append(f"left on the full disk: {', '.join(left[:4])}")
    changed = [k for k in before if after.get(k) != before[k] and not _allowed(k, may_change)]
    new = [k for k in after if k not in before and not _allowed(k, may_change)]
    if changed:
        notes.append(f"changed/removed: {', '.join(changed[:4])}")
    if new and case.expect not in ("ok", "ok-or-1"):
        notes.append(f"created: {', '.join(new[:4])}")
    if (work / "PWNED").exists():
        notes.append("CODE RAN")
    if case.check and not notes:
        note = case.check(work)
        if note:
            notes.append(note)
    if not args.keep:
        shutil.rmtree(d, ignore_errors=True)
    errline = [ln for ln in lines if re.match(r"eap [\w-]+: (error|interrupted)", ln)]
    return {"case": case.name, "group": case.group, "held": not notes, "traceback": tb, "rc": rc,
            "class": "held" if not notes else _classify(notes, case, rc), "note": "; ".join(notes), "s": elapsed,
            "stderr": err.strip()[-300:], "answer": (errline[-1] if errline else (lines[-1] if lines else ""))[:400]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", default=str(HERE), help="checkout of eap-model to audit (default: this one)")
    ap.add_argument("--only", default=None, help="regular expression on case names or groups")
    ap.add_argument("--timeout", type=float, default=45.0, help="seconds per case before it counts as a hang")
    ap.add_argument("--cap-GB", type=float, default=4.0, help="address-space cap per case")
    ap.add_argument("--keep", action="store_true", help="keep each case's folder")
    ap.add_argument("--verbose", action="store_true", help="print stderr of failed cases")
    ap.add_argument("--json", default=None, help="also write the results as JSON here")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args()
    tree = Path(args.tree).resolve()
    all_cases = cases()
    if args.only:
        all_cases = [c for c in all_cases if re.search(args.only, c.name) or re.search(args.only, c.group)]
    if args.list:
        for c in all_cases:
            print(f"{c.group:12s} {c.name}")
        print(f"{len(all_cases)} cases")
        return
    _ENV.update(os.environ, PYTHONPATH=str(tree), PYTHONDONTWRITEBYTECODE="1")
    _ENV.pop("EAP_SCHEDULER", None)
    silent = _Silent()
    silent.start()
    rev = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    print(f"auditing {tree} ({rev}): {len(all_cases)} cases", flush=True)
    results = []
    with tempfile.TemporaryDirectory(prefix="eap-audit-") as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        build_fixtures(root / "fixtures", tree, _ENV)
        print(f"fixtures built in {time.perf_counter() - t0:.0f} s", flush=True)
        for case in all_cases:
            r = run_case(case, root / "cases", root / "fixtures", args, silent.port)
            results.append(r)
            mark = "skip" if r["held"] is None else "held" if r["held"] else "FAIL"
            print(f"{mark} {r['s']:5.1f}s {r['group']:11s} {r['case']}" + (f"  — {r['note']}" if r["note"] else ""),
                  flush=True)
            if args.verbose and not r["held"] and r.get("stderr"):
                print("      " + r["stderr"].replace("\n", "\n      "))
    skipped = [r for r in results if r["held"] is None]
    results = [r for r in results if r["held"] is not None]
    held = sum(r["held"] for r in results)
    tbs = sum(r["traceback"] for r in results)
    print(f"\n{tree} ({rev}): tried {len(results)}, held {held}, failed {len(results) - held}, "
          f"tracebacks {tbs}" + (f"; skipped {len(skipped)} (no unshare/setpriv here)" if skipped else ""))
    classes = ("held", "data loss", "traceback", "hang", "silent acceptance", "other")
    print("  by class: " + ", ".join(f"{c} {sum(r['class'] == c for r in results)}" for c in classes))
    groups = sorted({r["group"] for r in results})
    for g in groups:
        rs = [r for r in results if r["group"] == g]
        print(f"  {g:12s} {sum(r['held'] for r in rs):3d} / {len(rs):3d} held   " + ", ".join(
            f"{c} {n}" for c in classes[1:] if (n := sum(r["class"] == c for r in rs))))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
