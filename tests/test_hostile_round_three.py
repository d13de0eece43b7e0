"""Hostile inputs, round three (issue 38): no name escapes its folder, nothing of a user's is
swept up, every OS error is one line, every count and size is bounded before work, nothing is
accepted silently, effect files are code (contained), and messages name the user's files and
flags.  Each class has fast cases here; ``bench/hostile_audit.py`` runs them as a user would
(fresh processes, a full disk, a file-size limit, no root powers)."""
from __future__ import annotations

import errno
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nnmodel.app.cli import main
from physics.errors import InputError
from physics.io.fileio import load_json
from physics.io.outputs import component, final_text, output_files, output_folder, separate
from physics.io.timeseries import read_timeseries
from physics.io.yamlio import loads_yaml
from test_hostile_round_two import EFFECT, FRF, SIM, _err, _record, bundle  # noqa: F401  (bundle: a fixture)

HERE = Path(__file__).resolve().parents[1]


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


# ------------------------------------------------------------------ 1. names never escape
@pytest.mark.parametrize("name,problem", [("", "is empty"), ("../victim", "is a path"), ("/abs/dev", "is a path"),
                                          (".hidden", "starts with '.'"), ("a\nb", "control character"),
                                          ("n" * 201, "longer than 200 bytes"), ("..", "is a path")])
def test_a_name_is_one_plain_path_component(name, problem):
    with pytest.raises(InputError, match=problem):
        component(name, "--name")
    assert component("ipmc_fitted-2 (v3)", "--name") == "ipmc_fitted-2 (v3)"


def test_identify_refuses_a_name_that_is_a_path_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "rec.csv")
    (tmp_path / "mydevice.yaml").write_text("my device\n")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "victim.yaml").write_text("mine\n")
    before = _snapshot(tmp_path)
    for name in ("/home/me/mydevice", str(tmp_path / "mydevice"), "../victim"):
        assert main(["identify", "rec.csv", "--free", "kf", "--name", name, "--out", "runs/id"]) == 2
        err = _err(capsys)
        assert "--name '" in err and "': is a path, not a name" in err
    assert "--name '../victim': is a path" in err
    assert _snapshot(tmp_path) == before


def test_an_output_and_its_sub_output_may_not_coincide_or_nest(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "rec.csv")
    assert main(SIM + ["--out", "O"]) == 0              # an eap folder --overwrite could replace
    capsys.readouterr()
    before = _snapshot(tmp_path)
    base = ["diagnose", "rec.csv", "--free", "kf"]
    for out, drafts, how in (("O", "O", "is the same folder as"), ("O", "O/drafts", "contains"),
                             ("X/O", "X", "lies inside")):
        assert main(base + ["--out", out, "--draft-effects", drafts, "--overwrite"]) == 2
        assert f"--out {out} {how} --draft-effects {drafts}" in _err(capsys)
    assert _snapshot(tmp_path) == before
    separate({"--out": "a", "--draft-effects": "b", "--plot": None})    # distinct: accepted


# ------------------------------------------------------------------ 2. ownership by proof, not by name
def test_only_proven_leftovers_are_removed_the_rest_is_named(tmp_path, recwarn):
    dead = _dead_pid()
    named = tmp_path / ".eap-tmp-999999-notes"           # a user's folder named like a staging folder
    named.mkdir()
    (named / "thesis.tex").write_text("my thesis")
    proven = tmp_path / f".eap-tmp-{dead}-abc12345"      # eap's, of a run that is gone
    proven.mkdir()
    (proven / ".eap-partial").write_text(json.dumps({"folder": proven.name, "pid": dead}))
    alive = tmp_path / f".eap-tmp-{os.getpid()}-zzz"     # eap's proof, but its process still runs
    alive.mkdir()
    (alive / ".eap-partial").write_text(json.dumps({"folder": alive.name, "pid": os.getpid()}))
    with output_files([tmp_path / "f.json"]) as (tmp,):
        tmp.write_text("{}")
    assert (named / "thesis.tex").read_text() == "my thesis" and not proven.exists() and alive.exists()
    assert any(named.name in str(w.message) and "left in place" in str(w.message) for w in recwarn)


def test_a_reused_pid_does_not_keep_a_leftover(tmp_path):
    """A proof names the start time of its process: the same pid in a later process is not it."""
    from physics.io.outputs import _running, process_start
    me = os.getpid()
    assert _running(me, process_start(me))
    if process_start(me) is not None:                    # Linux: the start time tells them apart
        assert not _running(me, str(int(process_start(me)) - 1))
    stale = tmp_path / f".o.eap-tmp-{me}"                # this pid's own earlier run (reused number)
    stale.mkdir()
    (stale / ".eap-partial").write_text(json.dumps({"folder": stale.name, "pid": me, "pid_start": "0"}))
    with output_folder(tmp_path / "o") as d:
        (d / "x").write_text("1")
    assert (tmp_path / "o" / "x").is_file() and not stale.exists()


@pytest.mark.parametrize("where", ["lock", "registry"])
def test_a_lock_or_registry_that_is_not_eaps_file_is_refused_before_anything_is_written(tmp_path, monkeypatch,
                                                                                          capsys, where):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / (".D.eap-lock" if where == "lock" else ".eap-files.json")
    path.mkdir()
    (path / "mine.txt").write_text("x")
    argv = SIM + ["--out", "D"] if where == "lock" else FRF + ["--json", "f.json"]
    assert main(argv) == 2
    assert path.name in _err(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name] and (path / "mine.txt").read_text() == "x"


# ------------------------------------------------------------------ 3. every OS error is one line
@pytest.mark.parametrize("code,words", [(errno.ENOSPC, "the disk is full"), (errno.EACCES, "permission denied"),
                                        (errno.EISDIR, "it is a folder"), (errno.ENAMETOOLONG, "name is too long")])
def test_os_errors_are_one_line_and_nothing_is_put_in_place(tmp_path, monkeypatch, capsys, code, words):
    import physics.io.frfdata as frfdata
    monkeypatch.chdir(tmp_path)

    def fail(data, path, **kw):   # the CSV fails while being written (beside the JSON already written)
        Path(path).write_text("half")
        raise OSError(code, os.strerror(code), str(path))
    monkeypatch.setattr("nnmodel.app.commands.frf.write_frf", fail)
    assert frfdata.write_frf is not fail
    assert main(FRF + ["--json", "f.json", "--csv", "f.csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and "Traceback" not in err[0], err
    assert err[0].startswith(f"eap frf: error: {tmp_path / 'f.csv'}: ") and ".eap-tmp" not in err[0]
    assert not list(tmp_path.iterdir())                   # nothing put in place, no staging folder left


def test_a_file_size_limit_is_one_line(tmp_path):
    """EFBIG for real: RLIMIT_FSIZE (Python ignores SIGXFSZ, so the write fails)."""
    env = dict(os.environ, PYTHONPATH=str(HERE))
    r = subprocess.run([sys.executable, "-m", "nnmodel.app.cli", "frf", "--device", "ip2c_pedot_water", "--rh", "60",
                        "--points", "500", "--json", "f.json"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000)))
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip() == ("eap frf: error: --json f.json: the file would exceed the file-size limit of this "
                                "process or file system (ulimit -f); raise it or write less (File too large); nothing "
                                "was written")
    assert not list(tmp_path.iterdir())


def test_an_unreadable_input_is_one_line(tmp_path, monkeypatch, capsys):
    import nnmodel.app.commands.compare as compare_cmd
    rec = _record(tmp_path / "rec.csv")

    def denied(*a, **k):
        raise PermissionError(errno.EACCES, "Permission denied", str(rec))
    monkeypatch.setattr(compare_cmd, "load_measurements", denied)
    assert main(["compare", str(rec), "--model", "ip2c_pedot_water", "--out", str(tmp_path / "O")]) == 2
    assert _err(capsys) == (f"eap compare: error: {rec}: permission denied; check the permissions, or choose another "
                            "path (Permission denied); nothing was written")


@pytest.mark.parametrize("kind", ["fifo", "folder", "device"])
def test_a_sidecar_that_is_not_a_regular_file_is_refused(tmp_path, kind):
    rec = _record(tmp_path / "rec.csv")
    side = tmp_path / "rec.yaml"
    {"fifo": lambda: os.mkfifo(side), "folder": side.mkdir, "device": lambda: side.symlink_to("/dev/zero")}[kind]()
    with pytest.raises(InputError, match=r"rec\.yaml: the sidecar of rec\.csv is a (named pipe|folder|device)"):
        read_timeseries(rec)


def test_a_path_too_long_in_dataset_json_is_refused_naming_it(tmp_path):
    from nnmodel.dataset import load_dataset
    from nnmodel.measured import build_dataset
    a = _record(tmp_path / "a.csv", n=400)
    ds = build_dataset(tmp_path / "DS", train=[str(a)])
    meta = json.loads((ds / "dataset.json").read_text())
    meta["files"][0]["path"] = "train/" + "a" * 5000 + ".csv"
    (ds / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(InputError, match=r"dataset\.json: files\[0\]\.path: .*255 bytes"):
        load_dataset(ds)


@pytest.mark.parametrize("text,key", [("rh_pct: " + "9" * 5000, "rh_pct"),
                                      ("sensor:\n  noise_rms_um: " + "9" * 400, "sensor.noise_rms_um"),
                                      ("a: [1, -" + "9" * 320 + "]", r"a\[1\]")])
def test_numbers_outside_float_range_are_refused_naming_the_key(text, key):
    with pytest.raises(InputError, match=rf"f\.yaml: {key}: .* outside the range of a float"):
        loads_yaml(text, "f.yaml")


def test_json_numbers_outside_float_range_and_sidecar_overflow(tmp_path):
    p = tmp_path / "d.json"
    p.write_text('{"fs_Hz": 1e400, "files": [{"samples": ' + "1" * 5000 + "}]}")
    with pytest.raises(InputError, match=r"d\.json: the JSON file: (fs_Hz|files\[0\]\.samples): .* range of a float"):
        load_json(p)
    rec = _record(tmp_path / "rec.csv")
    (tmp_path / "rec.yaml").write_text("sensor:\n  noise_rms_um: 1e300\n")
    with pytest.raises(InputError, match=r"rec\.yaml: sensor\.noise_rms_um: 1e\+300 um is 1e\+294 m"):
        read_timeseries(rec)


def test_param_checks_the_strip_and_is_given_once(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(FRF + ["--param", "L_total=2mm", "--json", "f.json"]) == 2
    assert "--param L_total=2mm: device 'ip2c_pedot_water': L_total 0.002 m is not longer than L_clamp" in _err(capsys)
    assert main(FRF + ["--param", "L_total=40mm", "--param", "L_total=30mm", "--json", "f.json"]) == 2
    assert "--param L_total is given twice (L_total=40mm, L_total=30mm)" in _err(capsys)
    assert not list(tmp_path.iterdir())


def test_loss_notes_survive_a_zero_training_loss():
    """Noise-free linear data: train_loss 0 gave a ZeroDivisionError after training."""
    from nnmodel.explain import losses
    note = losses({"models": {"ff": {"history": [{"epoch": 0, "train_loss": 0.0, "val_loss": 0.1}]}}})
    assert note and "train_loss 0" in str(note[0])


# ------------------------------------------------------------------ 4. every count and size bounded before work
@pytest.mark.parametrize("argv,message", [
    (["identify", "rec.csv", "--free", "kf", "--starts", "1000000"], "--starts 1000000: must be a whole number within 1–256"),
    (["diagnose", "rec.csv", "--starts", "1000000"], "--starts 1000000: must be a whole number within 1–256"),
    (["diagnose", "rec.csv", "--fs-max-Hz", "1e-9"], "--fs-max-Hz 1e-09: must lie within 1e-06–1e+09"),
    (["diagnose", "rec.csv", "--fs-max-Hz", "1e-6"], "--fs-max-Hz 1e-06 Hz leaves 0 samples of"),
    (["train-compare", "DS", "--tune", "1000000"], "--tune 1000000: must be a whole number within 1–1,000"),
    (["train-compare", "DS", "--devices", "1000"], "--devices 1000: must be a whole number within 1–"),
    (SIM[:-4] + ["--duration-s", "0.02", "--fs-Hz", "1e9", "--frequency-Hz", "1e5"], "exceeds 2e+11"),
])
def test_counts_and_sizes_are_refused_before_work(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "rec.csv")
    if argv[0] == "train-compare":
        from nnmodel.measured import build_dataset
        build_dataset(tmp_path / "DS", train=["rec.csv"])
    before = _snapshot(tmp_path)
    assert main(argv + ["--out", "O"]) == 2
    assert message in _err(capsys)
    assert _snapshot(tmp_path) == before


def test_steps_ahead_is_bounded_by_the_cap_and_the_record(tmp_path, monkeypatch, capsys):
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    t = np.arange(300) / 100.0
    u = np.sin(2 * np.pi * 2 * t)
    m = MODELS["rbf"](n_centres=6, nb=4, na=1, progress_bar=False)
    m.fit([Experiment(u=u, y=1e-4 * np.sin(2 * np.pi * 2 * t - 0.3), rh=np.full(300, 60.0), fs=100.0)], None)
    save(m, tmp_path / "b")
    _record(tmp_path / "rec.csv")
    monkeypatch.chdir(tmp_path)
    base = ["predict", "--model", "b", "--input", "rec.csv", "--out", "p.csv", "--steps-ahead"]
    assert main(base + [str(10 ** 12)]) == 2 and "--steps-ahead 1000000000000: must be a whole number" in _err(capsys)
    assert main(base + ["5000"]) == 2 and "--steps-ahead 5000: rec.csv has 400 samples" in _err(capsys)
    assert main(base + ["400"]) == 0                  # the whole record is a valid horizon


def test_a_transfer_function_order_is_checked_before_it_is_evaluated(tmp_path):
    from physics.effects import EFFECTS, load_effects_file
    f = tmp_path / "order.py"
    f.write_text(EFFECT.format(body="import numpy as np; return [1.0], list(np.poly(-np.linspace(1, 50, 5000)))"))
    with pytest.raises(InputError, match=r"order\.py: effect 'broken' fails the contract check 'finite': .*"
                                         r"denominator of order 5000; at most 32"):
        load_effects_file(f)
    assert "broken" not in EFFECTS


# ------------------------------------------------------------------ 5. nothing accepted silently
def test_contradicting_or_unknown_output_declarations(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "lab.csv", header=("t", "u", "y"), scale=2.0, offset=5.0)
    base = ["dataset", "--train", "lab.csv", "--columns", "time=t,voltage=u,deflection=y"]
    assert main(base + ["--output", "level:V", "--sensor-gain", "2.5mm/V", "--out", "D"]) == 2
    assert "--output level:V and --sensor-gain 2.5mm/V contradict each other" in _err(capsys)
    assert main(base + ["--output", "level:furlong", "--out", "D"]) == 0
    err = capsys.readouterr().err
    assert "eap dataset: note: output level:furlong: 'furlong' is not a unit eap knows" in err


def test_clipped_slices_stray_settings_and_empty_model_lists_are_refused(tmp_path, monkeypatch, capsys):
    from nnmodel.measured import build_dataset
    monkeypatch.chdir(tmp_path)
    _record(tmp_path / "rec.csv")
    assert main(["dataset", "--train", "rec.csv[5:5000000]", "--out", "D"]) == 2
    assert "sample 5000000 lies beyond the 400 samples of rec.csv" in _err(capsys)
    build_dataset(tmp_path / "DS", train=["rec.csv"])
    for argv, message in ((["--models", ""], "--models '' names no model"),
                          (["--models", "ff", "--set", "nosuch.x=1"], "--set nosuch.x=1: nosuch is not one of the models"),
                          (["--models", "ff", "--set", "ff.hidden=4", "--set", "ff.hidden=8"], "given twice"),
                          (["--models", "ff,ff"], "ff named twice")):
        assert main(["train-compare", "DS", *argv, "--out", "R"]) == 2, argv
        assert message in _err(capsys)
    assert not (tmp_path / "R").exists()


def test_dataset_check_verifies_sample_counts_and_refuses_a_linked_description(tmp_path):
    from nnmodel.measured import build_dataset, check_dataset
    a = _record(tmp_path / "a.csv", n=400)
    ds = build_dataset(tmp_path / "DS", train=[str(a)])
    mf = ds / "dataset.json"
    meta = json.loads(mf.read_text())
    meta["files"][0]["samples"] = 393
    mf.write_text(json.dumps(meta))
    with pytest.raises(InputError, match=r"400 samples but dataset\.json says 393"):
        check_dataset(ds)
    outside = tmp_path / "outside.json"
    outside.write_text(mf.read_text())
    mf.unlink()
    mf.symlink_to(outside)
    with pytest.raises(InputError, match=r"dataset\.json is a symbolic link"):
        check_dataset(ds)


@pytest.mark.parametrize("tamper,message", [("no-hash", "weights.sha256 None is not a SHA-256"),
                                            ("link", "a symbolic link"), ("card-std", "normalisation.output.std 0.0"),
                                            ("buffer-std", r"normalisation \['y_std'\] holds a standard deviation")])
def test_a_bundle_is_closed_and_hashed(bundle, tmp_path, tamper, message):
    import hashlib
    import shutil

    import torch

    from nnmodel.bundle import load
    b = tmp_path / "b"
    shutil.copytree(bundle, b)
    card = json.loads((b / "card.json").read_text())
    w = b / "weights.pt"
    if tamper == "no-hash":
        card["weights"].pop("sha256")
    elif tamper == "link":
        shutil.move(w, tmp_path / "outside.pt")
        w.symlink_to(tmp_path / "outside.pt")
    elif tamper == "card-std":
        card["normalisation"]["output"]["std"] = 0.0
    else:
        state = torch.load(w, weights_only=True)
        state["y_std"] = -state["y_std"]
        torch.save(state, w)
        card["weights"]["sha256"] = hashlib.sha256(w.read_bytes()).hexdigest()
    (b / "card.json").write_text(json.dumps(card))
    with pytest.raises(InputError, match=message):
        load(b)


# ------------------------------------------------------------------ 6. effect files are code, contained
@pytest.mark.parametrize("body,message", [
    ("import os; os._exit(0)", r"Broken\.output_tf called os\._exit\(0\)"),
    ("import sys; sys.exit(3)", r"Broken\.output_tf called sys\.exit\(3\)"),
    ("while True: pass", r"Broken\.output_tf ran longer than 0\.5 s")])
def test_exit_calls_and_endless_hooks_are_caught(tmp_path, monkeypatch, body, message):
    from physics.effects import EFFECTS, load_effects_file
    from physics.execution import usercode
    monkeypatch.setenv("EAP_HOOK_LIMIT_S", "0.5")          # the knob for hooks that need longer (here: shorter)
    f = tmp_path / "eff.py"
    f.write_text(EFFECT.format(body=body))
    with pytest.raises(InputError, match=rf"eff\.py: effect 'broken' fails the contract check 'finite': eff\.py: "
                                         rf"{message}"):
        load_effects_file(f)
    assert "broken" not in EFFECTS and os._exit is usercode._REAL_EXIT


def test_an_endless_import_and_an_exit_at_import_are_caught(tmp_path, monkeypatch, capsys):
    from physics.execution import usercode
    monkeypatch.setattr(usercode, "IMPORT_LIMIT_S", 0.5)
    loop, ex = tmp_path / "loop.py", tmp_path / "ex.py"
    loop.write_text("while True:\n    pass\n")
    ex.write_text("import os\nos._exit(0)\n")
    for f, message in ((loop, "importing it ran longer than 0.5 s"), (ex, "importing it called os._exit(0)")):
        assert main(FRF + ["--json", str(tmp_path / "f.json"), "--effects-path", str(f)]) == 2
        assert f"--effects-path {f}: {message}" in _err(capsys)
    assert not (tmp_path / "f.json").exists()


def test_the_help_says_an_effect_file_is_code(capsys):
    with pytest.raises(SystemExit):
        main(["frf", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "The file is CODE: eap imports and runs it with your rights" in out


# ------------------------------------------------------------------ 7. messages name the user's files and flags
def test_messages_name_flags_and_records_not_internals(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    tone = ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone", "--fs-Hz", "100",
            "--duration-s", "2", "--out", "D"]
    assert main(tone + ["--frequency-Hz", "80"]) == 2
    assert "--frequency-Hz 80 Hz must be positive and below the Nyquist frequency 50 Hz (half of --fs-Hz 100 Hz)" \
        in _err(capsys)
    from physics.analysis import metrics
    flat = np.full(1000, 1e-4)             # constant, its mean rounded: NRMSE was 2.7e18 %
    with pytest.raises(InputError, match="rec.csv: the measured deflection is constant"):
        metrics.summary(flat, np.arange(1000.0), names=("rec.csv: the measured deflection", "model"))
    assert final_text("/w/.D.eap-tmp-12/a.csv /w/.eap-tmp-3-ab_cd/f.yaml /w/.f.json.ab12cd_9.part") == \
        "/w/D/a.csv /w/f.yaml /w/f.json"
    from physics.io.fileio import write_json        # record keys of a diagnosis read from an output being written
    write_json(tmp_path / "d.json", {"records": {"/w/.DM.eap-tmp-77/m/r.csv": 1}})
    assert json.loads((tmp_path / "d.json").read_text()) == {"records": {"/w/DM/m/r.csv": 1}}


def test_a_start_on_its_bound_is_inside_it():
    """A drafted effect was dropped with "0.212 s is outside [0.212, …]": a start equal to its
    bound up to rounding is inside; a start truly outside is shown with the digits that differ."""
    from physics.contract import _outside
    assert not _outside(0.21199999999999999, 0.212, 1.0) and not _outside(1.0000000000000002, 0.1, 1.0)
    assert _outside(0.2119, 0.212, 1.0) == "0.2119 outside [0.212, 1]"
