"""The truth families of bench/truths: their physics against closed forms nobody here wrote,
determinism, independence from the package under test, and the files they write read back by
the package's reader."""
from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from bench.truths import FAMILIES, INDEPENDENT, TRUTHS, make_case, truth, truths
from bench.truths.case import remove_trend, trend_terms
from bench.truths.febeam import Beam, modal_tip
from bench.truths.lines import electrode_ladder, solvent_moment
from bench.truths.pnp import EPS0, charge_per_volt, debye_length

ROOT = Path(__file__).resolve().parents[1]
BETA_L = (1.8751040687, 4.6940911330)         # clamped–free Euler–Bernoulli roots (Meirovitch)


#: the families recorded as a lab does (five records, three RH levels, two amplitudes)
LAB_DESIGNED = ("pnp_fd", "circuit_lab")


@pytest.fixture(scope="module")
def cases():
    return {f: make_case(f, "none", 0) for f in LAB_DESIGNED}


# ---------------------------------------------------------------- the beam


def _uniform(n=24, L=0.025, E=0.2e9, w=5e-3, t=200e-6, rho=2000.0):
    EI, m = E * w * t ** 3 / 12, rho * w * t
    return Beam.build(L, np.full(n, EI), np.full(n, m)), EI, m, L


def test_fe_beam_static_tip_under_moment_and_couple():
    beam, EI, m, L = _uniform()
    M = 1e-3
    tip = beam.point_vector(L) @ beam.static(np.full(beam.z.size, M))
    assert tip == pytest.approx(M * L ** 2 / (2 * EI), rel=1e-9)           # uniform eigen-moment
    tip = beam.point_vector(L) @ beam.static(np.full(beam.z.size, M), couple=True)
    assert tip == pytest.approx(M * L ** 3 / (3 * EI), rel=1e-9)           # uniform distributed couple
    # the same through the modal sum at (almost) zero frequency
    om, phi = beam.modes()
    F = phi.T @ beam.G @ np.full(beam.z.size, M)
    h = modal_tip(om, beam.point_vector(L) @ phi, F[:, None], np.array([1e-9j]), alpha=0.0, beta=0.0)
    assert abs(h[0]) == pytest.approx(M * L ** 2 / (2 * EI), rel=1e-6)


def test_fe_beam_natural_frequencies_match_closed_form():
    beam, EI, m, L = _uniform()
    f = beam.modes()[0][:2] / (2 * np.pi)
    ref = np.array(BETA_L) ** 2 * math.sqrt(EI / m) / (2 * np.pi * L ** 2)
    assert f == pytest.approx(ref, rel=1e-4)


def test_fe_beam_taper_raises_the_first_frequency():
    # a strip narrowing towards the tip loses mass where it moves most: f1 rises (Rayleigh quotient)
    n = 24
    beam, EI, m, L = _uniform(n)
    z = (np.arange(n) + 0.5) / n
    shape = 1 - 0.3 * z
    tapered = Beam.build(L, EI * shape, m * shape)
    assert tapered.modes()[0][0] > 1.05 * beam.modes()[0][0]


# ---------------------------------------------------------------- charging through the thickness


def test_pnp_low_frequency_capacitance_and_rc_time():
    h, er, D, c0 = 90e-6, 41.4, 1.4e-9, 1100.0
    lam = debye_length(er, c0)
    C = EPS0 * er / (2 * lam)                   # two Debye–Hückel layers in series
    tau = lam * h / D                           # RC time (Bazant, Thornton & Ajdari 2004)
    f = np.array([1e-3, 1 / (2 * np.pi * tau)])
    q = charge_per_volt(f, h=h, eps_r=er, D=D, c0=c0)
    assert q[0].real == pytest.approx(C, rel=5e-3)
    assert q[1] == pytest.approx(C / (1 + 1j), rel=5e-3)


# ---------------------------------------------------------------- distributed lines


def test_solvent_line_thin_layer_limit_is_the_diffusion_closed_form():
    h = 90e-6
    Ds = h * h / 30.0
    f = np.array([1e-3, 1e-2, 0.1, 1.0])
    B = solvent_moment(f, h, Ds, 1e-9, n_cells=400)
    g = h * np.sqrt(2j * np.pi * f / Ds)
    ref = 1 - np.tanh(g) / g                    # Crank §4.3, first moment, no-flux faces
    assert np.max(np.abs(B - ref)) < 2e-3


def test_electrode_ladder_converges_to_the_rc_transmission_line():
    L, n = 0.025, 400
    r, y = 6000.0, 5e-3 * 2j * np.pi * 10 * 0.6    # Ω/m (both faces), S/m at 10 Hz
    dz = L / n
    links = np.full(n, r * dz)
    links[0] *= 0.5
    U = electrode_ladder(np.full((n, 1), y * dz), links)[:, 0]
    z = (np.arange(n) + 0.5) * dz
    m = np.sqrt(r * y)
    ref = np.cosh(m * (L - z)) / np.cosh(m * L)    # telegraph equation, open end
    assert np.max(np.abs(U - ref)) < 2e-3


# ---------------------------------------------------------------- circuit_lab pieces


def test_circuit_lab_mode_shapes_and_time_integration():
    from scipy.integrate import quad
    from scipy.signal import lsim
    from bench.truths.circuit_lab import lti_foh, mode_slope, mode_value
    L = 0.02
    assert abs(mode_value(0, L, L)) == pytest.approx(2.0, rel=1e-6)   # normalised cantilever mode at the tip
    # orthogonality of modes 1 and 2 (∫φ1 φ2 dz = 0) and slope zero at the clamp
    dot = quad(lambda z: mode_value(0, z, L) * mode_value(1, z, L), 0, L)[0]
    assert abs(dot) < 1e-8 * L
    assert abs(mode_slope(0, np.array([0.0]), L)[0]) < 1e-9
    rng = np.random.default_rng(3)
    A = np.array([[0.0, 1.0], [-(2 * np.pi * 12) ** 2, -2 * 0.1 * 2 * np.pi * 12]])
    B, C = np.array([0.0, 1.0]), np.array([1.0, 0.0])
    t = np.arange(2000) / 500.0
    u = rng.standard_normal(t.size)
    ref = lsim((A, B[:, None], C[None, :], np.zeros((1, 1))), u, t)[1]
    assert lti_foh(A, B, C, u, t[1] - t[0]) == pytest.approx(ref, rel=1e-6, abs=1e-12)


# ---------------------------------------------------------------- cases


def test_truth_table_names_only_catalog_effects():
    from physics.effects import EFFECTS
    for t in TRUTHS.values():
        assert set(t.expected) | set(t.acceptable) <= set(EFFECTS), t.name
        assert t.kind in ("none", "catalog", "outside", "twin", "pair", "route")
        assert (t.kind in ("catalog", "pair")) == bool(t.expected) or t.name == "pair_lowpass_sat"
    assert set(FAMILIES) == {"pnp_fd", "pnp_sweep", "circuit_lab", "lab", "perturbed"}
    assert set(LAB_DESIGNED) < set(INDEPENDENT)
    assert truth("lab", "solvent_diffusion").expected == ("solvent_diffusion",)
    assert truth("perturbed", "creep").kind == "outside"
    assert len([t for t in truths("pnp_fd") if truth("pnp_fd", t).kind == "pair"]) == 6


def test_independent_families_import_nothing_of_the_package():
    for f in (ROOT / "bench" / "truths").glob("*.py"):
        if f.name == "package.py":
            continue
        tree = ast.parse(f.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            assert not any(n.split(".")[0] in ("physics", "nnmodel") for n in names), (f.name, names)


def test_cases_are_deterministic_and_seeded(cases):
    import zlib
    from bench.truths import circuit_lab, pnp_fd
    c = cases["pnp_fd"]
    again = make_case("pnp_fd", "none", 0)
    assert [r.name for r in again.records] == [r.name for r in c.records]
    for a, b in zip(again.records, c.records):
        assert np.array_equal(a.measured, b.measured) and np.array_equal(a.voltage, b.voltage)
    for mod, name in ((pnp_fd, pnp_fd.LAB.name), (circuit_lab, circuit_lab.NAME)):   # another seed, another strip
        fam = zlib.crc32(name.encode())
        d0 = mod._draw_strip(np.random.default_rng([0, fam]))[1]
        d1 = mod._draw_strip(np.random.default_rng([1, fam]))[1]
        assert d0 != d1 and d0 == mod._draw_strip(np.random.default_rng([0, fam]))[1]


def test_case_physics_is_plausible_and_true_error_is_the_noise(cases):
    for fam, c in cases.items():
        assert c.true_error() == pytest.approx(c.noise_floor, rel=0.1)
        peak = max(float(np.max(np.abs(r.clean))) for r in c.records)
        assert 0.1e-3 < peak < 5e-3                       # tip 0.1–5 mm, within a laser's range
        amps = {round(float(np.max(np.abs(r.voltage))), 3) for r in c.records}
        assert len(amps) >= 2 and max(amps) <= 5.0        # two amplitudes at least, a few volts at most
        rhs = {round(float(np.mean(r.rh)) / 10) for r in c.records}
        assert len(rhs) >= 3                              # three RH levels
        for r in c.records:
            off, _ = trend_terms(r.measured - r.clean, r.time)
            assert off == pytest.approx(r.offset, abs=3 * c.noise_floor)


def test_hidden_ingredient_changes_the_response_and_user_model_leaves_it_out(cases):
    a = make_case("circuit_lab", "solvent", 0)
    assert a.effects == "default,-solvent_diffusion"
    base = cases["circuit_lab"]
    step_a = next(r for r in a.records if "step" in r.name)
    step_b = next(r for r in base.records if "step" in r.name)
    # back-relaxation: during the hold the water-like solvent (h²/Ds 8–60 s) takes back much of the
    # bend; the base's ethylene glycol (h²/Ds ~ 1 h) only ~2 sqrt(t Ds/π)/h ≈ 10 % in 25 s
    k0, k1 = int(3 * 200), int(26 * 200)
    assert step_a.clean[k1] < 0.7 * step_a.clean[k0]
    assert 0.8 * step_b.clean[k0] < step_b.clean[k1] < 0.97 * step_b.clean[k0]


def test_the_two_record_design_is_a_sweep_and_a_square_train_at_one_rh(tmp_path):
    """pnp_sweep: the same physics as pnp_fd recorded as the user of issue 34 did — a 120 s log
    sweep and a 60 s square pulse train at one RH, 1 µm noise; no truth that needs two RH levels;
    its strips drawn apart from pnp_fd's; the files read back by the package's reader."""
    from physics.io.timeseries import read_timeseries
    names = truths("pnp_sweep")
    assert "humidity" not in names and "route_creep_rh" not in names and "pair_modulus_rh" not in names
    assert {"none", "solvent", "creep", "pair_elec_solvent"} <= set(names)
    with pytest.raises(ValueError, match="not one of pnp_sweep"):
        make_case("pnp_sweep", "humidity", 0)
    c = make_case("pnp_sweep", "none", 0)
    assert c.family == "pnp_sweep" and c.effects == "none"
    assert [r.name.split("_")[1] for r in c.records] == ["sweep", "square"]
    assert [r.time[-1] for r in c.records] == pytest.approx([120.0 - 1 / 250, 60.0 - 1 / 250])
    assert max(float(np.mean(r.rh)) for r in c.records) - min(float(np.mean(r.rh)) for r in c.records) < 1.0
    assert c.noise_floor == pytest.approx(1e-6, rel=0.01) and c.true_error() == pytest.approx(c.noise_floor, rel=0.1)
    sq = c.records[1].voltage
    assert sq[:2 * 250].max() == 0 and sq.max() == pytest.approx(-sq.min()) and sq.max() > 0     # rest, then ± pulses
    assert make_case("pnp_fd", "none", 0).truth_params["L_total_mm"] != c.truth_params["L_total_mm"]
    files = c.write(tmp_path)
    ts = read_timeseries(files[1])
    assert np.allclose(ts.deflection, c.records[1].measured, atol=1e-8)
    assert ts.meta["sensor"]["deflection_noise"] == pytest.approx(1e-6)


@pytest.mark.parametrize("fam", LAB_DESIGNED)
def test_records_read_back_through_the_package_reader(cases, fam, tmp_path):
    from physics.io.timeseries import read_timeseries
    c = cases[fam]
    files = c.write(tmp_path)
    assert len(files) == 5
    for p, r in zip(files, c.records):
        ts = read_timeseries(p)
        assert np.allclose(ts.time, r.time, atol=1e-6)
        assert np.allclose(ts.voltage, r.voltage, atol=1e-4)
        assert np.allclose(ts.deflection, r.measured, atol=1e-8)
        assert np.allclose(ts.rh, r.rh, atol=1e-2)
    if fam == "pnp_fd":                                   # the careful lab states its sensor
        ts = read_timeseries(files[0])
        assert ts.meta["sensor"]["deflection_noise"] == pytest.approx(1.5e-6)


def test_trend_removal_matches_least_squares():
    t = np.linspace(0, 10, 501)
    e = 3.0 + 0.5 * t + np.sin(7 * t)
    off, slope = trend_terms(e, t)
    A = np.column_stack([np.ones_like(t), t])
    ref = np.linalg.lstsq(A, e, rcond=None)[0]
    assert (off, slope) == pytest.approx((ref[0], ref[1]), rel=1e-12)
    assert np.allclose(remove_trend(e, t), e - A @ ref)


# ---------------------------------------------------------------- the bench's reading of diagnosis.json


def test_bench_extracts_and_judges_a_diagnosis():
    import importlib.util
    spec = importlib.util.spec_from_file_location("lofo", ROOT / "bench" / "diagnose_lofo.py")
    lofo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(lofo)
    diag = {"base": {"rmse": 5e-6}, "noise_floor_m": 1e-6,
            "verdict": {"status": "explained", "ambiguous": [],
                        "chain": [{"effect": "solvent_diffusion", "confidence": 0.999, "confidence_label": "high",
                                   "rmse_before_m": 5e-6, "rmse_after_m": 1.2e-6},
                                  {"effect": "viscoelastic", "confidence": 0.5, "confidence_label": "low",
                                   "rmse_before_m": 1.2e-6, "rmse_after_m": 1.1e-6}],
                        "nuisance": {"records": [{"record": "dir/01_step.csv", "offset_um": 31.0}]}},
            "steps": [{"step": 1, "picked": "solvent_diffusion", "ranking": [{"effect": "solvent_diffusion"},
                                                                             {"effect": "humidity"}]}]}
    x = lofo.extract(diag)
    assert [p["effect"] for p in x["chain"]] == ["solvent_diffusion", "viscoelastic"]
    assert x["final_rmse"] == 1.1e-6 and x["offsets"] == {"01_step": pytest.approx(31e-6)}
    assert [c["picked"] for c in x["candidates"]] == [True, False]
    meta = {"expected": ["solvent_diffusion"], "acceptable": [], "true_error_m": 1e-6, "kind": "catalog",
            "true_offsets_m": {"01_step": [30e-6, 25e-6]}}
    j = lofo.judge(meta, x)
    assert j["named"] and not j["right"] and j["wrong"] and not j["wrong_high"]     # the low second pick is wrong
    assert j["ratio"] == pytest.approx(1.1) and j["offset_err"] == pytest.approx(6e-6)
    assert lofo.judge({**meta, "expected": [], "acceptable": ["solvent_diffusion"]}, x)["wrong_high"] is False


def test_the_sensor_forms_bow_and_cut_the_logged_deflection_only():
    """``bow``: y + b y²/S (even order, b of the stroke S at the stroke); ``clipped``: the
    logged deflection stops at ±c S — the strip's own motion is that of the nothing-hidden case."""
    base = make_case("pnp_sweep", "none", 0)
    stroke = max(float(np.max(np.abs(r.clean))) for r in base.records)
    bowed = make_case("pnp_sweep", "bow", 0)
    b = bowed.truth_params["bow"]
    assert 0.03 <= abs(b) <= 0.08 and bowed.effects == base.effects
    for r, r0 in zip(bowed.records, base.records):
        assert np.allclose(r.clean, r0.clean + b * r0.clean ** 2 / stroke, rtol=0, atol=1e-3 * stroke)
    cut = make_case("pnp_sweep", "clipped", 0)
    level = max(float(np.max(np.abs(r.clean))) for r in cut.records)
    assert level == pytest.approx(cut.truth_params["clip_over_stroke"] * stroke, rel=0.01)
    assert any(np.max(np.abs(r0.clean)) > level for r0 in base.records)
    for r, r0 in zip(cut.records, base.records):
        assert np.allclose(r.clean, np.clip(r0.clean, -level, level), rtol=0, atol=1e-3 * stroke)
