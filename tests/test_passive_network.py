"""The passive-network estimator paper: eq 19 is the Kalman-Bucy filter when u = q."""

import copy

import numpy as np
import pandas as pd
import yaml

from estim.config.loading import parse_data, quick_data
from estim.estimators import passive_network as pn
from estim.experiments import passive_network as analysis


def test_eq19_with_u_equal_q_is_the_kalman_bucy_filter():
    rng = np.random.default_rng(0)
    dt, steps, q, r, H = 0.01, 800, 1.0, 0.5, 0.5
    z = 0.5 * np.exp(-dt * np.arange(steps)) + 0.1 * rng.standard_normal((3, steps))
    ours = pn.estimator(z, dt, u=q, x0=1.0, v0=2.0, kind="eq19")
    # Kalman-Bucy for x' = -x + w, z = H x + v: K = P H / r, P' = -2P - P^2 H^2 / r + q
    x, P = np.ones(3), np.full(3, 2.0 * r / H)      # V = P H / r starts at 2
    for k in range(steps):
        K = P * H / r
        x, P = x + dt * (-x + K * (z[:, k] - H * x)), P + dt * (-2 * P - P**2 * H**2 / r + q)
        assert np.allclose(ours[:, k], x, rtol=1e-12, atol=1e-12)
    stationary = -2 + np.sqrt(4 + 2 * q)                # root of -2V - V^2/2 + q = 0
    assert abs(P[0] * H / r - stationary) < 1e-6


def test_the_table_is_deterministic_under_its_seed():
    spec = yaml.safe_load(open("configs/passive_network.yaml"))
    spec = quick_data(parse_data(copy.deepcopy(spec), "t.yaml", "t", plan=False))
    first = analysis.run(parse_data(copy.deepcopy(spec), "a.yaml", "a")).tables["errors"]
    second = analysis.run(parse_data(copy.deepcopy(spec), "a.yaml", "a")).tables["errors"]
    pd.testing.assert_frame_equal(first, second)
