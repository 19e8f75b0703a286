"""The optimum differentiator from Kalman theory: closed form, discrete filter, refusal."""

import numpy as np
import pytest
from scipy import linalg

from core import kalman_differentiator as kd

F = np.array([[0.0, 1.0], [0.0, 0.0]])
H = np.array([[1.0], [0.0]])


def _G(q):
    return np.array([[0.0], [np.sqrt(q)]])


def test_riccati_solution_is_the_closed_form():
    q, r = 1.0, 1e-4
    P, K = kd.steady_state(F, _G(q), H, r)
    c = kd.double_integrator(q, r)
    assert P[1, 1] == pytest.approx(c["P22"], rel=1e-9)
    assert K[:, 0] == pytest.approx([c["K1"], c["K2"]], rel=1e-9)
    assert c["P22"] == pytest.approx(0.1414, abs=1e-4)


def test_frequency_response_is_the_closed_form_up_to_20_hz():
    q, r = 1.0, 1e-4
    _, K = kd.steady_state(F, _G(q), H, r)
    w0 = kd.double_integrator(q, r)["w0"]
    f = np.linspace(0.1, 20.0, 50)
    s = 2j * np.pi * f
    closed = s * w0**2 / (s**2 + np.sqrt(2) * w0 * s + w0**2)
    assert np.max(np.abs(kd.frequency_response(F, H, K, f) - closed) / np.abs(closed)) < 1e-3


def test_monte_carlo_derivative_error_matches_the_discrete_riccati():
    q, r, dt, runs, steps = 1.0, 1e-4, 1e-3, 1000, 5000   # ~4e4 independent samples
    rng = np.random.default_rng(11)
    Phi, Qd = kd.discretize(F, _G(q), dt)
    L = np.linalg.cholesky(Qd)
    x = np.zeros((runs, 2))
    xs = np.empty((runs, steps, 2))
    for k in range(steps):
        x = x @ Phi.T + rng.standard_normal((runs, 2)) @ L.T
        xs[:, k] = x
    z = xs[..., :1] + np.sqrt(r / dt) * rng.standard_normal((runs, steps, 1))
    out = kd.differentiate(z, F, _G(q), H, r, dt)
    err = out["derivative"][:, 1000:, 0] - xs[:, 1000:, 1]         # after 1 s (10/w0)
    Pd = linalg.solve_discrete_are(Phi.T, H, Qd, np.array([[r / dt]]))
    # the filtered (a posteriori) covariance of the derivative
    S = H.T @ Pd @ H + r / dt
    P_post = Pd - Pd @ H @ np.linalg.inv(S) @ H.T @ Pd
    assert np.mean(err**2) == pytest.approx(P_post[1, 1], rel=0.03)
    assert P_post[1, 1] == pytest.approx(0.1409, abs=5e-4)


def test_a_model_whose_derivative_holds_white_noise_is_refused():
    with pytest.raises(ValueError, match="H'G != 0"):
        kd.differentiate(np.zeros((1, 5, 1)), F, np.array([[1.0], [0.0]]), H, 1e-4, 1e-3)
