"""Where the diagnosis's fits start and when they stop: a default search window is not a
bound, and a fit with an added effect never ends worse than the model without it."""
from __future__ import annotations

import warnings

import pytest

from physics.device import load_device
from physics.diagnose import candidates as C
from physics.diagnose.demo import hidden_effect_case
from physics.diagnose.diagnosis import read_records
from physics.identify.options import FitOptions


@pytest.fixture(scope="module")
def clean():
    """A base-only case (nothing hidden), its records and FRF targets."""
    case = hidden_effect_case(None, seed=0, duration=20.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = read_records(case.measurements, FitOptions())
    return case, data


def test_a_start_far_off_is_not_held_by_its_search_window(clean):
    """kf started 3000× too high: its default window (3 decades either side) excludes the
    optimum; the fit searches again around the edge it stopped on and ends where a fit from
    the device's value ends."""
    case, data = clean
    dev = load_device(case.device)
    ids = tuple(C.resolve_effects(case.base_effects, dev))
    fits = []
    for factor in (1.0, 3000.0):
        spec = C.ModelSpec("base", ids, ["kf", "beta_f"], start={"kf": factor * dev.params["kf"]})
        fits.append(C.fit_model(spec, dev, data.targets, data.target_records, n_starts=2))
    near, far = fits
    assert near.ok and far.ok, (near.error, far.error)
    assert far.values["kf"] < 3.0 * dev.params["kf"]            # below its first window
    assert far.values["kf"] == pytest.approx(near.values["kf"], rel=1e-3)
    assert far.frf_cost == pytest.approx(near.frf_cost, rel=1e-3)
    assert any("search window" in n for n in far.spec.notes) and not near.spec.notes
