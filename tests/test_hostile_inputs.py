"""Bad input gets a clear error and loses nothing: the acceptance cases of the data-safety
issue (CSV dialects, finite nonsense, sidecars, bundles) and a property test of the reader."""
import json
import string

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nnmodel.app.cli import main
from physics.errors import InputError
from physics.io.timeseries import read_timeseries, read_timeseries_pieces

T = np.arange(300) / 100.0
V = np.sin(2 * np.pi * 2 * T)
D = 1e-4 * np.sin(2 * np.pi * 2 * T - 0.3)


def _write(path, sep=",", decimal=".", header=("time_s", "voltage_V", "deflection_m", "rh_pct"),
           rows=None, encoding="utf-8", newline="\n"):
    rows = rows if rows is not None else [(a, b, c, 60.0) for a, b, c in zip(T.tolist(), V.tolist(), D.tolist())]
    lines = [sep.join(header)] + [sep.join(repr(float(x)).replace(".", decimal) if not isinstance(x, str) else x
                                           for x in r) for r in rows]
    path.write_bytes((newline.join(lines) + newline).encode(encoding))
    return path


@pytest.mark.parametrize("sep,decimal,newline", [(";", ".", "\n"), ("\t", ".", "\n"), (";", ",", "\r\n"),
                                                 ("\t", ",", "\n"), (" ", ".", "\n")])
def test_common_csv_dialects_are_read_exactly(tmp_path, sep, decimal, newline):
    p = _write(tmp_path / "rec.csv", sep=sep, decimal=decimal, newline=newline)
    ts = read_timeseries(p)
    np.testing.assert_array_equal(ts.voltage, V)
    np.testing.assert_array_equal(ts.deflection, D)


@pytest.mark.parametrize("sep,decimal", [(",", "."), (";", ","), (";", "."), ("\t", ",")])
def test_comment_lines_above_the_header_are_skipped_and_later_lines_keep_their_numbers(tmp_path, sep, decimal):
    """A lab export with '# …' notes (and a blank line) above the header reads as the file without
    them, and an error further down names the file's own line (before, the comment was sniffed as a
    blank-separated header and line 2 was said to have the wrong number of fields)."""
    plain = _write(tmp_path / "plain.csv", sep=sep, decimal=decimal)
    p = tmp_path / "rec.csv"
    p.write_bytes(b"# exported by the lab\n#RH 60 %\n\n" + plain.read_bytes())
    ts = read_timeseries(p)
    np.testing.assert_array_equal(ts.time, read_timeseries(plain).time)
    np.testing.assert_array_equal(ts.deflection, D)
    pieces = list(read_timeseries_pieces(p, rows=100))        # the streaming reader of long records
    np.testing.assert_array_equal(np.concatenate([q.time for q in pieces]), ts.time)
    rows = [(a, b, c, 60.0) for a, b, c in zip(T.tolist(), V.tolist(), D.tolist())]
    rows[5] = rows[205] = (T[5], "x", D[5], 60.0)      # data rows 6 and 206: lines 7, 207 of the plain file
    bad = _write(tmp_path / "bad.csv", sep=sep, decimal=decimal, rows=rows)
    bad.write_bytes(b"# exported by the lab\n#RH 60 %\n\n" + bad.read_bytes())
    with pytest.raises(InputError, match=r"bad\.csv, line 10, column 'voltage_V': 'x' is not a number"):
        read_timeseries(bad)
    rows[5] = (T[5], V[5], D[5], 60.0)
    bad = _write(tmp_path / "bad.csv", sep=sep, decimal=decimal, rows=rows)
    bad.write_bytes(b"# exported by the lab\n#RH 60 %\n\n" + bad.read_bytes())
    with pytest.raises(InputError, match=r"bad\.csv, line 210, column 'voltage_V': 'x' is not a number"):
        list(read_timeseries_pieces(bad, rows=100))
    short = tmp_path / "short.csv"                     # a line with a field missing: line 6 of this file
    lines = plain.read_text().splitlines()
    lines[2] = sep.join(lines[2].split(sep)[:-1])
    short.write_text("# notes\n\n" + "\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"short\.csv, line 5: 3 fields but the header has 4"):
        read_timeseries(short)
    hashed = tmp_path / "hashed.csv"                   # the header itself commented out
    hashed.write_text("# " + plain.read_text())
    with pytest.raises(InputError, match=r"hashed\.csv, line 2: numbers where the header line .* remove its '#'"):
        read_timeseries(hashed)
    notes = tmp_path / "notes.csv"
    notes.write_text("# exported by the lab\n# nothing else\n")
    with pytest.raises(InputError, match=r"notes\.csv: only comment \('#'\) or blank lines"):
        read_timeseries(notes)


def test_latin1_file_is_read_and_a_bad_cell_is_named(tmp_path):
    rows = [(a, b, c, 60.0) for a, b, c in zip(T.tolist(), V.tolist(), D.tolist())]
    p = _write(tmp_path / "ok.csv", rows=rows, encoding="latin-1")
    assert read_timeseries(p).n == T.size
    rows[5] = (T[5], "1\xe9", D[5], 60.0)
    p = _write(tmp_path / "bad.csv", rows=rows, encoding="latin-1")
    with pytest.raises(InputError, match=r"bad\.csv, line 7, column 'voltage_V': '1é' is not a number"):
        read_timeseries(p)


def test_one_column_file_with_a_sampling_rate(tmp_path):
    p = tmp_path / "u.csv"
    p.write_text("voltage_V\n" + "\n".join(map(repr, V.tolist())) + "\n")
    ts = read_timeseries(p, fs=100.0, rh=50, require_deflection=False)
    np.testing.assert_allclose(ts.time, T)


@pytest.mark.parametrize("column,value,unit", [("deflection_m", 1e300, "m"), ("voltage_V", 1e6, "V")])
def test_finite_nonsense_is_refused_with_row_column_and_unit(tmp_path, column, value, unit):
    rows = [[a, b, c, 60.0] for a, b, c in zip(T.tolist(), V.tolist(), D.tolist())]
    rows[10][1 if column == "voltage_V" else 2] = value
    p = _write(tmp_path / "rec.csv", rows=rows)
    with pytest.raises(InputError, match=rf"line 12, column '{column}': value .* is outside .* {unit}"):
        read_timeseries(p)


def test_compare_on_nonsense_exits_cleanly_and_writes_nothing(tmp_path, capsys):
    rows = [[a, b, c, 60.0] for a, b, c in zip(T.tolist(), V.tolist(), D.tolist())]
    rows[3][2] = 1e300
    p = _write(tmp_path / "rec.csv", rows=rows)
    assert main(["compare", str(p), "--model", "ip2c_pedot_water", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("eap compare: error: ") and "Traceback" not in err
    assert not (tmp_path / "o").exists()
    short = _write(tmp_path / "short.csv", rows=rows[:2])
    assert main(["identify", str(short), "--device", "ipmc_pt_eg", "--free", "kf", "--out",
                 str(tmp_path / "i")]) == 2
    assert "needs at least" in capsys.readouterr().err and not (tmp_path / "i").exists()


@pytest.mark.parametrize("sidecar,message", [
    ("signal: {kind: sweep, f_start_Hz: abc}\n", r"signal\.f_start_Hz: 'abc' is not valid"),
    ("signal: {kind: multisine, periods: many}\n", r"signal\.periods: 'many' is not valid"),
    ("sensor: {deflection_noise: loud}\n", r"sensor\.deflection_noise: 'loud' is not"),
    ("sensor: {bandwidth: -3}\n", r"bandwidth"),
    ("rh_pct: 30\n", r"says rh_pct=30 but the column 'rh_pct' averages 60"),
    ("a: &x [1, 2]\nb: [*x, *x]\n", r"anchors \(&x\) are not allowed"),
    ("note: caf\xe9\n", r"not UTF-8 text"),
])
def test_sidecars_are_checked(tmp_path, sidecar, message):
    p = _write(tmp_path / "rec.csv")
    (tmp_path / "rec.yaml").write_bytes(sidecar.encode("latin-1"))
    with pytest.raises(InputError, match=message):
        read_timeseries(p)


def test_yaml_alias_bomb_is_refused_quickly(tmp_path):
    bomb = "a: &a [x,x,x,x,x,x,x,x,x]\n" + "".join(
        f"{c}: &{c} [*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
    p = _write(tmp_path / "rec.csv")
    (tmp_path / "rec.yaml").write_text(bomb)
    with pytest.raises(InputError, match="not allowed"):
        read_timeseries(p)


def test_sidecar_geometry_is_refused_not_ignored(tmp_path, capsys):
    p = _write(tmp_path / "rec.csv")
    (tmp_path / "rec.yaml").write_text("geometry: {L_total_mm: 40}\n")
    assert main(["compare", str(p), "--model", "ipmc_pt_eg", "--out", str(tmp_path / "o")]) == 2
    assert "geometry" in capsys.readouterr().err


# ------------------------------------------------------------------ bundles
@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    from nnmodel.bundle import save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    rec = Experiment(u=V, y=D, rh=np.full(V.size, 60.0), fs=100.0)
    m = MODELS["rbf"](n_centres=8, nb=4, na=1, progress_bar=False)
    m.fit([rec], [rec])
    return save(m, tmp_path_factory.mktemp("b") / "rbf")


def _tamper(src, dst, card_fn=None, state_fn=None):
    import hashlib
    import shutil
    shutil.copytree(src, dst)
    card = json.loads((dst / "card.json").read_text())
    if state_fn:
        state = torch.load(dst / "weights.pt", weights_only=True)
        state_fn(state)
        torch.save(state, dst / "weights.pt")
        card["weights"]["sha256"] = hashlib.sha256((dst / "weights.pt").read_bytes()).hexdigest()
    if card_fn:
        card_fn(card)
    (dst / "card.json").write_text(json.dumps(card))
    return dst


@pytest.mark.parametrize("case,message", [
    ("huge", "at most 20,000"), ("missing_fs", "fs_hz"), ("nan", "NaN or infinite"),
    ("shape", "do not match"), ("inputs", "inputs"), ("type", "whole number")])
def test_tampered_bundles_are_refused_cleanly(bundle, tmp_path, case, message):
    from nnmodel.bundle import load

    def first_float(state):
        return next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    card_fn = {"huge": lambda c: c["hyper_parameters"].update(n_centres=10**8),
               "missing_fs": lambda c: c.pop("fs_hz"),
               "inputs": lambda c: c.update(inputs="voltage"),
               "type": lambda c: c["hyper_parameters"].update(nb=2.5)}.get(case)
    state_fn = {"nan": lambda s: s[first_float(s)].view(-1).__setitem__(0, float("nan")),
                "shape": lambda s: s.__setitem__(first_float(s), torch.zeros(3, 3, 3))}.get(case)
    bad = _tamper(bundle, tmp_path / case, card_fn, state_fn)
    with pytest.raises(InputError, match=message) as err:
        load(bad)
    assert "weights_only=False" not in str(err.value)


# ------------------------------------------------------------------ property test of the reader
_cell = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.integers(-10**6, 10**6),
                  st.text(alphabet=string.printable + "éµ°", max_size=6))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sep=st.sampled_from([",", ";", "\t"]), decimal=st.sampled_from([".", ","]),
       unit=st.sampled_from(["m", "mm", "um"]), n=st.integers(0, 40),
       nan_at=st.one_of(st.none(), st.integers(0, 39)), junk=st.one_of(st.none(), _cell),
       encoding=st.sampled_from(["utf-8", "utf-8-sig", "latin-1"]), crlf=st.booleans(),
       data=st.lists(st.floats(-1e-3, 1e-3, allow_nan=False, width=64), min_size=40, max_size=40))
def test_reader_reads_exactly_or_raises_its_own_error(tmp_path, sep, decimal, unit, n, nan_at, junk, encoding,
                                                        crlf, data):
    if decimal == "," and sep == ",":
        decimal = "."
    scale = {"m": 1.0, "mm": 1e3, "um": 1e6}[unit]
    y = np.array(data[:n]) * scale
    rows = [[i * 0.01, 0.5, y[i], 50.0] for i in range(n)]
    if nan_at is not None and nan_at < n:
        rows[nan_at][2] = float("nan")
    if junk is not None and n:
        rows[n // 2][1] = junk
    fmt = lambda x: (repr(float(x)) if not isinstance(x, str) else x).replace(".", decimal)  # noqa: E731
    text = "\n".join([sep.join(["time_s", "voltage_V", f"deflection_{unit}", "rh_pct"])]
                     + [sep.join(fmt(x) for x in r) for r in rows]) + "\n"
    if crlf:
        text = text.replace("\n", "\r\n")
    p = tmp_path / "rec.csv"
    try:
        p.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        return
    try:
        ts = read_timeseries(p)
    except InputError:
        return  # the package's own error: fine
    assert ts.n == n
    np.testing.assert_allclose(ts.deflection * scale, y, rtol=1e-15, atol=0)


@pytest.mark.parametrize("argv,message", [
    (["compare", "{rec}", "--model", "ip2c_pedot_water", "--window", "bogus"], "--window 'bogus': not a window"),
    (["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone", "--frequency-Hz", "2",
      "--duration-s", "3", "--fs-Hz", "0"], "--fs-Hz 0.0: must be a positive number"),
    (["frf", "--device", "ip2c_pedot_water", "--rh", "60", "--f-min-Hz", "10", "--f-max-Hz", "1"],
     "--f-min-Hz 10 and --f-max-Hz 1 must be positive and increasing"),
    (["simulate", "--device", "ip2c_pedot_water", "--rh", "60", "--signal", "tone", "--frequency-Hz", "2",
      "--duration-s", "3", "--fs-Hz", "100", "--effects", ""], "an empty list is ambiguous"),
])
def test_bad_options_are_named_with_their_flag(tmp_path, capsys, argv, message):
    """Case 10 of the reliability review: bad option values are one line naming the flag."""
    rec = _write(tmp_path / "rec.csv")
    out = tmp_path / "o"
    argv = [a.replace("{rec}", str(rec)) for a in argv]
    argv += ["--json", str(tmp_path / "f.json")] if argv[0] == "frf" else ["--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "f.json").exists()


def test_required_options_do_not_advertise_a_default(capsys):
    for cmd in ("predict", "compare", "identify", "dataset", "train-compare"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        assert "default: None" not in capsys.readouterr().out, cmd


def test_a_sidecar_sensor_bandwidth_inside_the_band_is_announced(tmp_path, capsys):
    """Case 7: a wrong sensor.bandwidth used to change the fit silently; inside the compared
    band it is now flagged, with the flag that ignores it."""
    rec = _write(tmp_path / "rec.csv")
    (tmp_path / "rec.yaml").write_text("sensor: {bandwidth: 0.5}\n")
    assert main(["compare", str(rec), "--model", "ip2c_pedot_water", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "sensor.bandwidth 0.5 Hz low-passes the model output inside the compared band" in out
    assert "--sensor-bandwidth-Hz none ignores it" in out
    assert main(["compare", str(rec), "--model", "ip2c_pedot_water", "--out", str(tmp_path / "p"),
                 "--sensor-bandwidth-Hz", "none"]) == 0
    assert "sensor.bandwidth" not in capsys.readouterr().out
