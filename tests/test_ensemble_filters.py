"""The ensemble Kalman filter and the bootstrap particle filter: on a linear Gaussian model
both approach the Kalman filter as their members grow; their draws come only from the
generator they are given; a broken run is frozen as in the other filters."""

from __future__ import annotations

import numpy as np
import pytest

from estim.estimators.base import takes_generator
from estim.estimators.bootstrap_pf import BootstrapParticleFilter
from estim.estimators.enkf import EnsembleKalmanFilter
from estim.estimators.kf import KalmanFilter

SETTINGS = dict(Q=[1e-3, 2e-3], R=0.1, P0=[0.2, 0.2], x0=[0.5, 0.0])


def kalman(oscillator, z, u, dt):
    Ad, Bd = oscillator.discrete(dt)
    return KalmanFilter(A=Ad, B=Bd, C=oscillator.C, **SETTINGS).run(oscillator, z, u, dt)


def measured(oscillator, rng, runs: int, steps: int, dt: float):
    """Measurements of the model the filters assume (its process and measurement noise),
    and the input."""
    Ad, Bd = oscillator.discrete(dt)
    u = rng.normal(size=(steps, 1))
    x = np.broadcast_to([0.5, 0.0], (runs, 2)) + rng.normal(size=(runs, 2)) * np.sqrt(0.2)
    z = np.empty((runs, steps, 1))
    for k in range(steps):
        x = x @ Ad.T + u[k] @ Bd.T + rng.normal(size=(runs, 2)) * np.sqrt([1e-3, 2e-3])
        z[:, k] = x @ np.asarray(oscillator.C).T + rng.normal(size=(runs, 1)) * np.sqrt(0.1)
    return z, u


@pytest.mark.parametrize("cls, members, mean_bar, cov_bar", [
    (EnsembleKalmanFilter, 4000, 0.2, 0.15),
    (BootstrapParticleFilter, 8000, 0.2, 0.2)])
def test_many_members_approach_the_kalman_filter(oscillator, cls, members, mean_bar, cov_bar):
    """On measurements of the model they assume, with thousands of members the estimate is
    the KF's to a fraction of the KF's own standard deviation, and the covariance the KF's
    to a fraction of itself; with ten members the estimate is visibly further off."""
    dt = 0.05
    z, u = measured(oscillator, np.random.default_rng(3), 2, 100, dt)
    exact = kalman(oscillator, z, u, dt)
    sd = np.sqrt(exact.P_diag)

    def off(count):
        est = cls(members=count, **SETTINGS).run(oscillator, z, u, dt,
                                                 rng=np.random.default_rng(7))
        assert not est.broken.any()
        return est, np.max(np.abs(est.x_hat - exact.x_hat) / sd)

    est, many = off(members)
    assert many < mean_bar
    assert np.max(np.abs(est.P_diag / exact.P_diag - 1)) < cov_bar
    assert off(10)[1] > 2 * many


@pytest.mark.parametrize("cls", [EnsembleKalmanFilter, BootstrapParticleFilter])
def test_draws_come_from_the_generator_given(oscillator, cls):
    dt = 0.05
    rng = np.random.default_rng(4)
    z, u = rng.normal(size=(3, 30, 1)), rng.normal(size=(30, 1))
    f = cls(members=50, **SETTINGS)
    assert takes_generator(f)
    a = f.run(oscillator, z, u, dt, rng=np.random.default_rng(1))
    b = f.run(oscillator, z, u, dt, rng=np.random.default_rng(1))
    c = f.run(oscillator, z, u, dt, rng=np.random.default_rng(2))
    assert a.x_hat.tobytes() == b.x_hat.tobytes()
    assert not np.array_equal(a.x_hat, c.x_hat)
    assert f.run(oscillator, z, u, dt).x_hat.tobytes() == \
        f.run(oscillator, z, u, dt).x_hat.tobytes()          # no generator: a fixed seed


@pytest.mark.parametrize("cls", [EnsembleKalmanFilter, BootstrapParticleFilter])
def test_a_run_that_leaves_the_bound_is_broken_and_frozen(oscillator, cls):
    dt = 0.05
    rng = np.random.default_rng(5)
    z, u = 0.1 * rng.normal(size=(3, 40, 1)), np.zeros((40, 1))
    z[1, 10:] = 1e4                     # the EnKF follows it; the particle filter's likeliest
    f = cls(members=200, divergence_bound=50.0, **{**SETTINGS, "R": 1e-4})
    est = f.run(oscillator, z, u, dt, rng=np.random.default_rng(0))
    if cls is BootstrapParticleFilter:  # particle stays within the bound: nothing breaks
        assert not est.broken.any()
        return
    assert est.broken.tolist() == [False, True, False]
    first = np.flatnonzero(np.isnan(est.x_hat[1, :, 0]))[0]
    assert first == 10 and np.isnan(est.P[1, first:]).all()
    assert np.isfinite(est.x_hat[[0, 2]]).all()
