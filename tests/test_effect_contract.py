"""The effect contract, checked over every registered effect (the built-ins and the shipped
example ``examples/effects/creep.py``): spec completeness, solver agreement, the off values
give exactly the model without the effect, passivity, and identification on its own data."""
from pathlib import Path

import numpy as np
import pytest

from physics import signals
from physics.device import load_device
from physics.diagnose.signatures import FEATURE_TEXT
from physics.diagnose.specs import _scaled, param_bounds, spec_of, start_points
from physics.effects import (BUILT_IN, CHAIN, DIAGNOSIS_KEYS, EFFECTS, REVEAL_RULES, effect_classes_in_file, register,
                             stage_of, unregister)
from physics.frequency import frequency_response
from physics.identify import IdentificationProblem, fit_lsq
from physics.identify.problem import FRFTarget
from physics.model import ActuatorModel
from physics.timedomain import simulate

CREEP = Path(__file__).resolve().parents[1] / "examples" / "effects" / "creep.py"
DEVICE = "ipmc_pt_eg"


(EXAMPLE,) = effect_classes_in_file(CREEP)
#: every effect the contract is checked on (read at collection, before the example is registered)
CLASSES = {**{e: EFFECTS[e] for e in BUILT_IN if e != "double_layer"}, EXAMPLE.id: EXAMPLE}
EFFECT_IDS = list(CLASSES)
LINEAR = [e for e, c in CLASSES.items() if c.linear]


def _spec(e) -> dict:
    return CLASSES[e].diagnosis or {}


@pytest.fixture(scope="module", autouse=True)
def example_registered():
    register(EXAMPLE)
    yield
    unregister(EXAMPLE.id)


@pytest.mark.parametrize("effect", EFFECT_IDS)
def test_diagnosis_spec_is_complete(effect):
    spec = spec_of(effect)
    dev = load_device(DEVICE)
    assert spec, f"{effect} declares no diagnosis spec"
    assert set(spec) <= set(DIAGNOSIS_KEYS)
    assert "free" in spec and "nested" in spec and spec.get("excitation")
    assert set(spec.get("reveal", {})) <= set(REVEAL_RULES)
    assert spec.get("signature") and all(f in FEATURE_TEXT and w > 0 for f, w in spec["signature"])
    declared = {p.name for p in EFFECTS[effect].params} | set(EFFECTS[effect].requires)
    for name in spec["free"]:
        assert name in declared, f"{effect}: free {name} is not a parameter of the effect"
        lo, hi = param_bounds(name, dev)
        assert lo < hi
    for st in start_points(effect, dev):
        for name, v in st.items():
            lo, hi = param_bounds(name, dev)
            assert lo <= v <= hi, (effect, name, v)
    for role, (name, rank) in spec.get("roles", {}).items():
        assert role in ("gain", "stiffness") and name in declared | set(dev.params)
    for name in spec.get("off", {}):
        assert name in declared | set(dev.params), (effect, name)


def test_every_effect_fills_a_stage_or_adds_factors_and_hooks_are_unique():
    for e in EFFECT_IDS:
        cls = EFFECTS[e]
        assert stage_of(cls) is not None or any(callable(getattr(cls, h, None))
                                                for h in ("load_factor", "output_response"))
    # each stage hook is provided by exactly one stage (so the model's dispatch is unambiguous)
    hooks = {}
    for d in CHAIN:
        for name in vars(d):
            if callable(getattr(d, name)) and not name.startswith("_"):
                hooks.setdefault(name, []).append(d.slot)
    shared = {h: s for h, s in hooks.items() if len(s) > 1}
    assert not shared, shared


def _periodic_frf(model, rh, periods):
    fs, period = 200.0, 20.0
    sig = signals.multisine(rms=0.02, f_start=0.1, f_stop=20.0, period=period, fs=fs, seed=3)
    n = sig.t.size
    if model.outputs:             # added output filters start from rest: repeat periods, keep the last
        v = np.tile(sig.v, periods)
        t = np.arange(v.size) / fs
        y = simulate(model, None, t, v, rh=rh).deflection[-n:]
    else:
        y = simulate(model, None, sig.t, sig.v, rh=rh, periodic=True).deflection
    k = np.arange(int(np.ceil(0.1 * period)), int(20.0 * period) + 1)
    return k / period, np.fft.rfft(y)[k] / np.fft.rfft(sig.v)[k]


@pytest.mark.parametrize("effect", LINEAR)
def test_frequency_and_time_solvers_agree(effect):
    """≤ 1 % and 1° over 0.1–20 Hz between the closed form and the time solver."""
    m = ActuatorModel(DEVICE, f"none,+{effect}")
    f, H = _periodic_frf(m, 60.0, periods=8)
    ratio = H / frequency_response(m, None, f, rh=60.0).deflection
    assert np.max(np.abs(np.abs(ratio) - 1)) < 0.01, effect
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 1.0, effect


@pytest.mark.parametrize("effect", [e for e in EFFECT_IDS if _spec(e).get("off")])
def test_off_values_give_exactly_the_model_without_it(effect):
    dev = load_device(DEVICE)
    off = {k: _scaled(v, dev) for k, v in spec_of(effect)["off"].items()}
    base = ActuatorModel(dev, "linear" if effect != "creep" else "default")
    ids = [e for e in base.effect_ids if e != effect] if effect in base.effect_ids else list(base.effect_ids)
    without = ActuatorModel(dev, ids)
    with_off = ActuatorModel(dev.with_params(**off), ids + [effect])
    f = np.geomspace(0.01, 50, 40)
    np.testing.assert_allclose(frequency_response(with_off, None, f, rh=60).deflection,
                               frequency_response(without, None, f, rh=60).deflection, rtol=1e-12)
    sig = signals.tone(0.5, 1.0, 4.0, 200.0)
    a = simulate(with_off, None, sig.t, sig.v, rh=60).deflection
    b = simulate(without, None, sig.t, sig.v, rh=60).deflection
    # a large-signal effect runs the implicit stepper instead of the exact LTI solution: the
    # two discretisations agree to ~1e-4 of the range, not to rounding
    tol = 1e-9 if EFFECTS[effect].linear else 1e-3
    assert np.max(np.abs(a - b)) <= tol * np.max(np.abs(b)), effect


@pytest.mark.parametrize("effect", EFFECT_IDS)
def test_each_effect_is_passive(effect):
    """Re Y_in ≥ 0 (the strip absorbs electrical power) and no negative material loss."""
    m = ActuatorModel(DEVICE, f"none,+{effect}")
    S = 2j * np.pi * np.logspace(-4, 3, 50)
    for rh in (40.0, 100.0):
        fr = frequency_response(m, None, np.abs(S) / (2 * np.pi), rh=rh)
        assert np.all(fr.current.real >= 0)
        EI, _ = m.section(m.params_at(rh), float(m.hook("stiffness_factor")(rh)))
        assert np.all(EI(S).imag >= 0) and np.all(EI(S).real > 0)


def _truth(effect, dev):
    """A point inside the spec's bounds (geometric mean, or the middle when lo ≤ 0)."""
    out = {}
    for name in spec_of(effect)["free"]:
        lo, hi = param_bounds(name, dev)
        out[name] = float(np.sqrt(lo * hi)) if lo > 0 else 0.5 * (lo + hi)
    return out


IDENTIFIABLE = [e for e in LINEAR if _spec(e).get("free") and not _spec(e).get("describing_function")]


@pytest.mark.parametrize("effect", IDENTIFIABLE)
def test_identify_recovers_the_effect_parameters_on_its_own_data(effect):
    dev0 = load_device(DEVICE)
    truth = _truth(effect, dev0)
    dev = dev0.with_params(**truth)
    ids = f"none,+{effect}"
    f = np.geomspace(1e-3, 50.0, 120)
    H = frequency_response(ActuatorModel(dev, ids), None, f, rh=60.0).deflection
    target = FRFTarget("synthetic", f, H, np.ones(f.size), 60.0, None, None, {})
    names = list(truth)
    start = {}
    for n in names:
        lo, hi = param_bounds(n, dev0)
        start[n] = float(np.clip(truth[n] * 1.6 if truth[n] else 0.2 * (hi - lo), lo, hi))
    prob = IdentificationProblem(dev, ids, [target], names, start=start,
                                 bounds={n: param_bounds(n, dev0) for n in names})
    extra = [[st.get(n, start[n]) for n in names] for st in start_points(effect, dev0)]
    fit = fit_lsq(prob, n_starts=2, seed=0, extra_starts=extra)
    got = dict(zip(prob.labels, fit.theta))
    for n in names:
        assert got[n] == pytest.approx(truth[n], rel=0.02, abs=1e-6 * abs(truth[n])), (effect, n, got[n], truth[n])
