"""Parameter identification: recovery of known parameters from simulated, sensor-corrupted
records, honest uncertainty, the thesis procedure, joint humidity fits, device files."""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import yaml

from physics import signals, simulate
from physics.compare import FRFOptions
from physics.device import load_device
from physics.errors import InputError
from physics.solvers.frequency import frequency_response
from physics.io.frfdata import FRFData, write_frf
from physics.identify import (FreeParameter, IdentifiabilityWarning, identify, parse_assignments, uncertainty,
                              write_device, write_identification)
from physics.model import ActuatorModel
from physics.io.sensor import SensorModel
from physics.io.timeseries import TimeSeries, write_timeseries


def periodic_record(model, rh, *, seed=0, sensor=None, period=10.0, periods=3, fs=1000.0, rms=0.5):
    """A multisine record in periodic steady state, measured through ``sensor``."""
    sig = signals.multisine(rms, 0.1, 50.0, period, 1, fs, seed=seed)
    y = simulate(model, None, sig.t, sig.v, rh=rh, periodic=True).deflection
    n = periods * sig.t.size
    ts = TimeSeries(np.arange(n) / fs, np.tile(sig.v, periods), np.tile(y, periods), rh=np.full(n, float(rh)),
                    meta={"signal": {**sig.describe(), "periods": periods}}, source=f"synthetic RH {rh:g}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # RH clipped at 100 % by the sensor model
        return (sensor or SensorModel()).apply(ts, seed=seed + 100)


@pytest.fixture(scope="module")
def ipmc():
    return ActuatorModel("ipmc_pt_eg", "default")


@pytest.fixture(scope="module")
def ipmc_record(ipmc):
    return periodic_record(ipmc, 100.0, seed=1)


# ---------------------------------------------------------------------------- recovery


def test_ipmc_thesis_case_recovered_within_5_percent(ipmc, ipmc_record):
    true = {"kf": ipmc.device["kf"], "beta_f": ipmc.device["beta_f"]}
    res = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,beta_f",
                   start={"kf": 1.5 * true["kf"], "beta_f": 0.6 * true["beta_f"]})
    for name, v in true.items():
        assert res.values[name] == pytest.approx(v, rel=0.05)
    assert res.fit.j_err < 0.05 * res.j_err_initial
    assert res.device["kf"] == pytest.approx(res.values["kf"])          # the fitted device carries them


def test_recovery_within_reported_uncertainty(ipmc):
    """With a noisy laser (20 µm RMS) the errors are noise-driven: each estimate must lie
    within 3 reported standard errors of the truth, and those errors must be small enough
    to mean something."""
    sensor = dataclasses.replace(SensorModel(), deflection_noise=20e-6)
    true = np.array([ipmc.device["kf"], ipmc.device["beta_f"]])
    for seed in (2, 3):
        rec = periodic_record(ipmc, 60.0, seed=seed, sensor=sensor)
        res = identify([rec], "ipmc_pt_eg", "default", ["kf", "beta_f"], start={"kf": 0.006, "beta_f": 1e-3})
        z = (res.fit.theta - true) / res.fit.std_error
        assert np.all(np.abs(z) < 3.0), z
        assert np.all(res.fit.rel_std_error < 0.005)          # ~0.05–0.15 % expected: not inflated
        lo, hi = res.fit.ci95[:, 0], res.fit.ci95[:, 1]
        assert np.all(lo < res.fit.theta) and np.all(res.fit.theta < hi)


def test_ip2c_eq16_recovered_within_5_percent():
    model = ActuatorModel("ip2c_pedot_water", "default")
    rec = periodic_record(model, 100.0, seed=4)
    names = ["kf0", "frac_a", "frac_p", "frac_b", "beta_f"]
    true = {n: model.device[n] for n in names}
    start = {"kf0": 1.4 * true["kf0"], "frac_a": 0.7, "frac_p": 0.7 * true["frac_p"], "frac_b": 0.05,
             "beta_f": 1.3 * true["beta_f"]}
    res = identify([rec], "ip2c_pedot_water", "default", names, start=start)
    for n in names:
        assert res.values[n] == pytest.approx(true[n], rel=0.05), n
    assert "fractional_coupling" in res.problem.effects


def test_thesis_nelder_mead_procedure(ipmc, ipmc_record):
    res = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,beta_f", method="both",
                   start={"kf": 1.5 * ipmc.device["kf"], "beta_f": 0.6 * ipmc.device["beta_f"]})
    nm = res.fits["nelder-mead"]
    assert nm.nit <= 100
    assert res.settings["thesis_nelder_mead"] == {"max_iter": 100, "xatol": 1e-6, "fatol": 1e-6,
                                                  "tolerance_on": res.settings["thesis_nelder_mead"]["tolerance_on"]}
    assert nm.j_err < 0.05 * res.j_err_initial
    assert nm.theta[0] == pytest.approx(ipmc.device["kf"], rel=0.05)
    assert nm.theta[1] == pytest.approx(ipmc.device["beta_f"], rel=0.05)
    assert res.primary == "lsq" and res.fit.method == "lsq"
    # J_err of eq. 13 recomputed by hand on the fitted model
    prob = res.problem
    H = prob.responses(nm.theta)
    mags = np.concatenate([np.abs(h) - np.abs(t.response) for h, t in zip(H, prob.targets)])
    assert nm.j_err == pytest.approx(math.sqrt(np.mean(mags ** 2)))


def test_time_residual_fit():
    """Fitting the time record directly (short, 200 Hz, from rest)."""
    model = ActuatorModel("ipmc_pt_eg", "electrode_resistance")
    sig = signals.noise(0.5, 0.2, 20.0, 12.0, 200.0, seed=5)
    y = simulate(model, None, sig.t, sig.v, rh=100.0).deflection
    rec = SensorModel(bandwidth=None, rh_noise=0.0).apply(TimeSeries(sig.t, sig.v, y, rh=np.full(sig.t.size, 100.0)),
                                                          seed=5)
    res = identify([rec], model.device, "electrode_resistance", "kf,beta_f", residual="time",
                   start={"kf": 0.006, "beta_f": 1e-3})
    assert res.values["kf"] == pytest.approx(model.device["kf"], rel=0.02)
    assert res.values["beta_f"] == pytest.approx(model.device["beta_f"], rel=0.05)
    assert "time record" in res.fit.residual_kind


def test_frf_file_input(tmp_path):
    """An FRF CSV (closed form + 1 % noise, with coherence) is fitted as it is."""
    model = ActuatorModel("ipmc_pt_eg", "default")
    f = np.logspace(-1, np.log10(50), 200)
    H = frequency_response(model, None, f, rh=100.0).deflection
    rng = np.random.default_rng(0)
    Hn = H * (1 + 0.01 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / np.sqrt(2))
    path = write_frf(FRFData(f, Hn, coherence=np.full(f.size, 0.9999), rh=100.0), tmp_path / "frf.csv")
    res = identify([str(path)], "ipmc_pt_eg", "default", "kf,beta_f", start="kf=0.006,beta_f=1e-3")
    assert res.values["kf"] == pytest.approx(model.device["kf"], rel=0.01)
    assert res.values["beta_f"] == pytest.approx(model.device["beta_f"], rel=0.02)
    assert res.problem.targets[0].estimator == {"method": "file"}


# ---------------------------------------------------------------------------- humidity


@pytest.fixture(scope="module")
def rh_records(ipmc):
    return [periodic_record(ipmc, rh, seed=10 + i, periods=2) for i, rh in enumerate((40.0, 60.0, 80.0))]


def test_joint_fit_per_rh_recovers_table_v(ipmc, rh_records, tmp_path):
    hum = ipmc.stages["humidity"]
    truth_Y = {rh: ipmc.device["Y"] * float(hum.stiffness_factor(rh)) for rh in (40, 60, 80)}
    truth_kf = {rh: ipmc.params_at(rh)["kf"] for rh in (40, 60, 80)}
    res = identify(rh_records, "ipmc_pt_eg", "default", "beta_f", per_rh="Y,kf",
                   start="Y=0.3 GPa,kf=0.005,beta_f=1e-3", frf_options=FRFOptions(max_points=120))
    assert res.problem.levels == [40.0, 60.0, 80.0]
    for rh in (40, 60, 80):
        assert res.values[f"Y@RH{rh}"] == pytest.approx(truth_Y[rh], rel=0.02)
        assert res.values[f"kf@RH{rh}"] == pytest.approx(truth_kf[rh], rel=0.02)
    assert res.values["beta_f"] == pytest.approx(ipmc.device["beta_f"], rel=0.02)
    # the written device carries the per-RH values as absolute humidity maps and loads back
    out = write_identification(res, tmp_path)
    dev = load_device(tmp_path / out["device_written"])
    m = dev.humidity_maps["kf"]
    assert m.mode == "absolute" and m.rh.tolist() == [40.0, 60.0, 80.0]
    assert m.values == pytest.approx([res.values[f"kf@RH{rh}"] for rh in (40, 60, 80)], rel=1e-6)
    model = ActuatorModel(dev, "default")
    assert model.params_at(60.0)["kf"] == pytest.approx(truth_kf[60], rel=0.02)


def test_shared_parameter_with_ratio_map_is_the_reference_value(ipmc, rh_records):
    """Fitting kf shared over RH 40 and 80 % with the Table V ratio map returns kf at the
    device's reference RH (100 %), where no record was taken."""
    res = identify(rh_records[::2], "ipmc_pt_eg", "default", "kf", start={"kf": 0.002})
    assert res.values["kf"] == pytest.approx(ipmc.device["kf"], rel=0.02)


def test_per_rh_needs_humidity_and_two_levels(ipmc_record, rh_records):
    with pytest.raises(InputError, match="humidity effect"):
        identify(rh_records, "ipmc_pt_eg", "electrode_resistance", per_rh="kf")
    with pytest.raises(InputError, match="two or more RH levels"):
        identify([ipmc_record], "ipmc_pt_eg", "default", per_rh="kf")


# ---------------------------------------------------------------------------- uncertainty, identifiability


class _LinearProblem:
    """r(x) = A x − b, the case where the Bates–Watts formula is exact OLS."""

    def __init__(self, A, b):
        self.A, self.b = A, b
        self.params = [FreeParameter(f"p{i}", 0.0, -1e3, 1e3, "linear", "1") for i in range(A.shape[1])]
        self.labels = [p.name for p in self.params]
        self.x_bounds = (np.full(A.shape[1], -1e3), np.full(A.shape[1], 1e3))

    def from_x(self, x):
        return np.asarray(x, dtype=float)

    def r(self, x):
        return self.A @ x - self.b


def test_uncertainty_matches_ordinary_least_squares():
    rng = np.random.default_rng(0)
    A = np.column_stack([np.ones(50), np.linspace(0, 1, 50)])
    b = A @ np.array([2.0, -1.0]) + 0.1 * rng.standard_normal(50)
    prob = _LinearProblem(A, b)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    unc = uncertainty(prob, x, prob.r)
    resid = A @ x - b
    s2 = resid @ resid / (50 - 2)
    cov = s2 * np.linalg.inv(A.T @ A)
    assert unc["s2"] == pytest.approx(s2)
    assert unc["std_error"] == pytest.approx(np.sqrt(np.diag(cov)), rel=1e-6)
    assert unc["correlation"][0, 1] == pytest.approx(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]), rel=1e-6)
    assert unc["warnings"] == []


def test_correlated_pair_is_flagged(ipmc_record):
    """The deflection depends on kf and n_solvation only through their product."""
    with pytest.warns(IdentifiabilityWarning) as rec:
        res = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,n_solvation", n_starts=1)
    text = " ".join(str(w.message) for w in rec)
    assert "kf" in text and "n_solvation" in text
    assert any("near-singular" in w or "correlated" in w or "not identifiable" in w for w in res.warnings)


def test_parameter_without_effect_is_refused(ipmc_record):
    with pytest.raises(InputError, match=r"Y_polymer has no effect.*layered_beam"):
        identify([ipmc_record], "ipmc_pt_eg", "default", "kf,Y_polymer")


# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("kwargs, message", [
    (dict(free="kf,bogus"), "unknown parameter 'bogus'"),
    (dict(free=""), "no free parameter"),
    (dict(free="kf,kf"), "given twice"),
    (dict(free="kf", per_rh="kf"), "either shared"),
    (dict(free="kf", start="kf=-1"), "not positive"),
    (dict(free="kf", bounds="kf=1e-3"), "expected lo:hi"),
    (dict(free="kf", bounds="kf=1e-2:1e-3"), "must be below"),
    (dict(free="kf", start="beta_f=1e-3"), "not a free parameter"),
    (dict(free="kf", start="kf=0.1", bounds="kf=1e-4:1e-2"), "outside its bounds"),
    (dict(free="kf", method="simplex"), "expected lsq, nelder-mead or both"),
    (dict(free="kf", start="kf=abc"), "expected a number"),
])
def test_bad_arguments(ipmc_record, kwargs, message):
    with pytest.raises(InputError, match=message):
        identify([ipmc_record], "ipmc_pt_eg", "default", **kwargs)


def test_assignments_with_units():
    assert parse_assignments("Y=0.2 GPa,kf=0.004") == {"Y": pytest.approx(2e8), "kf": 0.004}
    assert parse_assignments("Y=0.1:1 GPa", ranges=True) == {"Y": (pytest.approx(1e8), pytest.approx(1e9))}
    with pytest.raises(InputError, match=r"Y='0.2 m'.*not compatible with 'Pa'"):
        parse_assignments("Y=0.2 m")


def test_measurement_without_rh_needs_it(tmp_path, ipmc_record):
    ts = TimeSeries(ipmc_record.time, ipmc_record.voltage, ipmc_record.deflection)
    with pytest.raises(InputError, match="no relative humidity"):
        identify([ts], "ipmc_pt_eg", "default", "kf")


# ---------------------------------------------------------------------------- device file


def test_written_device_file(tmp_path, ipmc):
    """Elastic model (viscoelastic off) so that Y itself is identifiable; written in the
    original unit (GPa) with source and standard error."""
    model = ActuatorModel("ipmc_pt_eg", "electrode_resistance,solvent_diffusion")
    rec = periodic_record(model, 100.0, seed=7, periods=2)
    res = identify([rec], "ipmc_pt_eg", "electrode_resistance,solvent_diffusion", "kf,Y",
                   start="kf=0.003,Y=0.3 GPa")
    path = write_device(res, tmp_path / "fitted.yaml", name="ipmc_fit", date="2024-05-01")
    raw = yaml.safe_load(path.read_text())
    y = raw["mechanical"]["Y"]
    assert y["unit"] == "GPa" and y["value"] == pytest.approx(res.values["Y"] / 1e9, rel=1e-6)
    assert y["source"].startswith("identified by eap identify from synthetic RH 100 on 2024-05-01")
    assert "standard error" in y["note"]
    assert raw["default_effects"] == ["electrode_resistance", "solvent_diffusion"]
    dev = load_device(path)
    assert dev.name == "ipmc_fit"
    assert dev["Y"] == pytest.approx(model.device["Y"], rel=0.02)
    assert dev["kf"] == pytest.approx(res.values["kf"], rel=1e-6)
    assert dev["Rs"] == model.device["Rs"]                        # untouched values stay
    assert raw["electrical"]["Rs"]["source"] == yaml.safe_load(
        open(model.device.path))["electrical"]["Rs"]["source"]
    with pytest.raises(InputError, match="refusing to overwrite"):
        write_device(res, path, protect=(path,))


def test_cli_identify(tmp_path, ipmc_record, capsys):
    from nnmodel.app.cli import main
    csv = write_timeseries(ipmc_record, tmp_path / "meas.csv")
    out = tmp_path / "out"
    code = main(["identify", str(csv), "--device", "ipmc_pt_eg", "--free", "kf,beta_f",
                 "--start", "kf=0.006,beta_f=1e-3", "--points", "150", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "kf" in text and "model evaluations" in text
    for name in ("ipmc_pt_eg_identified.yaml", "report.json", "index.html", "parameters.csv"):
        assert (out / name).is_file()
    dev = load_device(out / "ipmc_pt_eg_identified.yaml")
    assert dev["kf"] == pytest.approx(0.0041, rel=0.05)
    code = main(["identify", str(csv), "--device", "ipmc_pt_eg", "--free", "kff", "--out", str(out), "--overwrite"])
    assert code == 2
    assert "unknown parameter 'kff'" in capsys.readouterr().err


def test_multistarts_on_two_workers_give_the_serial_fit(ipmc, ipmc_record):
    """The least-squares starts are tasks of the execution layer: the fit, every start's
    record and the evaluation count do not depend on where they ran."""
    from physics.execution.parallel import ParallelSettings
    kw = dict(start={"kf": 1.5 * ipmc.device["kf"], "beta_f": 0.6 * ipmc.device["beta_f"]}, n_starts=3)
    serial = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,beta_f", **kw)
    par = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,beta_f", settings=ParallelSettings(2), **kw)
    assert len(par.fit.starts) == 3 and par.fit.starts == serial.fit.starts
    np.testing.assert_array_equal(par.fit.theta, serial.fit.theta)
    assert par.n_evaluations == serial.n_evaluations > 3


def test_screened_starts_reach_the_full_fit_with_fewer_evaluations(ipmc, ipmc_record, monkeypatch):
    """``keep_starts``: every start runs a short way, only the lowest go on to convergence.
    On a problem whose starts meet in one optimum the fit is the full one's, the evaluations
    fewer, and each start's record says whether it was continued or screened out (the short
    run shortened here so that no start converges within it)."""
    from physics.identify import fitting
    kw = dict(start={"kf": 1.5 * ipmc.device["kf"], "beta_f": 0.6 * ipmc.device["beta_f"]}, n_starts=5)
    full = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,Rs,beta_f", **kw)
    monkeypatch.setattr(fitting, "SCREEN_NFEV_PER_PARAM", 1)
    kept = identify([ipmc_record], "ipmc_pt_eg", "default", "kf,Rs,beta_f", keep_starts=1, **kw)
    np.testing.assert_allclose(kept.fit.theta, full.fit.theta, rtol=1e-4)
    assert kept.n_evaluations < full.n_evaluations
    notes = [s["screened"] for s in kept.fit.starts]
    assert len(notes) == 5 and sum(n.startswith("continued") for n in notes) == 1
    out = [s for s in kept.fit.starts if "not among the 1 lowest" in s["screened"]]
    assert len(out) == 4 and all(s["nfev"] <= 1 * 3 for s in out)    # the short run: 1 evaluation per parameter
    with pytest.raises(InputError, match="keep_starts"):
        identify([ipmc_record], "ipmc_pt_eg", "default", "kf", keep_starts=0)
