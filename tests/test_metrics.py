import json
import math

import numpy as np
import pytest

from physics.errors import InputError
from physics.analysis.metrics import correlation, fit_percent, j_err, nrmse, rmse, summary

Y = np.array([1.0, 2.0, 3.0, 4.0])


def test_perfect_model():
    assert rmse(Y, Y) == 0.0 and nrmse(Y, Y) == 0.0
    assert fit_percent(Y, Y) == 100.0 and correlation(Y, Y) == pytest.approx(1.0)


def test_mean_model_scores_zero_fit():
    mean = np.full(4, Y.mean())
    assert fit_percent(Y, mean) == pytest.approx(0.0, abs=1e-12)
    assert nrmse(Y, mean) == pytest.approx(1.0)
    assert rmse(Y, mean) == pytest.approx(math.sqrt(1.25))  # population std of 1..4


def test_hand_computed_values():
    yhat = np.array([1.0, 2.0, 3.0, 6.0])  # one error of 2 -> RMSE sqrt(4/4) = 1
    assert rmse(Y, yhat) == pytest.approx(1.0)
    assert nrmse(Y, yhat) == pytest.approx(1 / math.sqrt(1.25))  # ||e|| / ||y - mean|| = 2/sqrt(5)
    assert fit_percent(Y, yhat) == pytest.approx(100 * (1 - 2 / math.sqrt(5)))
    assert rmse([0, 0, 0, 0], [1, -1, 1, -1]) == pytest.approx(1.0)
    assert fit_percent(Y, -Y + 5) == pytest.approx(100 * (1 - math.sqrt(20) / math.sqrt(5)))  # -100 %


def test_correlation():
    assert correlation(Y, 2 * Y + 3) == pytest.approx(1.0)
    assert correlation(Y, -Y) == pytest.approx(-1.0)
    assert correlation([1, 2, 3], [1, 3, 2]) == pytest.approx(0.5)  # (1)/(sqrt2*sqrt2)


def test_j_err_thesis_eq13():
    assert j_err([1.0, 2.0, 3.0], [1.0, 2.0, 5.0]) == pytest.approx(math.sqrt(4 / 3))
    # complex responses: only magnitudes are compared (|3+4j| = 5)
    assert j_err(np.array([3 + 4j, 1j]), np.array([5.0, -1.0])) == 0.0


def test_summary_is_json_ready():
    s = summary(Y, np.array([1.0, 2.0, 3.0, 6.0]))
    assert set(s) == {"n", "rmse", "nrmse", "fit_percent", "correlation"}
    assert all(type(v) in (int, float) for v in s.values())
    assert s["n"] == 4 and s["rmse"] == pytest.approx(1.0)
    assert json.loads(json.dumps(s)) == s


@pytest.mark.parametrize("y, yhat, msg", [
    (Y, Y[:3], "y has 4 values but yhat has 3"),
    (Y, np.array([1.0, np.nan, 3, 4]), "yhat: element 1 is nan"),
    (np.array([1.0, 2, np.inf, 4]), Y, "y: element 2 is inf"),
    (Y.reshape(2, 2), Y.reshape(2, 2), "1-D"),
    ([], [], "non-empty"),
    (["a", "b"], ["a", "b"], "real numbers"),
    (Y.astype(complex), Y, "real numbers"),
])
def test_bad_input(y, yhat, msg):
    with pytest.raises(InputError, match=msg):
        rmse(y, yhat)


def test_undefined_for_constant_signals():
    const = np.ones(4)
    for metric in (nrmse, fit_percent, correlation):
        with pytest.raises(InputError, match="y is constant"):
            metric(const, Y)
    with pytest.raises(InputError, match="yhat is constant"):
        correlation(Y, const)


def test_metrics_in_blocks_and_with_an_offset(monkeypatch):
    """A long record's metrics are summed a block at a time (no record-long difference or
    centred copy), and the offset compare removes is passed instead of an aligned copy of
    the measurement: the values of the whole-record formulas on y − offset, to rounding (in
    one block the RMSE is exactly that of the aligned copy)."""
    import physics.analysis.metrics as m
    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(size=5000)) * 1e-6 + 2e-5
    yhat = 0.8 * y + 1e-7 * rng.normal(size=y.size)
    c = float(np.mean(y) - np.mean(yhat))
    al = y - c
    e = al - yhat
    want = {"n": y.size, "rmse": math.sqrt(e @ e / y.size),
            "nrmse": math.sqrt(e @ e) / math.sqrt((al - al.mean()) @ (al - al.mean())),
            "correlation": float((al - al.mean()) @ (yhat - yhat.mean()))
            / math.sqrt(((al - al.mean()) @ (al - al.mean())) * ((yhat - yhat.mean()) @ (yhat - yhat.mean())))}
    want["fit_percent"] = 100 * (1 - want["nrmse"])
    one_block = summary(y, yhat, offset=c)
    assert one_block["rmse"] == rmse(al, yhat) and one_block["correlation"] == correlation(y, yhat)
    for block in (1 << 20, 1000, 999, 7):
        monkeypatch.setattr(m, "BLOCK", block)
        assert summary(y, yhat, offset=c) == pytest.approx(want, rel=1e-12)
        assert summary(al, yhat) == pytest.approx(want, rel=1e-12)
