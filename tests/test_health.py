"""Filter health (estim.experiments.shared.health) and the RLS settings the audit of issue 11
named."""

import numpy as np
import pytest
from scipy import stats

from estim.estimators.base import Estimate
from estim.estimators.kf import KalmanFilter
from estim.estimators.rls import RecursiveLeastSquares
from estim.experiments.shared import health

A = np.array([[0.95, 0.1], [-0.1, 0.95]])
C = np.array([[1.0, 0.0]])
Q, R, P0 = np.diag([0.01, 0.02]), np.array([[0.25]]), np.diag([1.0, 1.0])


def linear_gaussian(runs, steps, seed, a=A, drive=0.0):
    """Truth of ``x_k = a x_{k-1} + [drive, 0] + v``, ``z = C x + w``, ``x_0 ~ N(0, P0)``."""
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(np.zeros(2), P0, size=runs)
    states = np.empty((runs, steps, 2))
    for k in range(steps):
        x = x @ a.T + [drive, 0.0] + rng.multivariate_normal(np.zeros(2), Q, size=runs)
        states[:, k] = x
    z = states @ C.T + rng.normal(scale=np.sqrt(R[0, 0]), size=(runs, steps, 1))
    return states, z


def kf(a=A, q=Q, b=(0.0, 0.0)):
    return KalmanFilter(A=a, B=np.reshape(b, (2, 1)), C=C, Q=q, R=R, P0=P0, x0=[0.0, 0.0])


def test_nees_and_nis_of_a_consistent_kf_fall_in_their_bands_at_the_nominal_rate():
    states, z = linear_gaussian(100, 400, seed=1)
    est = kf().run(None, z, np.zeros((400, 1)))
    nees_mean, nees_in = health.averaged_in_band(health.nees(states, est.x_hat, est.P), 2)
    nis_mean, nis_in = health.averaged_in_band(health.nis(est.innovation, est.S), 1)
    assert nees_mean == pytest.approx(2.0, rel=0.05)
    assert nis_mean == pytest.approx(1.0, rel=0.05)
    # 400 steps at 95 %: binomial SD 1.1 %; allow 4 SD either side
    assert 0.905 <= nees_in <= 0.995
    assert 0.905 <= nis_in <= 0.995


def test_nees_of_an_overconfident_kf_leaves_its_band():
    states, z = linear_gaussian(100, 400, seed=2)
    est = kf(q=Q / 100).run(None, z, np.zeros((400, 1)))
    mean, inside = health.averaged_in_band(health.nees(states, est.x_hat, est.P), 2)
    assert mean > 4 and inside < 0.1


def test_band_is_the_chi_square_quantile_of_the_run_average():
    lo, hi = health.band(4, 30)
    assert (lo, hi) == pytest.approx((3.05, 5.07), abs=0.01)   # the audit's [3.05, 5.07]


def test_the_chi_square_functions_are_scipy_stats_own_computation_bit_for_bit():
    """health computes chi-square quantiles and tails with scipy.special (a run need not
    import scipy.stats, 0.3 s); the stored bands and p-values stay what scipy.stats gives."""
    for dof in (1, 4, 10, 120, 4000, 30000):
        for p in (0.0025, 0.025, 0.05, 0.5, 0.975, 0.9975):
            assert health.chi2_ppf(p, dof) == float(stats.chi2.ppf(p, dof))
    x = np.concatenate([np.linspace(-1.0, 200.0, 2001), [np.nan, np.inf, -np.inf, 0.0]])
    for lag in (1, 5, 10):
        assert np.array_equal(health.chi2_sf(x, lag), stats.chi2.sf(x, lag), equal_nan=True)


def test_ljung_box_p_values_are_uniform_for_white_noise_and_small_for_ar1():
    rng = np.random.default_rng(3)
    p = health.ljung_box(rng.normal(size=(400, 300)), lag=10)
    assert stats.kstest(p, "uniform").pvalue > 1e-3
    e = rng.normal(size=(50, 300))
    ar = np.empty_like(e)
    ar[:, 0] = e[:, 0]
    for k in range(1, 300):
        ar[:, k] = 0.5 * ar[:, k - 1] + e[:, k]
    assert np.all(health.ljung_box(ar, lag=10) < 1e-3)


def test_whiteness_of_a_consistent_kf_passes_at_about_the_nominal_rate():
    _, z = linear_gaussian(300, 300, seed=4)
    passed = health.white(kf().run(None, z, np.zeros((300, 1))).innovation, lag=10, level=0.05)
    assert 0.90 <= passed.mean() <= 0.99       # 95 % +- 4 binomial SD of 300 runs


def test_a_wrong_kf_is_inconsistent_not_diverged_and_a_right_one_neither():
    """The truth is driven by a known input; the wrong model leaves the input out and trusts
    its own prediction (Q a thousandth of the truth's): its NIS leaves the band in every run
    (inconsistent), but its error stays bounded (the stable model pulls it back), so no run
    diverged. The right model's runs fall outside the 95 % band about 5 % of the time."""
    runs, steps = 200, 300
    states, z = linear_gaussian(runs, steps, seed=5, drive=1.0)
    actual = states @ C.T
    u = np.ones((steps, 1))
    good = kf(b=(1.0, 0.0)).run(None, z, u)
    nis_good = health.nis(good.innovation, good.S)
    assert not health.diverged(good, actual).any()
    assert 0.01 <= health.inconsistent(nis_good, 1).mean() <= 0.10
    wrong = kf(q=Q / 1000).run(None, z, u)
    assert health.inconsistent(health.nis(wrong.innovation, wrong.S), 1).all()
    assert not health.diverged(wrong, actual).any()


def test_a_constructed_runaway_is_diverged_and_a_biased_run_is_inconsistent_not_diverged():
    """Run 0's error grows tenfold every quarter of the record (a runaway); run 1 is off by a
    constant bias far outside the covariance it reports (NIS ~ 100 at every step) but its
    error does not grow; run 2 is right and consistent."""
    steps = 400
    t = np.arange(steps) / steps
    actual = np.broadcast_to(np.sin(2 * np.pi * 5 * t)[None, :, None], (3, steps, 1)).copy()
    y_hat = actual.copy()
    y_hat[0, :, 0] += 1e-3 * np.exp(4 * np.log(10) * t)
    y_hat[1, :, 0] += 1.0
    rng = np.random.default_rng(9)
    y_hat[2, :, 0] += 0.1 * rng.standard_normal(steps)
    innovation = y_hat - actual
    S = np.full((3, steps, 1, 1), 0.01)
    est = Estimate(y_hat=y_hat, innovation=innovation, broken=np.zeros(3, bool), S=S)
    assert health.diverged(est, actual).tolist() == [True, False, False]
    assert health.inconsistent(health.nis(innovation, S), 1).tolist() == [True, True, False]
    assert health.runaway(y_hat - actual, 0.0, growth=10.0).tolist() == [True, False, False]
    assert not health.runaway(y_hat - actual, 10.0).any()      # below the scale: no runaway


def test_divergence_by_output_range_for_a_filter_without_noise_model():
    z = np.random.default_rng(6).normal(size=(4, 50, 1))
    est = RecursiveLeastSquares(order=2).run(None, z, np.ones((50, 1)))
    assert not health.diverged(est, None, (-10.0, 10.0)).any()
    assert health.diverged(est, None, (5.0, 10.0)).all()
    assert health.inconsistent(None, 1) is None          # no noise model: no consistency


def test_rls_lambda0_is_refused_where_it_would_do_nothing():
    with pytest.raises(ValueError, match="lambda0 is the constant factor"):
        RecursiveLeastSquares(lambda0=0.99).validate(None)
    with pytest.raises(ValueError, match="needs lambda0"):
        RecursiveLeastSquares(forgetting="fixed").validate(None)


def test_rls_fixed_forgetting_uses_lambda0():
    """With lambda0 = 1 the recursion is ridge least squares on all data so far (prior
    W = 0 with P = delta I); a lambda0 below 1 weights recent data more and changes it."""
    rng = np.random.default_rng(7)
    u = rng.normal(size=(200, 1))
    z = rng.normal(size=(1, 200, 1))
    rls = RecursiveLeastSquares(order=3, forgetting="fixed", lambda0=1.0, delta=10.0)
    est = rls.run(None, z, u)
    phi = rls.regressors(u[None])[0]
    W = np.linalg.solve(phi.T @ phi + np.eye(phi.shape[1]) / 10.0, phi.T @ z[0])
    assert est.y_hat[0, -1] == pytest.approx(phi[-1] @ W, rel=1e-9)
    forgetful = RecursiveLeastSquares(order=3, forgetting="fixed", lambda0=0.9,
                                      delta=10.0).run(None, z, u)
    assert abs(forgetful.y_hat[0, -1, 0] - est.y_hat[0, -1, 0]) > 1e-3


def test_rls_reports_the_sine_regressors_poor_excitation_and_p_max_bounds_it():
    """A sampled sine excites 2 lag directions plus the bias: rank 3 of 11 regressors; the
    unexcited part of P grows under forgetting unless the bounded-P variant caps it."""
    k = np.arange(2000)
    u = np.sin(2 * np.pi * k / 10)[:, None]
    z = (0.3 * u + 0.5 * np.random.default_rng(8).normal(size=(2000, 1)))[None]
    est = RecursiveLeastSquares(order=10).run(None, z, u)
    d = est.diagnostics
    assert d["regressor_rank"][0] == 3 and d["regressor_size"][0] == 11
    assert d["lambda_at_floor"][0] > 0.1
    assert d["p_max_eig"][0] > 1e6
    bounded = RecursiveLeastSquares(order=10, p_max=1e3).run(None, z, u)
    assert bounded.diagnostics["p_max_eig"][0] <= 1e3 * (1 + 1e-9)


def test_divergence_needs_the_stated_number_of_consecutive_steps_out_of_range():
    """The estimate outside the physical range on 4 steps in a row is not divergence at 5;
    on 5 it is, and steps outside that are not consecutive never are."""
    steps = 20
    y = np.zeros((3, steps, 1))
    y[0, 3:7] = 10.0                       # 4 in a row
    y[1, 3:8] = 10.0                       # 5 in a row
    y[2, ::2] = 10.0                       # every other step
    est = Estimate(y_hat=y, innovation=y, broken=np.zeros(3, bool))
    flagged = health.diverged(est, None, (-1.0, 1.0), consecutive=5)
    assert flagged.tolist() == [False, True, False]


def test_a_run_notes_each_estimator_that_broke_in_every_run_of_some_rows():
    """estim run's printout of an estimation config: a line per estimator whose every run
    broke in some rows, none for one that kept some runs."""
    import pandas as pd

    from estim.experiments import estimation
    from estim.experiments.base import Result
    from estim.experiments.estimation import printing

    rmse = pd.DataFrame({
        "measurement": ["noisy"] * 4, "noise_reading": ["sigma"] * 4, "noise_param": [0.1] * 4,
        "frequency_hz": [100.0, 100.0, 1000.0, 1000.0], "estimator": ["UKF", "EKF"] * 2,
        "rmse": [float("inf"), 0.1, float("inf"), float("inf")], "runs": [5] * 4,
        "diverged": [5, 0, 5, 4]})
    lines = printing.broken_lines(rmse)
    assert lines == [lines[0]] and lines[0].startswith("note: UKF broke in every run of 2 of 2 "
                                                       "rows")
    text = estimation.printout(Result(tables={"rmse": rmse}))
    assert text.splitlines()[-1] == lines[0]
