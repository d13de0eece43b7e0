"""Hostile inputs, round two (issue 27) and lab files as they are (issue 25 parts 1 and 5):
nothing a user owns is touched, datasets are closed worlds, resources are bounded, results
are physics or an error, and any output quantity goes through with its name and unit.

Named cases first, then property tests (Hypothesis) of the column map, YAML, JSON, dataset
descriptions and bundle cards: whatever the input, the package answers with its own
:class:`InputError` (one message) or reads it exactly — never another exception."""
from __future__ import annotations

import hashlib
import json
import os
import string
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nnmodel.app.cli import main
from physics.errors import InputError, ModelError
from physics.io.fileio import MAX_DEPTH, load_json
from physics.io.outputs import MARKER, REGISTRY, output_files, output_folder
from physics.io.timeseries import parse_column_map, read_timeseries
from physics.io.yamlio import loads_yaml

HERE = Path(__file__).resolve().parents[1]
SIM = ["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone", "--duration-s", "1",
       "--fs-Hz", "50"]
FRF = ["frf", "--device", "ip2c_pedot_water", "--rh", "60", "--points", "20"]


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _record(path: Path, n: int = 400, fs: float = 100.0, header=("time_s", "voltage_V", "deflection_m", "rh_pct"),
            scale: float = 1e-4, offset: float = 0.0, sep: str = ",") -> Path:
    t = np.arange(n) / fs
    v = np.sin(2 * np.pi * 1.3 * t) + 0.2 * np.sin(2 * np.pi * 7.1 * t)
    y = scale * np.sin(2 * np.pi * 1.3 * t - 0.3) + offset
    cols = [t, v, y, np.full(n, 60.0)][:len(header)]
    path.write_text(sep.join(header) + "\n" + "".join(sep.join(repr(float(x)) for x in row) + "\n"
                                                      for row in zip(*cols)))
    return path


def _err(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    return err.splitlines()[-1] if err else ""


# ------------------------------------------------------------------ 1. ownership, not folders
def test_overwrite_replaces_only_what_eap_wrote(tmp_path):
    out = tmp_path / "o"
    with output_folder(out) as d:
        (d / "train").mkdir()
        (d / "train" / "a.csv").write_text("1")
        (d / "summary.json").write_text("{}")
    files = json.loads((out / MARKER).read_text())["files"]
    assert set(files) == {"train/a.csv", "summary.json"} and files["summary.json"] == _sha(out / "summary.json")
    for rel in ("notes.txt", "train/mine.txt"):          # a file the user put there afterwards
        (out / rel).write_text("mine")
        with pytest.raises(InputError, match=rel.replace(".", r"\.")):
            with output_folder(out, overwrite=True):
                pass
        assert (out / rel).read_text() == "mine"
        (out / rel).unlink()
    (out / "summary.json").write_text('{"edited": 1}')   # a file eap wrote, edited by the user: now theirs
    with pytest.raises(InputError, match="summary.json"):
        with output_folder(out, overwrite=True):
            pass
    (out / "summary.json").write_text("{}")
    (out / "empty").mkdir()                                  # even an empty folder the user made
    with pytest.raises(InputError, match="empty/"):
        with output_folder(out, overwrite=True):
            pass
    (out / "empty").rmdir()
    with output_folder(out, overwrite=True) as d:          # only eap's files: replaced
        (d / "new.txt").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "new.txt"]


def test_inputs_inside_the_output_folder_are_never_replaced(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    d = tmp_path / "D"
    assert main(SIM + ["--out", str(d)]) == 0
    dev = d / "mydev.yaml"
    dev.write_bytes((HERE / "configs/devices/ip2c_pedot_water.yaml").read_bytes())
    creep = d / "my_gain.py"     # an effect of its own id (the registry outlives a main() call)
    creep.write_text(EFFECT.format(body="return [2.0], [1.0]").replace('"broken"', '"my_gain"'))
    before = {p: p.read_bytes() for p in (dev, creep)}
    argv = ["simulate", "--device", str(dev), "--rh", "60", "--signal", "tone", "--duration-s", "1", "--fs-Hz", "50",
            "--out", str(d), "--overwrite"]
    assert main(argv) == 2 and "mydev.yaml" in _err(capsys)
    from physics.effects import unregister
    try:
        assert main(SIM + ["--effects", "default,+my_gain", "--effects-path", str(creep), "--out", str(d),
                           "--overwrite"]) == 2
    finally:
        unregister("my_gain")
    assert "my_gain.py" in _err(capsys)
    assert all(p.read_bytes() == b for p, b in before.items())


def test_file_outputs_follow_the_same_rules(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    dev = tmp_path / "mydev.yaml"
    dev.write_bytes((HERE / "configs/devices/ip2c_pedot_water.yaml").read_bytes())
    mine = tmp_path / "mine.json"
    mine.write_text('{"mine": 1}')
    snapshot = {p: p.read_bytes() for p in (dev, mine)}
    cases = [(["frf", "--device", str(dev), "--rh", "60", "--json", str(dev), "--overwrite"], "input of this run"),
             (FRF + ["--json", str(mine)], "--overwrite"),
             (FRF + ["--json", str(mine), "--overwrite"], "not written by eap"),
             (FRF + ["--json", "."], "is a folder"),
             (FRF + ["--json", "/proc/self/x.json"], "--json /proc/self/x.json"),
             (FRF + ["--json", "a.json", "--csv", "a.json"], "--csv a.json: the FRF table is written as CSV"),
             (FRF + ["--json", "b.csv", "--csv", "b.csv"], "same file")]
    for argv, message in cases:
        assert main(argv) == 2, argv
        assert message in _err(capsys), argv
    assert all(p.read_bytes() == b for p, b in snapshot.items())
    assert main(FRF + ["--json", "f.json", "--csv", "f.csv", "--plot", "f.png"]) == 0
    capsys.readouterr()
    reg = json.loads((tmp_path / REGISTRY).read_text())["files"]
    assert set(reg) == {"f.json", "f.csv", "f.yaml", "f.png"} and reg["f.csv"]["sha256"] == _sha(tmp_path / "f.csv")
    assert main(FRF + ["--json", "f.json"]) == 2 and "--overwrite" in _err(capsys)
    assert main(FRF + ["--json", "f.json", "--overwrite"]) == 0       # its own earlier output
    (tmp_path / "f.json").write_text("edited by hand")
    assert main(FRF + ["--json", "f.json", "--overwrite"]) == 2 and "not written by eap" in _err(capsys)


def test_a_users_sidecar_beside_a_csv_output_is_never_taken_over(tmp_path):
    side = tmp_path / "p.yaml"
    side.write_text("my: notes\n")
    with pytest.raises(InputError, match=r"p\.yaml"):
        with output_files([tmp_path / "p.csv"], overwrite=True):
            pass
    assert side.read_text() == "my: notes\n" and not (tmp_path / "p.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".eap-tmp")]


# ------------------------------------------------------------------ 2. a dataset is a closed world
@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from nnmodel.measured import build_dataset
    root = tmp_path_factory.mktemp("ds")
    a = _record(root / "a.csv", n=600)
    (root / "a.yaml").write_text("sensor: {model: Keyence LK-G5001, bandwidth_Hz: 1000, noise_rms_um: 0.5}\n")
    return build_dataset(root / "DS", train=[f"{a}[0:400]"], test=[f"{a}[400:600]"])


def _copy(src: Path, dst: Path) -> Path:
    import shutil
    shutil.copytree(src, dst, symlinks=True)
    return dst


def _edit(ds: Path, fn) -> None:
    mf = ds / "dataset.json"
    meta = json.loads(mf.read_text())
    fn(meta)
    mf.write_text(json.dumps(meta))


def test_the_sensor_and_noise_floor_reach_the_dataset(dataset):
    meta = json.loads((dataset / "dataset.json").read_text())
    assert meta["noise_floor_m"] == pytest.approx(0.5e-6)
    assert meta["sensor"] == {"model": "Keyence LK-G5001", "bandwidth": 1000.0, "deflection_noise": 5e-07,
                              "noise_floor_m": 5e-07}
    assert all(e["sidecar_sha256"] for e in meta["files"])


@pytest.mark.parametrize("case,message", [
    ("dotdot", "relative, no '..'"), ("absolute", "relative, no '..'"), ("passwd", "relative, no '..'"),
    ("symlink", "symbolic link"), ("sidecar", r"\.yaml: content differs"), ("duplicate", "listed twice"),
    ("no-sha", "sha256 None"), ("fs", "fs_Hz -1"), ("entry", "must be an object"), ("files", "non-empty list"),
    ("added-sidecar", "does not list")])
def test_a_dataset_never_reads_outside_its_folder(dataset, tmp_path, case, message):
    from nnmodel.dataset import load_dataset
    ds = _copy(dataset, tmp_path / "DS")
    outside = _record(tmp_path / "outside.csv")
    first = lambda m: m["files"][0]  # noqa: E731
    rel = json.loads((ds / "dataset.json").read_text())["files"][0]["path"]
    if case == "dotdot":
        _edit(ds, lambda m: first(m).update(path="../outside.csv", sha256=_sha(outside)))
    elif case == "absolute":
        _edit(ds, lambda m: first(m).update(path=str(outside), sha256=_sha(outside)))
    elif case == "passwd":
        _edit(ds, lambda m: first(m).update(path="../../../../../../etc/passwd", sha256=_sha(Path("/etc/passwd"))))
    elif case == "symlink":
        (ds / rel).unlink()
        (ds / rel).symlink_to(outside)
        _edit(ds, lambda m: first(m).update(sha256=_sha(outside)))
    elif case == "sidecar":
        side = (ds / rel).with_suffix(".yaml")
        side.write_text(side.read_text().replace("noise_floor_m: 5.0e-07", "noise_floor_m: 0.5"))
    elif case == "duplicate":
        _edit(ds, lambda m: m["files"].append(dict(first(m))))
    elif case == "no-sha":
        _edit(ds, lambda m: first(m).pop("sha256"))
    elif case == "fs":
        _edit(ds, lambda m: m.update(fs_Hz=-1))
    elif case == "entry":
        _edit(ds, lambda m: m["files"].__setitem__(0, [1, 2]))
    elif case == "files":
        _edit(ds, lambda m: m.update(files={"a": 1}))
    elif case == "added-sidecar":
        _edit(ds, lambda m: first(m).update(sidecar_sha256=None))
    with pytest.raises(InputError, match=message):
        load_dataset(ds)
    assert main(["dataset", "--check", str(ds)]) == 2


def test_overlapping_or_identical_records_are_refused_unless_allowed(tmp_path, capsys):
    a = _record(tmp_path / "a.csv", n=600)
    copy = tmp_path / "copy.csv"
    copy.write_bytes(a.read_bytes())
    for parts in ([f"{a}[0:400]", "--test", f"{a}[300:600]"], [str(a), "--test", str(a)],
                  [str(a), "--test", str(copy)], [str(a), str(a)]):
        assert main(["dataset", "--train", *parts, "--out", str(tmp_path / "D")]) == 2, parts
        assert "share samples" in _err(capsys) and not (tmp_path / "D").exists()
    assert main(["dataset", "--train", f"{a}[0:400]", "--test", f"{a}[300:600]", "--allow-overlap", "--out",
                 str(tmp_path / "D")]) == 0
    meta = json.loads((tmp_path / "D" / "dataset.json").read_text())
    assert meta["overlap"] == [{"records": ["train/a_0-400.csv", "test/a_300-600.csv"], "samples": [300, 400]}]
    assert all(e.get("overlap") for e in meta["files"])


def test_a_column_mapped_twice_and_a_constant_record_are_refused(tmp_path, capsys):
    for text in ("voltage=V1,deflection=V1", "voltage=y:V,deflection=y", "voltage=u,voltage=y"):
        with pytest.raises(InputError, match="twice|both"):
            parse_column_map(text)
    flat = _record(tmp_path / "flat.csv", scale=0.0, offset=1e-4)
    assert main(["dataset", "--train", str(flat), "--out", str(tmp_path / "D")]) == 2
    err = _err(capsys)
    assert "flat.csv" in err and "deflection is constant" in err


# ------------------------------------------------------------------ 3. every resource bounded
def test_workers_and_scheduler_addresses_are_checked_before_work(monkeypatch):
    from physics.execution.parallel import ParallelSettings, cores
    with pytest.raises(InputError, match=f"workers {cores() + 1}: this machine gives {cores()} core"):
        ParallelSettings(cores() + 1)
    assert ParallelSettings(1000, "tcp://10.0.0.5:8786").workers == 1000   # a cluster sizes itself
    for bad in ("not a url", "tcp://", "http://example.com", "tcp://host:99999", "tcp://host"):
        with pytest.raises(InputError, match="not a Dask scheduler address"):
            ParallelSettings(1, bad)
    monkeypatch.setenv("EAP_SCHEDULER", "::garbage::")
    with pytest.raises(InputError, match="EAP_SCHEDULER"):
        ParallelSettings.resolve(1, None)


def test_a_closed_scheduler_port_is_a_clear_error():
    from physics.execution.parallel import ParallelSettings, map_tasks
    with pytest.raises(InputError, match=r"scheduler tcp://127\.0\.0\.1:1: cannot connect"):
        map_tasks(abs, [1, 2], ParallelSettings(1, "tcp://127.0.0.1:1"), progress=False)


@pytest.mark.parametrize("argv,message", [
    (FRF + ["--n-modes", "1000000", "--json", "f.json"], "--n-modes 1000000: must be a whole number within 1–64"),
    (FRF + ["--f-max-Hz", "1e300", "--json", "f.json"], "--f-max-Hz 1e+300: must lie within"),
    (FRF + ["--points", "1000000000", "--json", "f.json"], "--points 1000000000"),
    (SIM + ["--amplitude-V", "1e6", "--out", "S"], "--amplitude-V 1000000.0: must lie within 0–1000"),
    (SIM + ["--fs-Hz", "1e300", "--out", "S"], "--fs-Hz 1e+300"),
    (SIM + ["--duration-s", "1e9", "--out", "S"], "samples; a record needs 16 to 2e+07"),
])
def test_sizes_are_refused_before_allocating(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in _err(capsys)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("text,message", [
    ("a: " + "[" * 3000 + "]" * 3000, "nested more than"), ("a: 1\na: 2\n", "key 'a' appears twice"),
    ("x: !!python/object/apply:os.system [ls]\n", "could not determine a constructor"),
    ("a: &x [1]\nb: *x\n", "anchors")], ids=["deep", "repeated-key", "python-tag", "alias"])
def test_yaml_is_bounded_and_unambiguous(text, message):
    with pytest.raises(InputError, match=message):
        loads_yaml(text, "f.yaml")


@pytest.mark.parametrize("text,message", [
    ('{"a": ' + "[" * 3000 + "]" * 3000 + "}", "nested more than"), ('{"a": 1, "a": 2}', "appears twice"),
    ('{"fs_Hz": NaN}', "NaN is not a number"), ("{not json", "not valid JSON"), (b'{"a": "\xff"}', "not UTF-8")],
    ids=["deep", "repeated-key", "nan", "broken", "latin-1"])
def test_json_is_bounded_and_unambiguous(tmp_path, text, message):
    p = tmp_path / "x.json"
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    with pytest.raises(InputError, match=message):
        load_json(p)
    assert MAX_DEPTH >= 8   # every description the package writes nests less


# ------------------------------------------------------------------ 4. physics or an error
EFFECT = '''from physics.effects import OutputEffect
from physics.parameters import ParamSpec

class Broken(OutputEffect):
    id = "broken"
    summary = "a broken user effect"
    params = (ParamSpec("broken_k", "1", -1e9, 1e9, "gain", optional=True, default=1.0),)

    def output_tf(self, p):
        {body}
'''


@pytest.mark.parametrize("body,check", [
    ("return [float('nan')], [1.0]", "finite"), ("return [1.0], [0.0]", "finite"),
    ("return 'not a transfer function'", "finite"), ("raise ZeroDivisionError('boom')", "boom"),
    ("return [1.0], [1.0, -5.0]", "stable"), ("return [1.0, 0.0, 0.0], [1.0]", "improper")])
def test_a_broken_user_effect_is_refused_when_loaded(tmp_path, body, check):
    from physics.effects import EFFECTS, load_effects_file
    f = tmp_path / "eff.py"
    f.write_text(EFFECT.format(body=body))
    with pytest.raises(InputError, match=rf"eff\.py: effect 'broken' fails the contract check .*{check}"):
        load_effects_file(f)
    assert "broken" not in EFFECTS


def test_an_effect_file_that_exits_is_reported(tmp_path, capsys):
    f = tmp_path / "exits.py"
    f.write_text("import sys\nsys.exit(0)\n")
    assert main(FRF + ["--json", str(tmp_path / "f.json"), "--effects-path", str(f)]) == 2
    assert "exits.py: importing it called sys.exit(0)" in _err(capsys)
    assert not (tmp_path / "f.json").exists()


def test_non_finite_and_non_physical_inputs_are_errors(tmp_path):
    from physics.io.frfdata import read_frf
    h = tmp_path / "h.csv"
    h.write_text("freq_Hz,mag_m_per_V,phase_deg\n" + "".join(f"{f},1e297,-10\n" for f in (0.1, 1.0, 10.0)))
    with pytest.raises(InputError, match=r"h\.csv, line 2, column 'mag_m_per_V': value 1e\+297 is outside 0–1000 m/V"):
        read_frf(h)
    for step in ("1e288", "1e-302"):
        p = tmp_path / f"s{step}.csv"
        p.write_text("time_s,voltage_V,deflection_m,rh_pct\n" + "".join(
            f"{i}{'e' + step.split('e')[1]},{np.sin(i / 3):.4f},{1e-5 * np.sin(i / 3):.3e},60\n" for i in range(40)))
        with pytest.raises(InputError, match="sampling rate of .* Hz, outside 1e-06–1e\\+09 Hz"):
            read_timeseries(p)


def test_predict_refuses_an_unwritable_target_before_any_work(tmp_path, capsys):
    rec = _record(tmp_path / "rec.csv")
    assert main(["predict", "--model", str(tmp_path / "nope"), "--input", str(rec), "--out", "/proc/self/x.csv"]) == 2
    assert "--out /proc/self/x.csv" in _err(capsys)


# ------------------------------------------------------------------ smaller items
def test_the_smaller_items(tmp_path, capsys):
    p = tmp_path / "rec.csv"
    p.write_text("time_s,voltage_V,deflection_m,rh_pct\n" + "".join(f"0,{i},0,5,0,0001,60\n" for i in range(20)))
    with pytest.raises(InputError, match=r"rec\.csv, line 2: 7 fields but the header has 4 .*a decimal comma needs"):
        read_timeseries(p)
    rec = _record(tmp_path / "r.csv")
    for sidecar, message in (("excitation: {kind: 5}\n", "excitation.kind: 5 is not valid"),
                             ("rh_pct: 60\nrh_pct: 20\n", "appears twice")):
        (tmp_path / "r.yaml").write_text(sidecar)
        with pytest.raises(InputError, match=message):
            read_timeseries(rec)
    (tmp_path / "r.yaml").unlink()
    big = _record(tmp_path / "big.csv", n=4000)
    big.write_bytes(big.read_bytes() + "1.0,0.1,1e-5,60 \xe9\n".encode("latin-1"))   # after the sniffed head
    with pytest.raises(InputError, match=r"big\.csv, line 4002, column 'rh_pct': '60 é' is not a number"):
        read_timeseries(big)


def test_a_task_fails_with_the_users_message_alone():
    from physics.execution.parallel import ParallelSettings, _run_batch, map_tasks
    with pytest.raises(InputError) as err:
        map_tasks(_bad_input, [{"name": "ff", "overrides": {"lr": 1}, "dataset": "/x"}], ParallelSettings(),
                  progress=False)
    assert str(err.value) == "value 5.2 is outside -1–1 m"
    ok, (k, exc) = _run_batch(_bad_input, [{"name": "ff"}])   # what a worker process sends back
    assert not ok and isinstance(exc, InputError) and str(exc) == "value 5.2 is outside -1–1 m"
    with pytest.raises(ModelError, match=r"task 'ff' failed: KeyError"):
        map_tasks(_bug, [{"name": "ff", "data": list(range(1000))}], ParallelSettings(), progress=False)


def _bad_input(task):
    raise InputError("value 5.2 is outside -1–1 m")


def _bug(task):
    raise KeyError("sha256")


# ------------------------------------------------------------------ issue 25: any quantity, lab files
def test_a_level_in_volts_goes_through_with_its_name_and_unit(tmp_path, capsys):
    lab = _record(tmp_path / "lab.csv", header=("t", "u", "y"), scale=2.0, offset=5.0, n=800)
    base = ["dataset", "--train", f"{lab}[0:600]", "--test", f"{lab}[600:800]", "--columns",
            "time=t,voltage=u,deflection=y", "--out", str(tmp_path / "D")]
    assert main(base) == 2                      # 5 "m" of tip deflection: refused at import, with the way out
    err = _err(capsys)
    assert "lab.csv, line 2, column 'y' (output): value 4.4" in err and "--output NAME:UNIT" in err
    assert main(base + ["--output", "level:V"]) == 0
    assert "output level [V]" in capsys.readouterr().out
    from nnmodel.dataset import load_dataset
    ds = load_dataset(tmp_path / "D")
    assert ds.output.to_dict() == {"name": "level", "unit": "V"}
    assert (tmp_path / "D" / ds.entries("train")[0]["path"]).read_text().startswith("time_s,voltage_V,level_V\n")
    rec = ds.records("train")[0]
    assert rec.y.min() > 2.9 and rec.y.max() < 7.1          # read back in volts, once, with the same rule


def test_column_units_from_the_map_or_the_header_said_aloud(tmp_path, capsys):
    tip = _record(tmp_path / "tip.csv", header=("Time [s]", "Drive (V)", "Tip (mm)"), scale=0.1)
    for spec in ("deflection=Tip (mm):mm", "deflection=Tip (mm)"):
        out = tmp_path / ("D" + str(len(spec)))
        assert main(["dataset", "--train", str(tip), "--columns", f"time=Time [s],voltage=Drive (V),{spec}",
                     "--rh", "50", "--out", str(out)]) == 0
        err = capsys.readouterr().err
        assert ("read as the tip deflection in mm (the unit in its header)" in err) == spec.endswith("(mm)")
        from nnmodel.dataset import load_dataset
        y = load_dataset(out).records("train")[0].y
        assert np.max(np.abs(y)) == pytest.approx(1e-4, rel=0.05)   # 0.1 mm, not 0.1 m
    assert main(["dataset", "--train", str(tip), "--columns", "time=Time [s],voltage=Drive (V),deflection=Tip (mm):um",
                 "--rh", "50", "--out", str(tmp_path / "X")]) == 2
    assert "mapped with unit um but its header says mm" in _err(capsys)
    with pytest.raises(InputError, match=r"column 'U' \(mapped to voltage\) is missing.*columns"):
        read_timeseries(tip, columns={"time": "Time [s]", "voltage": "U", "deflection": "Tip (mm)"}, rh=50)


def test_a_sensor_gain_turns_volts_into_metres(tmp_path):
    lab = _record(tmp_path / "lab.csv", header=("t", "u", "y"), scale=2.0, offset=0.0)
    ts = read_timeseries(lab, columns=parse_column_map("time=t,voltage=u,deflection=y:V"), rh=50, gain="0.5mm/V")
    assert ts.output.is_deflection and np.max(np.abs(ts.deflection)) == pytest.approx(1e-3, rel=0.02)
    with pytest.raises(InputError, match="the sensor gain is per mV"):
        read_timeseries(lab, columns=parse_column_map("time=t,voltage=u,deflection=y:V"), rh=50, gain="0.5mm/mV")


def test_sidecar_spellings_are_read_into_stored_names(tmp_path):
    rec = _record(tmp_path / "r.csv")
    (tmp_path / "r.yaml").write_text("sensor:\n  model: Keyence LK-G5001\n  bandwidth_kHz: 1\n  noise_rms_um: 2\n"
                                     "  resolution_nm: 10\ndescription: free text\n")
    meta = read_timeseries(rec).meta
    assert meta["sensor"]["bandwidth"] == 1000.0 and meta["sensor"]["deflection_noise"] == pytest.approx(2e-6)
    assert meta["sensor"]["noise_floor_m"] == pytest.approx(np.sqrt(4e-12 + 1e-16 / 12))
    (tmp_path / "r.yaml").write_text("sensor: laser triangulation, Keyence LK-G\n")
    assert read_timeseries(rec).meta["sensor"] == {"description": "laser triangulation, Keyence LK-G"}
    (tmp_path / "r.yaml").write_text("sensor: {noise_rms_furlong: 3}\n")
    with pytest.raises(InputError, match=r"r\.yaml: sensor\.noise_rms_furlong: unknown unit symbol 'furlong'"):
        read_timeseries(rec)


def test_predict_takes_a_column_map_and_names_its_output_column(tmp_path, capsys):
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    t = np.arange(600) / 100.0
    u = np.sin(2 * np.pi * 0.7 * t)
    y = 5.0 + 0.5 * np.sin(2 * np.pi * 0.7 * t - 0.4)
    m = MODELS["rbf"](n_centres=6, nb=4, na=1, progress_bar=False)
    m.fit([Experiment(u=u, y=y, rh=None, fs=100.0)], None)
    bundle = save(m, tmp_path / "b", output=("level", "V"))
    lab = tmp_path / "lab.csv"
    lab.write_text("t,u\n" + "".join(f"{a},{b}\n" for a, b in zip(t, u)))
    out = tmp_path / "p.csv"
    assert main(["predict", "--model", str(bundle), "--input", str(lab), "--out", str(out)]) == 2
    assert "--columns time=t,voltage=u" in _err(capsys)
    assert main(["predict", "--model", str(bundle), "--input", str(lab), "--columns", "time=t,voltage=u", "--out",
                 str(out)]) == 0
    assert "(level_V)" in capsys.readouterr().out
    assert out.read_text().splitlines()[0] == "time_s,voltage_V,level_V"


def test_a_long_record_is_predicted_in_pieces_with_the_same_result(tmp_path, capsys, monkeypatch):
    """Memory per sample: a long input is read, predicted and written piece by piece (the
    memory filters and the core's state carry over), giving the whole-record prediction."""
    import nnmodel.app.commands.predict as predict_cmd
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    rng = np.random.default_rng(0)
    u = np.convolve(rng.normal(size=3000), np.ones(8) / 8, "same")
    y = np.convolve(u, np.exp(-np.arange(30) / 6.0), "full")[:u.size] * 1e-5
    m = MODELS["ff"](nb=4, na=2, hidden=6, layers=1, memory_filters=3, max_epochs=2, progress_bar=False)
    m.fit([Experiment(u=u, y=y, rh=None, fs=100.0)], None)
    bundle = save(m, tmp_path / "ff")
    rec = tmp_path / "long.csv"
    t = np.arange(5003) / 100.0
    v = np.sin(2 * np.pi * 0.37 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t)
    rec.write_text("time_s,voltage_V\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, v)))
    argv = ["predict", "--model", str(bundle), "--input", str(rec), "--rh", "50"]
    assert main(argv + ["--out", str(tmp_path / "whole.csv")]) == 0
    monkeypatch.setattr(predict_cmd, "STREAM_BYTES", 0)
    monkeypatch.setattr(predict_cmd, "STREAM_SAMPLES", 1000)
    assert main(argv + ["--out", str(tmp_path / "pieces.csv")]) == 0
    capsys.readouterr()
    import pandas as pd
    whole, pieces = pd.read_csv(tmp_path / "whole.csv"), pd.read_csv(tmp_path / "pieces.csv")
    assert list(whole.columns) == list(pieces.columns) and len(whole) == len(pieces) == 5003
    np.testing.assert_array_equal(whole["time_s"], pieces["time_s"])
    np.testing.assert_allclose(pieces["deflection_m"], whole["deflection_m"], rtol=1e-6,
                               atol=1e-6 * np.abs(whole["deflection_m"]).max())   # float32 rounding only
    import yaml
    assert yaml.safe_load((tmp_path / "pieces.yaml").read_text())["prediction"]["in_pieces"] is True


# ------------------------------------------------------------------ property tests
_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "cm": 1e-2, "nm": 1e-9}


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(unit=st.sampled_from(sorted(_UNITS)), where=st.sampled_from(["map", "paren", "bracket"]),
       name=st.text(alphabet=string.ascii_letters + " ", min_size=1, max_size=8).filter(lambda s: s.strip() == s),
       data=st.lists(st.floats(-5e-3, 5e-3, allow_nan=False, width=64), min_size=20, max_size=20))
def test_column_units_scale_exactly(tmp_path, unit, where, name, data):
    col = {"map": name, "paren": f"{name} ({unit})", "bracket": f"{name} [{unit}]"}[where]
    y = np.array(data) / _UNITS[unit]
    p = tmp_path / "r.csv"
    p.write_text(f"t;u;{col}\n" + "".join(f"{i * 0.1!r};{0.5 + i % 3!r};{float(v)!r}\n" for i, v in enumerate(y)))
    text = f"time=t,voltage=u,deflection={col}" + (f":{unit}" if where == "map" else "")
    ts = read_timeseries(p, columns=parse_column_map(text), rh=50)
    np.testing.assert_allclose(ts.deflection, y * _UNITS[unit], rtol=1e-12, atol=0)


_json = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12),
                               st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=12)),
                     lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4),
                     max_leaves=20)


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(["rh_pct", "signal", "excitation", "sensor", "geometry", "device", "x"]),
       value=_json, inner=st.sampled_from(["kind", "periods", "f_start_Hz", "bandwidth_Hz", "noise_rms_um",
                                           "noise_floor_m", "adc_bits", "model"]), as_section=st.booleans())
def test_any_sidecar_is_read_or_refused_with_its_name(tmp_path, key, value, inner, as_section):
    import yaml
    rec = tmp_path / "r.csv"
    if not rec.exists():
        _record(rec, n=40)
    doc = {key: {inner: value} if as_section else value}
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(doc))
    try:
        read_timeseries(rec)
    except InputError as exc:
        assert "r.yaml" in str(exc) or "r.csv" in str(exc)


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.lists(st.sampled_from(["files", 0, "path", "sha256", "split", "samples", "fs_Hz", "output",
                                      "rh_levels", "sidecar_sha256", "schema", "heldout_rh"]), min_size=1, max_size=3),
       value=_json)
def test_any_edit_of_dataset_json_loads_or_is_refused(dataset, tmp_path, path, value):
    from nnmodel.dataset import load_dataset
    ds = tmp_path / "DS"
    if not ds.exists():
        _copy(dataset, ds)
    meta = json.loads((dataset / "dataset.json").read_text())
    node = meta
    try:
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    except (KeyError, IndexError, TypeError):
        return
    (ds / "dataset.json").write_text(json.dumps(meta))
    try:
        d = load_dataset(ds)
        for e in d.entries():       # what loads is usable: every record reads inside the folder
            assert (ds / e["path"]).resolve().is_relative_to(ds.resolve())
    except InputError as exc:
        assert "dataset.json" in str(exc) or str(ds) in str(exc)


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    t = np.arange(300) / 100.0
    u = np.sin(2 * np.pi * 2 * t)
    m = MODELS["rbf"](n_centres=6, nb=4, na=1, progress_bar=False)
    m.fit([Experiment(u=u, y=1e-4 * np.sin(2 * np.pi * 2 * t - 0.3), rh=np.full(300, 60.0), fs=100.0)], None)
    return save(m, tmp_path_factory.mktemp("b") / "rbf")


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.lists(st.sampled_from(["hyper_parameters", "n_centres", "nb", "na", "fs_hz", "inputs", "output",
                                      "normalisation", "weights", "sha256", "format_version", "rh_range_pct"]),
                     min_size=1, max_size=2), value=_json)
def test_any_edit_of_a_bundle_card_loads_or_is_refused(bundle, tmp_path, path, value):
    import shutil

    from nnmodel.bundle import load
    b = tmp_path / "b"
    if b.exists():
        shutil.rmtree(b)
    shutil.copytree(bundle, b)
    card = json.loads((b / "card.json").read_text())
    node = card
    try:
        for k in path[:-1]:
            node = node[k]
        if not isinstance(node, dict):
            return
        node[path[-1]] = value
    except (KeyError, TypeError):
        return
    (b / "card.json").write_text(json.dumps(card))
    try:
        load(b)
    except InputError:
        pass


def test_a_card_whose_sizes_the_weights_contradict_is_refused_naming_them(tmp_path, monkeypatch, capsys):
    """A size within its cap but not the one the weights were trained with: the refusal names
    the card's sizes, not only torch's shape message."""
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    t = np.arange(300) / 100.0
    u = np.sin(2 * np.pi * 2 * t)
    m = MODELS["ff"](na=1, nb=4, hidden=4, layers=2, max_epochs=1, progress_bar=False)
    m.fit([Experiment(u=u, y=1e-4 * np.sin(2 * np.pi * 2 * t - 0.3), rh=np.full(300, 60.0), fs=100.0)], None)
    b = save(m, tmp_path / "ff")
    card = json.loads((b / "card.json").read_text())
    card["hyper_parameters"]["nb"] = 9
    (b / "card.json").write_text(json.dumps(card))
    _record(tmp_path / "r.csv")
    monkeypatch.chdir(tmp_path)
    assert main(["predict", "--model", "ff", "--input", "r.csv", "--out", "p.csv"]) == 2
    err = _err(capsys)
    assert "the card's sizes na=1, nb=9, hidden=4, layers=2" in err and not (tmp_path / "p.csv").exists(), err


def test_nothing_is_left_behind_by_refused_outputs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(SIM + ["--amplitude-V", "1e6", "--out", "S"]) == 2
    assert main(FRF + ["--json", "/proc/self/x.json"]) == 2
    capsys.readouterr()
    assert not [p for p in tmp_path.iterdir()], os.listdir(tmp_path)


@pytest.mark.parametrize("signame, code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_python_drops_in_a_gc_callback_still_stops_the_run(tmp_path, monkeypatch, capsys, signame, code):
    """Issue 27 audit: SIGTERM during `generate --workers 2` arrived inside Dask's gc callback,
    where Python prints an exception and carries on: the run finished with exit 0."""
    import gc
    import signal
    import sys

    from nnmodel.app import cli
    from physics.io import outputs
    real = outputs.preflight

    def dropped(phase, info):
        gc.callbacks.remove(dropped)
        cli._on_signal(getattr(signal, signame), None)

    armed = [True]

    def preflight(*a, **k):            # the signal lands in a gc callback once the run has begun (once:
        if armed:                      # a command may check its --out more than once)
            armed.clear()
            gc.callbacks.append(dropped)
            gc.collect()
        return real(*a, **k)
    monkeypatch.setattr(outputs, "preflight", preflight)
    monkeypatch.setattr(sys, "unraisablehook", lambda u: None)
    monkeypatch.chdir(tmp_path)
    try:
        assert main(SIM + ["--out", "S"]) == code
    finally:                           # nothing of the fake signal outlives the test
        if dropped in gc.callbacks:
            gc.callbacks.remove(dropped)
        outputs.INTERRUPTS.clear()
    assert _err(capsys) == "eap simulate: interrupted; nothing written to S"
    assert not [p for p in tmp_path.iterdir()], os.listdir(tmp_path)
