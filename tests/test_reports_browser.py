"""Every kind of HTML report, rendered in a real headless browser (Debian's ``chromium``;
``.ci/run`` installs it): every image loads, no script errors, nothing wider than the
viewport outside the scroll boxes, and the main numbers on the page equal the JSON beside
it.  A screenshot of each page is kept under its run folder (an artefact, not in git)."""
import json

import pytest

from browser_check import assert_clean, needs_browser, render
from nnmodel.cli import main
from physics.timeseries import write_timeseries

pytestmark = needs_browser


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    from physics.diagnose.demo import hidden_effect_case
    d = tmp_path_factory.mktemp("recs")
    case = hidden_effect_case("electrode_resistance", 0, duration=30.0)
    return [write_timeseries(m, d / f"r{k}.csv") for k, m in enumerate(case.measurements)]


@pytest.mark.parametrize("kind", ["compare", "identify", "diagnose"])
def test_measurement_reports(kind, records, tmp_path):
    out = tmp_path / kind
    args = {"compare": ["compare", *map(str, records), "--model", "ipmc_pt_eg", "--effects", "none"],
            "identify": ["identify", *map(str, records), "--device", "ipmc_pt_eg", "--effects", "none",
                         "--free", "kf,beta_f"],
            "diagnose": ["diagnose", *map(str, records), "--device", "ipmc_pt_eg", "--effects", "none",
                         "--quiet"]}[kind]
    assert main(args + ["--out", str(out)]) == 0
    page = out / "report.html"
    check, text = render(page)
    assert_clean(check, page)
    check_narrow, _ = render(page, width=700)   # a narrow window: tables scroll inside their box
    assert not check_narrow["too_wide"], check_narrow
    if kind == "diagnose":
        verdict = json.loads((out / "diagnosis.json").read_text())["verdict"]["missing_effect"]
        assert verdict in text


def test_run_page_tells_the_story(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "--physics-only", "--quiet", "--out", str(out)]) == 0
    page = out / "index.html"
    check, text = render(page)
    assert_clean(check, page)
    assert check["sections"][:1] == ["Devices and their physics"]
    assert {"Where the model fails", "The diagnosis", "Before and after"} <= set(check["sections"])
    rep = json.loads((out / "report.json").read_text())
    loop = rep["loop"]
    assert f"{loop['rmse_before_um']:.3g} µm" in text and f"{loop['rmse_after_um']:.3g} µm" in text
    res = rep["physics"]["ipmc_pt_eg"]["resonance_Hz_by_rh"]
    assert f"{res['40']:.1f} Hz" in text
    outside = rep["outside"]          # the out-of-catalog loop: what remains → a drafted effect → the error after
    assert "Beyond the catalog: physics no effect models" in check["sections"]
    assert outside["before"]["verdict"]["status"] in text and outside["drafts"], outside
    assert all((out / x["file"]).is_file() and x["contract"] == "passed" for x in outside["drafts"])
    assert f"{1e6 * outside['before']['rmse_m']:.3g} → {1e6 * outside['after']['rmse_m']:.3g} µm" in text
    assert page.with_name("index.screenshot.png").is_file()


def test_train_compare_report(tmp_path):
    from nnmodel.dataset import generate
    ds = generate(tmp_path / "ds", "quick", progress=False, duration_s=4.0, train_rh_pct=[40, 80],
                  heldout_rh_pct=[60], excitations=["sweep"], varying_rh={"train": 0, "test": 0,
                                                                          "range_pct": [40, 100]},
                  measurement_like={"effects": [], "count": 0, "rh_pct": [70]})
    out = tmp_path / "tc"
    assert main(["train-compare", str(ds), "--models", "ff", "--set", "ff.max_epochs=1", "--quiet",
                 "--out", str(out)]) == 0
    page = out / "report.html"
    check, text = render(page)
    assert_clean(check, page)
    best = json.loads((out / "compare.json").read_text())["best_heldout"]
    assert f"{100 * best['nrmse']:.2f} %" in text
