"""A correction on a reference (linear start, the hybrid's physics) is kept only when its
validation gain stands out from the gain's own uncertainty (batch means over blocks)."""
import numpy as np
import torch
from torch import nn

import pytest

from nnmodel.batches import paired_gain
from nnmodel.models.base import GAIN_BLOCKS, GAIN_SE, keep_if_better
from nnmodel.models.core import SequenceCore
from nnmodel.models.normalise import Seq

N, SEG = 1000, 100     # a validation record of 10 segments, one block each


class _Residual(SequenceCore):
    """Output = the reference (input channel 1) + w × the correction (input channel 2)."""

    n_init = 1

    def __init__(self):
        super().__init__()
        self.w = nn.Parameter(torch.ones(()))

    def init_state(self, u_hist, y_hist, rh_hist):
        return None

    def simulate(self, state, u, rh):
        return u[..., 0] + self.w * u[..., 1]

    def zero_correction(self):
        with torch.no_grad():
            self.w.zero_()


def _record(signs, a):
    """y = reference + s (s = ±1 by segment); the correction is a·s where ``signs`` is +1
    (it removes part of the error) and −a·s where it is −1 (it adds to it)."""
    s = np.repeat(np.where(np.arange(N // SEG) % 2 == 0, 1.0, -1.0), SEG)
    ref = np.sin(np.arange(N) / 30.0)
    corr = a * s * np.repeat(np.asarray(signs, float), SEG)
    return [Seq(np.stack([ref, corr], 1).astype(np.float32), (ref + s).astype(np.float32), None)]


def test_a_gain_the_validation_cannot_tell_from_chance_leaves_the_reference():
    assert GAIN_BLOCKS == N // SEG
    # right on 6 segments, wrong on 4: the pooled error is lower (4a − 10a² > 0 per segment) ...
    val = _record([1, 1, -1, 1, -1, 1, -1, 1, -1, 1], 0.2)
    core = _Residual()
    out = keep_if_better(core, val)
    assert out["validation_nrmse_network"] < out["validation_nrmse_reference"]    # the old rule kept it
    assert out["kept"] == "linear" and core.w.item() == 0.0                      # ... within its uncertainty: dropped
    assert out["validation_blocks"] >= 2 and 0 < out["validation_gain"] < GAIN_SE * out["validation_gain_se"]
    assert "within its uncertainty" in out["reason"]


def test_a_gain_everywhere_is_kept():
    core = _Residual()
    out = keep_if_better(core, _record([1] * 10, 0.5))
    assert out["kept"] == "network" and core.w.item() == 1.0
    assert out["validation_gain"] > GAIN_SE * out["validation_gain_se"]


def test_the_correlation_time_of_an_ar1_series_is_its_textbook_value():
    """AR(1) with coefficient φ: integrated autocorrelation time (1 + φ) / (1 − φ) (19 for 0.9)."""
    from scipy.signal import lfilter

    from nnmodel.batches import correlation_time
    x = lfilter([1.0], [1.0, -0.9], np.random.default_rng(0).normal(size=200_000))
    assert abs(correlation_time(x) - 19.0) < 1.5
    assert abs(correlation_time(np.random.default_rng(1).normal(size=50_000)) - 1.0) < 0.1


def test_blocks_are_no_shorter_than_the_correlation_time():
    """A slowly varying difference (AR(1) with φ = 0.99: correlation time ~ 200 samples) on
    1000 samples gives a handful of blocks, not the 10 asked for: the standard error is not
    understated."""
    from scipy.signal import lfilter

    from nnmodel.batches import paired_gain
    d = 0.05 + lfilter([1.0], [1.0, -0.99], np.random.default_rng(2).normal(size=1000)) * 0.01
    gain, se, blocks = paired_gain([d + 1.0], [np.ones(1000)], 10)
    assert 2 <= blocks <= 7 and abs(gain - d.mean()) < 1e-12


def test_models_with_different_start_up_windows_are_paired_on_the_samples_both_score():
    """A grey box and a network start their free runs after different numbers of samples: their
    per-record errors (which end at the record's end) are compared on the common tail — the
    default `eap run` stopped with a broadcast error in the hybrid's fallback check before."""
    rng = np.random.default_rng(3)
    tail = rng.normal(size=400) ** 2
    ref = [np.concatenate([np.full(9, 50.0), tail + 1.0])]     # starts 9 samples earlier
    new = [tail]
    gain, se, blocks = paired_gain(ref, new, 10)
    assert gain == pytest.approx(1.0) and blocks >= 2
