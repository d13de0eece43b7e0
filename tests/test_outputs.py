"""The output-folder policy (physics.io.outputs): nothing a user owns is deleted or replaced."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from nnmodel.app.cli import main
from physics.errors import InputError
from physics.io.outputs import LOCK_SUFFIX, MARKER, output_folder


def _record(path: Path, n: int = 400, fs: float = 200.0) -> Path:
    t = np.arange(n) / fs
    v = np.sin(2 * np.pi * 2 * t)
    d = 1e-4 * np.sin(2 * np.pi * 2 * t - 0.4)
    lines = ["time_s,voltage_V,deflection_m,rh_pct"] + [f"{a},{b},{c},60" for a, b, c in zip(t.tolist(), v.tolist(), d.tolist())]
    path.write_text("\n".join(lines) + "\n")
    return path


def _compare(rec, out, *extra):
    return main(["compare", str(rec), "--model", "ip2c_pedot_water", "--out", str(out), *extra])


def test_folder_is_written_atomically_with_marker(tmp_path):
    with output_folder(tmp_path / "o") as d:
        (d / "a.txt").write_text("x")
        assert not (tmp_path / "o").exists()  # nothing visible until the end
    assert (tmp_path / "o" / "a.txt").read_text() == "x"
    assert json.loads((tmp_path / "o" / MARKER).read_text())["pid"] == os.getpid()
    assert not list(tmp_path.glob(".o.*"))  # no temp folder or lock left
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "o").stat().st_mode & 0o777 == 0o777 & ~umask   # the usual mode, not mkdtemp's 0700


def test_failure_leaves_nothing_and_keeps_the_old_result(tmp_path):
    with output_folder(tmp_path / "o") as d:
        (d / "a.txt").write_text("old")
    with pytest.raises(RuntimeError):
        with output_folder(tmp_path / "o", overwrite=True) as d:
            (d / "a.txt").write_text("half")
            raise RuntimeError("crash halfway")
    assert (tmp_path / "o" / "a.txt").read_text() == "old"
    assert not list(tmp_path.glob(".o.*"))


def test_existing_folder_needs_overwrite_and_must_be_ours(tmp_path):
    rec = _record(tmp_path / "rec.csv")
    out = tmp_path / "res"
    assert _compare(rec, out) == 0
    assert _compare(rec, out) == 2                    # exists: refused without --overwrite
    assert _compare(rec, out, "--overwrite") == 0     # ours: replaced
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "thesis.docx").write_text("years of work")
    assert _compare(rec, precious, "--overwrite") == 2
    assert (precious / "thesis.docx").read_text() == "years of work"


@pytest.mark.parametrize("target", [".", "..", "~", "/"])
def test_dangerous_targets_are_refused(tmp_path, monkeypatch, capsys, target):
    work = tmp_path / "work"
    work.mkdir()
    rec = _record(work / "rec.csv")
    monkeypatch.chdir(work)
    assert _compare(rec, target, "--overwrite") == 2
    assert "refusing to write into" in capsys.readouterr().err
    assert rec.is_file()


def test_output_folder_holding_an_input_is_refused(tmp_path, capsys):
    out = tmp_path / "ow2"
    out.mkdir()
    rec = _record(out / "metrics.csv")
    before = rec.read_bytes()
    assert _compare(rec, out, "--overwrite") == 2
    assert "contains the input" in capsys.readouterr().err
    assert rec.read_bytes() == before
    # identify with --name: the input's sidecar is never a target either
    assert main(["identify", str(rec), "--device", "ipmc_pt_eg", "--free", "kf", "--name", "metrics",
                 "--out", str(out)]) == 2
    assert not (out / "metrics.yaml").exists()


def test_a_second_writer_fails_at_once_naming_the_first(tmp_path):
    parent = tmp_path
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        (parent / f".o{LOCK_SUFFIX}").write_text(json.dumps({"pid": proc.pid, "command": "eap generate --out o",
                                                             "started": "now"}))
        with pytest.raises(InputError, match=rf"being written by another run \(pid {proc.pid}: eap generate"):
            with output_folder(parent / "o"):
                pass
    finally:
        proc.kill()
        proc.wait()
    with output_folder(parent / "o") as d:  # the lock of a dead run is stale: replaced
        (d / "x").write_text("1")
    assert (parent / "o" / "x").is_file()


def test_temp_folders_of_killed_runs_are_cleaned_only_with_proof(tmp_path, recwarn):
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()  # a pid that no longer runs
    stale = tmp_path / f".o.eap-tmp-{proc.pid}"
    stale.mkdir()   # eap's proof: names this very folder and the pid of the run that made it
    (stale / ".eap-partial").write_text(json.dumps({"folder": stale.name, "pid": proc.pid, "pid_start": None}))
    named = tmp_path / f".o.eap-tmp-{proc.pid + 1}"
    named.mkdir()   # only named like one (the old marker: a command line, no proof): kept and named
    (named / ".eap-partial").write_text("eap generate")
    copied = tmp_path / f".o.eap-old-{proc.pid}"
    copied.mkdir()  # a proof copied from another folder proves nothing
    (copied / ".eap-partial").write_text(json.dumps({"folder": stale.name, "pid": proc.pid}))
    with output_folder(tmp_path / "o") as d:
        (d / "x").write_text("1")
    assert not stale.exists() and named.exists() and copied.exists()
    notes = " ".join(str(w.message) for w in recwarn)
    assert named.name in notes and copied.name in notes and "left in place" in notes


def test_unwritable_out_fails_before_any_work(tmp_path, capsys):
    rec = _record(tmp_path / "rec.csv")
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert _compare(rec, blocker / "out") == 2            # a parent that is a file: unwritable even as root
    assert "choose a writable --out" in capsys.readouterr().err
    if os.geteuid() != 0:                                 # a read-only folder (root writes anywhere)
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        assert _compare(rec, ro / "out") == 2
        assert "not writable" in capsys.readouterr().err


def test_generate_never_deletes_a_users_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "keep.txt").write_text("mine")
    assert main(["generate", "--config", "quick", "--out", ".", "--overwrite"]) == 2
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "data.csv").write_text("1,2")
    assert main(["generate", "--config", "quick", "--out", "precious", "--overwrite"]) == 2
    assert (tmp_path / "keep.txt").read_text() == "mine" and (precious / "data.csv").read_text() == "1,2"
    assert "holds files eap did not write" in capsys.readouterr().err


def test_predict_and_train_compare_have_distinct_defaults():
    from nnmodel.app.cli import build_parser
    p = build_parser()
    defaults = {}
    for cmd in ("compare", "train-compare", "identify", "diagnose", "simulate", "validate", "run"):
        args = p.parse_args([cmd] + (["x"] if cmd in ("compare", "train-compare", "identify", "diagnose")
                                     else []) + (["--model", "m"] if cmd == "compare" else []))
        defaults[cmd] = args.out
    assert len(set(defaults.values())) == len(defaults), defaults


@pytest.mark.parametrize("sig", ["INT", "TERM"])
def test_interruption_prints_one_line_and_leaves_nothing(tmp_path, sig):
    import signal as signal_mod
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    # Ctrl-C as from a terminal: a suite run as a background job (`pytest &`) inherits an ignored
    # SIGINT, which eap rightly keeps ignoring; the child gets the default disposition back.
    proc = subprocess.Popen([sys.executable, "-m", "nnmodel.app.cli", "generate", "--config", "default", "--out",
                             str(tmp_path / "ds")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            text=True, preexec_fn=lambda: signal_mod.signal(signal_mod.SIGINT, signal_mod.SIG_DFL))
    deadline = time.time() + 60
    while time.time() < deadline and not list(tmp_path.glob(".ds.eap-tmp-*/**/*.csv")):
        time.sleep(0.2)
    proc.send_signal(getattr(signal_mod, f"SIG{sig}"))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == (130 if sig == "INT" else 143), err
    assert err.strip().splitlines()[-1].endswith(f"interrupted; nothing written to {tmp_path / 'ds'}")
    assert "Traceback" not in err
    assert not (tmp_path / "ds").exists() and not list(tmp_path.glob(".ds*"))
