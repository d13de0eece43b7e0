"""The physics commands of the `eap` command line, end to end."""
import json

import numpy as np
import pytest

from nnmodel.app.cli import main
from physics.io.timeseries import read_timeseries


def test_simulate_writes_a_readable_time_series_and_plots(tmp_path, capsys):
    out = tmp_path / "sim"
    rc = main(["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone",
               "--frequency-Hz", "2", "--duration-s", "3", "--fs-Hz", "200", "--fields", "voltage",
               "--out", str(out)])
    assert rc == 0
    ts = read_timeseries(out / "simulation.csv")
    assert ts.n == 600 and ts.fs == pytest.approx(200.0)
    assert np.all(ts.rh == 60.0) and np.ptp(ts.deflection) > 0
    assert (out / "simulation.png").stat().st_size > 1000
    summary = json.loads((out / "summary.json").read_text())
    assert "fractional_coupling" in summary["effects"]
    with np.load(out / "fields.npz", allow_pickle=False) as f:
        assert f["voltage"].shape[1] == 600
    assert "wrote" in capsys.readouterr().out


def test_simulate_from_an_input_file_never_overwrites_it(tmp_path):
    src = tmp_path / "in.csv"
    t = np.arange(0, 1, 0.01)
    src.write_text("time_s,voltage_V,rh_pct\n" + "\n".join(f"{a},{np.sin(6 * a)},55" for a in t))
    before = src.read_text()
    assert main(["simulate", "--device", "ipmc_pt_eg", "--input", str(src), "--out", str(tmp_path)]) == 2
    assert src.read_text() == before  # an output folder holding the input is refused
    assert main(["simulate", "--device", "ipmc_pt_eg", "--input", str(src), "--out", str(tmp_path / "o")]) == 0
    assert src.read_text() == before
    assert read_timeseries(tmp_path / "o" / "simulation.csv").rh[0] == 55.0


def test_frf_json_csv_and_plot(tmp_path):
    j, c, p = tmp_path / "f.json", tmp_path / "f.csv", tmp_path / "f.png"
    assert main(["frf", "--device", "ipmc_pt_eg", "--rh", "80", "--points", "50", "--json", str(j),
                 "--csv", str(c), "--plot", str(p)]) == 0
    data = json.loads(j.read_text())
    assert len(data["freq_Hz"]) == 50 and data["rh_pct"] == 80
    assert p.stat().st_size > 1000
    from physics.io.frfdata import read_frf
    assert read_frf(c).freq.size == 50


def test_effects_lists_every_effect(capsys):
    from physics.effects import EFFECTS
    assert main(["effects", "--device", "ipmc_pt_eg"]) == 0
    out = capsys.readouterr().out
    for eid in EFFECTS:
        assert eid in out
    assert main(["effects", "--explain", "solvent_diffusion"]) == 0
    assert "back-relaxation" in capsys.readouterr().out


def test_bad_options_give_one_clear_error(tmp_path, capsys):
    rc = main(["frf", "--device", "ipmc_pt_eg", "--effects", "magic", "--json", str(tmp_path / "x.json")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "unknown effect(s) magic" in err and "Traceback" not in err
    assert main(["frf", "--device", "ipmc_pt_eg", "--effects", "humidity", "--json", str(tmp_path / "y.json")]) == 2
    assert "give --rh" in capsys.readouterr().err


def test_top_level_help_lists_every_command(capsys):
    import pytest as _pytest
    with _pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    commands = ("run", "simulate", "frf", "effects", "generate", "train-compare", "predict", "compare",
                "identify", "diagnose", "validate", "benchmark", "demo")
    for cmd in commands:
        assert cmd in out
    for cmd in commands:            # every command's own help renders (argparse %-formats it)
        with _pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0


def test_param_overrides_geometry_with_units(tmp_path, capsys):
    """--param L_total=…mm: the first resonance follows 1/L² of the free length (beam theory)."""
    import json
    from physics.device import load_device
    d = load_device("ipmc_pt_eg")
    Lc, L0 = d["L_clamp"], d["L_total"] - d["L_clamp"]
    L1 = 1.5 * L0
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["frf", "--effects", "none", "--rh", "60", "--f-max-Hz", "300", "--json", str(a)]) == 0
    assert main(["frf", "--effects", "none", "--rh", "60", "--f-max-Hz", "300", "--json", str(b), "--param",
                 f"L_total={1e3 * (Lc + L1)!r}mm"]) == 0
    assert "from --param" in capsys.readouterr().err
    fa = json.loads(a.read_text())["natural_frequencies_Hz"][0]
    fb = json.loads(b.read_text())["natural_frequencies_Hz"][0]
    assert fa / fb == pytest.approx((L1 / L0) ** 2, rel=1e-6)
    assert main(["frf", "--param", "L_total=4kg", "--json", str(b)]) == 2
    assert "not compatible" in capsys.readouterr().err


def test_long_compare_reports_its_stages_unless_quiet(tmp_path, capsys, monkeypatch):
    """Inputs above LONG_INPUT_BYTES get a line per stage on stderr; --quiet silences them;
    short inputs print none (their error messages stay the first line)."""
    from nnmodel.app.commands import _common
    assert main(["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone",
                 "--frequency-Hz", "2", "--duration-s", "3", "--fs-Hz", "200", "--out", str(tmp_path / "sim")]) == 0
    rec = tmp_path / "sim" / "simulation.csv"
    capsys.readouterr()
    base = ["compare", str(rec), "--model", "ip2c_pedot_water"]
    assert main(base + ["--out", str(tmp_path / "a")]) == 0
    assert "[compare" not in capsys.readouterr().err
    monkeypatch.setattr(_common, "LONG_INPUT_BYTES", 1)
    assert main(base + ["--out", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err
    assert "[compare" in err and "samples" in err and "writing the report" in err
    assert main(base + ["--out", str(tmp_path / "c"), "--quiet"]) == 0
    assert "[compare" not in capsys.readouterr().err
