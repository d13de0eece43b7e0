"""`eap benchmark --suite eap` and `--suite greybox`: smoke runs on tiny datasets.

The full suites are programs (minutes to an hour); here they run on 6-s records at
100 Hz with tiny models, to check the wiring, the outputs and the verdict logic (the
greybox smoke run is marked slow: `pytest -m slow`)."""
import json

import pytest

from nnmodel.benchmarks import SUITES, eap, greybox
from nnmodel.app.cli import main
from nnmodel.dataset import generate, load_dataset
from physics.errors import InputError

TINY = dict(fs_Hz=100.0, f_max_Hz=20.0, duration_s=6.0, train_rh_pct=[40, 100], heldout_rh_pct=[70],
            excitations=["sweep", "noise"], validation_per_rh=1, test_per_train_rh=1, test_per_heldout_rh=1,
            varying_rh={"train": 1, "test": 1, "range_pct": [40, 100]},
            measurement_like={"effects": ["nonlinear_charge"], "count": 1, "rh_pct": [55]})
SMALL = {"ff": dict(nb=5, hidden=8, max_epochs=2, memory_filters=3, memory_max_s=5.0),
         "rbf": dict(nb=5, n_centres=10, memory_filters=3, memory_max_s=5.0),
         "narx": dict(na=1, nb=3, hidden=8, max_epochs=1, horizon=20, stride=20, memory_filters=3,
                      memory_max_s=5.0),
         "hybrid": dict(nb=3, hidden=8, max_epochs=2, memory_filters=3, memory_max_s=5.0, gain_hidden=4)}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("ds") / "tiny", dict(TINY), progress=False)


def test_eap_suite_writes_one_table_with_every_model_and_the_physics_reference(tiny, tmp_path):
    out = tmp_path / "eap"
    rep = eap.run(["ff", "rbf", "hybrid"], out, data=tiny, progress=False,
                  overrides={k: SMALL[k] for k in ("ff", "rbf", "hybrid")}, echo=lambda *a: None)
    for f in ("eap.json", "eap.csv", "index.html", "eap.html", "eap.png", "compare/index.html",
              "compare/models/hybrid/card.json"):
        assert (out / f).is_file(), f
    data = json.loads((out / "eap.json").read_text())
    from browser_check import CHROMIUM, assert_clean, render
    if CHROMIUM:   # the benchmark page through the one report builder, in a real browser
        check, text = render(out / "index.html")
        assert_clean(check, out / "index.html")
    names = [r["model"] for r in data["results"]]
    assert names[0] == "physics" and {"ff", "rbf", "hybrid"} <= set(names)
    for r in data["results"]:
        if r["role"] == "model":
            assert r["n_parameters"] > 0 and r["samples_per_s"] > 0 and r["train_time_s"] > 0
            assert r["nrmse_pct"]["heldout_rh"] > 0
    # the ranking and the winners name networks only, ordered by held-out error
    held = {r["model"]: r["nrmse_pct"]["heldout_rh"] for r in data["results"] if r["role"] == "model"}
    assert data["ranking_heldout"] == sorted(held, key=held.get)
    assert data["winners"]["heldout_rh"]["model"] == data["ranking_heldout"][0]
    assert "physics" not in data["ranking_heldout"]
    table = eap.format_table(rep)
    assert "held-out RH %" in table and "physics (reference)" in table
    html = (out / "index.html").read_text()
    assert "data:image/png;base64" in html and "no published figures" in html


def test_eap_suite_reuses_a_generated_dataset_only_for_the_same_configuration(tmp_path):
    out = tmp_path / "b"
    msgs = []
    cfg = tmp_path / "tiny.yaml"
    import yaml
    cfg.write_text(yaml.safe_dump(TINY))
    ds = eap._dataset(out, None, str(cfg), msgs.append)
    h = load_dataset(ds).hash
    ds2 = eap._dataset(out, None, str(cfg), msgs.append)
    assert ds2 == ds and load_dataset(ds2).hash == h and "reusing" in msgs[-1]


@pytest.mark.slow
def test_greybox_study_reports_the_verdicts_and_a_data_efficiency_curve(tmp_path):
    ds = generate(tmp_path / "gb", dict(TINY, effects="electrode_resistance,solvent_diffusion,fractional_coupling,"
                                              "viscoelastic,humidity,nonlinear_charge",
                                        measurement_like={"effects": [], "count": 0, "rh_pct": []}),
                  progress=False)
    out = tmp_path / "study"
    rep = greybox.run(["hybrid", "ff"], out, data=ds, progress=False, sizes=(1, None), curve_budget_s=5.0,
                      overrides={"hybrid": SMALL["hybrid"], "ff": SMALL["ff"]}, echo=lambda *a: None)
    for f in ("greybox.json", "greybox.csv", "index.html", "greybox.html", "greybox_efficiency.png"):
        assert (out / f).is_file(), f
    from browser_check import CHROMIUM, assert_clean, render
    if CHROMIUM:
        check, _ = render(out / "index.html")
        assert_clean(check, out / "index.html")
    rows = {r["model"]: r for r in rep["full_data"]}
    # the hybrid's physics lacks nonlinear_charge: its physics part alone is scored separately
    assert "physics_base" in rows and rows["physics_base"]["heldout_rh_pct"] > rows["physics"]["heldout_rh_pct"]
    assert set(rep["checks"]) == {"hybrid_beats_physics", "hybrid_beats_best_pure_network"}
    sizes = sorted({c["n_records"] for c in rep["curve"]})
    assert sizes[0] == 1 and sizes[-1] == len(load_dataset(ds).entries("train"))
    assert {c["model"] for c in rep["curve"]} == {"hybrid", "ff"}


def test_subsets_cover_the_rh_levels_before_repeating_one():
    entries = [{"path": f"r{i}", "rh_pct": rh} for i, rh in enumerate([40, 40, 60, 60, 80, 80, 100, 100])]
    entries.append({"path": "v", "rh_pct": {"varying": [40, 100]}})
    order = greybox.subset_order(entries)
    assert [e["rh_pct"] for e in order[:4]] == [40, 100, 60, 80]
    assert order[-1]["path"] == "v" and len(order) == len(entries)


def test_benchmark_command_checks_its_arguments(tmp_path, capsys):
    assert {"eap", "silverbox", "greybox"} <= set(SUITES)
    assert main(["benchmark", "--suite", "all", "--out", str(tmp_path), "--data", "x"]) != 0
    assert "one suite" in capsys.readouterr().err
    assert main(["benchmark", "--suite", "eap", "--out", str(tmp_path), "--limit", "100"]) != 0
    assert "--limit" in capsys.readouterr().err
    with pytest.raises(InputError, match="hybrid"):
        greybox.run(["ff"], tmp_path, data="unused", echo=lambda *a: None)
