"""bench/silverbox_floor.py: the split of a free-run error into what sits on the lines an odd
multisine excites and what sits at the level of the lines it does not, on synthetic periods
whose answer is known."""
from __future__ import annotations

import numpy as np
import pytest

from bench.silverbox_floor import FS, PERIOD, error_split, periods


def _odd_multisine(rng, n_periods: int, gap: int = 300) -> tuple[np.ndarray, list[int]]:
    """Periods of an odd random-phase multisine (odd lines up to 200 Hz) separated by zero gaps,
    and where each period starts."""
    k = np.arange(PERIOD // 2 + 1)
    spec = np.where((k % 2 == 1) & (k * FS / PERIOD < 200.0), np.exp(2j * np.pi * rng.random(k.size)), 0.0)
    one = np.fft.irfft(spec, PERIOD)
    one *= 0.05 / one.std()
    parts, starts = [np.zeros(gap)], []
    for _ in range(n_periods):
        starts.append(sum(p.size for p in parts))
        parts += [one, np.zeros(gap)]
    return np.concatenate(parts), starts


def test_the_zero_gaps_mark_every_complete_period():
    u, starts = _odd_multisine(np.random.default_rng(0), 3)
    found = periods(u)
    assert len(found) == 3
    assert np.max(np.abs(np.array(found) - starts)) <= 2          # the gap's edge, within the moving window


@pytest.mark.parametrize("error_on_excited_lines", [0.0, 3.0])
def test_a_disturbance_on_every_line_is_floor_and_an_error_on_the_excited_lines_is_not(error_on_excited_lines):
    rng = np.random.default_rng(1)
    u, starts = _odd_multisine(rng, 2)
    noise = 1e-4 * rng.standard_normal(u.size)                    # 0.1 mV on every line alike
    residual = noise + error_on_excited_lines * 1e-4 / 0.05 * u   # an error of the drive's response: odd lines only
    odd, even, rmse, floor = error_split(residual, starts)
    assert floor == pytest.approx(1e-4, rel=0.08)                 # the noise is found either way
    if error_on_excited_lines:
        assert rmse == pytest.approx(1e-4 * np.sqrt(1 + error_on_excited_lines ** 2), rel=0.08)
        assert np.all(odd > 3 * even)
    else:
        assert rmse == pytest.approx(floor, rel=0.05)
        assert np.all((odd / even > 0.7) & (odd / even < 1.4))
