"""The linear yardstick (nnmodel.linear) against systems whose answer is known."""
import numpy as np

from nnmodel.benchmarks import toy
from nnmodel.data import nrmse
from nnmodel.linear import LinearModel, fit_linear


def test_a_noise_free_arx_system_is_recovered_with_its_own_orders():
    """toy.linear2 is y[k] = 1.5 y[k-1] - 0.7 y[k-2] + 0.25 u[k-1]: orders (2, 2) with
    feedthrough are the fewest coefficients that simulate it exactly."""
    train, val = toy.records("linear2", 1500, seeds=(1,)), toy.records("linear2", 600, seeds=(2,))
    m = fit_linear(train, val)
    assert (m.na, m.nb) == (2, 2)
    np.testing.assert_allclose(m.a, [1.5, -0.7], atol=1e-6)
    u = toy.excitation(800, seed=9)
    assert nrmse(toy.linear2(u), m.simulate(u)) < 1e-5          # from rest, as the true system
    again = LinearModel.from_card(m.card())
    np.testing.assert_array_equal(again.simulate(u), m.simulate(u))


def test_output_error_refinement_removes_the_bias_of_least_squares_under_output_noise():
    """White noise on the output biases least squares of the system's own orders (its
    one-step errors are coloured); the output-error refinement fits the simulation and comes
    closer to the truth, and is kept because it validates better."""
    train = toy.records("linear2", 3000, seeds=(1,), noise=0.5)
    val = toy.records("linear2", 1000, seeds=(2,), noise=0.5)
    orders = dict(na_grid=(2,), nb_grid=(2,))
    oe = fit_linear(train, val, **orders)
    ls = fit_linear(train, val, output_error=False, **orders)
    assert oe.report["output_error_kept"] is True and "output_error_kept" in ls.report
    assert oe.report["validation_nrmse"] < ls.report["validation_nrmse"]
    u = toy.excitation(1500, seed=9)
    y = toy.linear2(u)
    e_oe, e_ls = nrmse(y, oe.simulate(u)), nrmse(y, ls.simulate(u))
    assert e_oe < 0.5 * e_ls, (e_oe, e_ls)
    np.testing.assert_allclose(oe.a, [1.5, -0.7], atol=0.03)


def test_rh_enters_linearly_and_the_grid_fits_short_records():
    train = toy.records("rh", 40, seeds=(1,), rh_levels=(40.0, 80.0))    # 40 samples: history of 19 at most
    m = fit_linear(train, None, 0.25)
    assert m.uses_rh and max(m.report["grid_nb"]) <= 19 and np.isfinite(m.simulate(train[0].u, 60.0)).all()
