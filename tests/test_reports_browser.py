"""Every kind of HTML page, audited in a real headless browser at a 1280 px window
(:mod:`browser_check`): images load, no script error, no horizontal overflow or scroll box,
no ``nan``, no program identifier as a table header, a unit on every header over numbers,
no temporary folder named — and the main numbers on the page equal the JSON beside it.
A full-page screenshot of each page is kept under its run folder (an artefact, not in git).
The benchmark and validate pages are audited by their own tests (test_benchmark_eap.py,
test_reference_strip.py)."""
import json

import pytest
import yaml

from browser_check import assert_clean, needs_browser, render
from nnmodel.app.cli import main
from physics.io.timeseries import write_timeseries

pytestmark = needs_browser

#: A small dataset for the page of ``eap run`` (the structure of the quick preset, short records).
TINY_RUN = dict(device="ip2c_pedot_water", effects="default", fs_Hz=100.0, f_max_Hz=20.0, duration_s=6.0,
                train_rh_pct=[40, 100], heldout_rh_pct=[70], excitations=["sweep", "noise"],
                validation_per_rh=1, test_per_train_rh=1, test_per_heldout_rh=1,
                varying_rh={"train": 1, "test": 1, "range_pct": [40, 100]},
                measurement_like={"effects": ["nonlinear_charge"], "count": 1, "rh_pct": [55]})


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    from physics.testbeds.demo import hidden_effect_case
    d = tmp_path_factory.mktemp("recs")
    case = hidden_effect_case("electrode_resistance", 0, duration=30.0)
    return [write_timeseries(m, d / f"r{k}.csv") for k, m in enumerate(case.measurements)]


def _audit(out):
    """Audit the page of a command's folder (``index.html``; an older ``report.html`` is still
    audited, so the checks can be run against an old commit), then check its name and the
    redirect kept under the old name.  Returns (audit dict, text, page)."""
    page = out / "index.html"
    if not page.is_file() and (out / "report.html").is_file():
        page = out / "report.html"
    check, text = render(page)
    assert_clean(check, page)
    assert page.name == "index.html", sorted(p.name for p in out.iterdir())
    old = out / "report.html"
    if old.is_file():
        assert "index.html" in old.read_text() and old.stat().st_size < 2000
    return check, text, page


@pytest.mark.parametrize("kind", ["compare", "identify", "diagnose"])
def test_measurement_reports(kind, records, tmp_path):
    out = tmp_path / kind
    args = {"compare": ["compare", *map(str, records), "--model", "ipmc_pt_eg", "--effects", "none"],
            "identify": ["identify", *map(str, records), "--device", "ipmc_pt_eg", "--effects", "none",
                         "--free", "kf,beta_f"],
            "diagnose": ["diagnose", *map(str, records), "--device", "ipmc_pt_eg", "--effects", "none",
                         "--quiet", "--apply"]}[kind]
    assert main(args + ["--out", str(out)]) == 0
    check, text, page = _audit(out)
    check_narrow, _ = render(page, width=700, screenshot=False)   # a narrow window: tables scroll in their box
    assert not check_narrow["too_wide"], check_narrow
    if kind == "diagnose":
        verdict = json.loads((out / "diagnosis.json").read_text())["verdict"]["missing_effect"]
        assert verdict in text
        assert str(out.resolve()) in text or str(out) in text   # the suggested command names the final folder
    if kind == "compare":
        rep = json.loads((out / "report.json").read_text())
        rmse = rep["records"][0]["time_metrics"]["rmse"]
        assert f"{1e6 * rmse:.3g}" in text   # tips in µm


def test_run_page_tells_the_story(tmp_path):
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY_RUN))
    out = tmp_path / "run"
    assert main(["run", "--quiet", "--dataset-config", str(cfg), "--models", "ff,hybrid",
                 "--set", "ff.max_epochs=1", "--set", "hybrid.max_epochs=1", "--out", str(out)]) == 0
    check, text, page = _audit(out)
    assert check["sections"][:1] == ["Devices and their physics"]
    assert {"Where the model fails", "The diagnosis", "Before and after"} <= set(check["sections"])
    rep = json.loads((out / "report.json").read_text())
    loop = rep["loop"]
    assert f"{loop['rmse_before_um']:.3g} µm" in text
    res = rep["physics"]["ipmc_pt_eg"]["resonance_Hz_by_rh"]
    assert f"{res['40']:.1f} Hz" in text
    outside = rep["outside"]          # the out-of-catalog loop: what remains → a drafted effect → the error after
    assert "Beyond the catalog: physics no effect models" in check["sections"]
    assert outside["before"]["verdict"]["status"] in text and outside["drafts"], outside
    assert all((out / x["file"]).is_file() and x["contract"] == "passed" for x in outside["drafts"])
    assert f"{1e6 * outside['before']['rmse_m']:.3g} → {1e6 * outside['after']['rmse_m']:.3g} µm" in text
    assert "measurement-like" in text and "not in the training data" in text   # the odd number has its sentence
    assert page.with_name("index.screenshot.png").is_file()
    assert (out / "compare" / "index.html").is_file()
    assert ".eap-tmp-" not in (out / "compare" / "compare.json").read_text()   # final paths in the JSON too


def test_train_compare_report(tmp_path):
    from nnmodel.dataset import generate
    ds = generate(tmp_path / "ds", "quick", progress=False, duration_s=4.0, train_rh_pct=[40, 80],
                  heldout_rh_pct=[60], excitations=["sweep"], varying_rh={"train": 0, "test": 0,
                                                                          "range_pct": [40, 100]},
                  measurement_like={"effects": [], "count": 0, "rh_pct": [70]})
    out = tmp_path / "tc"
    assert main(["train-compare", str(ds), "--models", "ff", "--set", "ff.max_epochs=1", "--quiet",
                 "--out", str(out)]) == 0
    check, text, page = _audit(out)
    best = json.loads((out / "compare.json").read_text())["best_heldout"]
    assert f"{100 * best['nrmse']:.2f} %" in text
