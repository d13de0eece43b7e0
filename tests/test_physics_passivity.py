"""No negative damping or energy creation for any effect combination and RH in 40–100 %."""
import itertools

import numpy as np
import pytest

import physics
from physics import signals
from physics.effects import BUILT_IN, EFFECTS, stage_of
from physics.model import ActuatorModel
from physics.solvers.frequency import frequency_response
from physics.solvers.timedomain import _load_filters, beam_statespace

OPTIONAL = [e for e in BUILT_IN if e != "double_layer"]   # each effect alone: test_effect_contract
SUBSETS = [c for r in range(len(OPTIONAL) + 1) for c in itertools.combinations(OPTIONAL, r)]
#: every subset a model can hold: at most one effect per stage of the chain
COMBOS = [c for c in SUBSETS if len({stage_of(EFFECTS[e]) for e in c if stage_of(EFFECTS[e])})
          == sum(1 for e in c if stage_of(EFFECTS[e]))]
S = 2j * np.pi * np.logspace(-4, 3, 50)


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_every_combination_absorbs_electrical_power_and_has_stable_mechanics(device):
    assert len(SUBSETS) == 2 ** len(OPTIONAL) and len(COMBOS) > 2 ** (len(OPTIONAL) - 1)
    device = physics.load_device(device).with_params(cpe_a=0.5)      # a constant-phase charge where it is on
    for combo in COMBOS:
        m = ActuatorModel(device, list(combo))
        for rh in (40.0, 70.0, 100.0):
            rh_arg = rh if m.stages["humidity"].needs_rh else None
            fr = frequency_response(m, None, np.abs(S) / (2 * np.pi), rh=rh_arg)
            assert np.all(fr.current.real >= 0), (combo, rh)          # Re Y_in ≥ 0: passive load
            p = m.params_at(rh_arg)
            EI, _ = m.section(p, float(m.stages["humidity"].stiffness_factor(rh)))
            Ew = EI(S)
            assert np.all(Ew.imag >= 0) and np.all(Ew.real > 0), (combo, rh)   # no negative loss


@pytest.mark.parametrize("device", ["ipmc_pt_eg", "ip2c_pedot_water"])
def test_realised_time_domain_systems_are_stable(device):
    m = ActuatorModel(device, "linear")
    p = dict(m.device.params)
    for f in _load_filters(m, p, np.pi * 1000):
        assert np.all(f.poles().real < 0)
    for k in (0.5, 1.0, 3.0):
        assert np.all(beam_statespace(m, p, k).poles().real < 0)


def test_energy_absorbed_is_positive_for_large_signals():
    rng = np.random.default_rng(1)
    sig = signals.noise(rms=1.0, f_start=0.1, f_stop=20.0, duration=20.0, fs=200.0, seed=int(rng.integers(100)))
    r = physics.simulate("ipmc_pt_eg", "nonlinear_charge,thermal,electrode_resistance", sig.t, sig.v)
    cum = np.cumsum(r.voltage * r.current) / 200.0
    # stored double-layer energy can flow back, but never more than what went in
    assert cum[-1] > 0 and np.min(cum) > -1e-12 * np.max(np.abs(cum))
