"""The optimum differentiator from Kalman theory: closed form, discrete filter, refusal."""

import numpy as np
import pytest
from scipy import linalg

from estim.estimators import kalman_differentiator as kd

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


@pytest.mark.slow
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


def test_with_bandwidth_tracks_a_ramp_exactly_and_lags_a_sine_as_the_closed_form():
    """The double integrator's differentiator has zero steady-state error on a ramp (type 2),
    and on a sine its steady-state output is the sine's derivative through
    ``s w0^2 / (s^2 + sqrt(2) w0 s + w0^2)``, to within one sample of phase (the discrete
    filter's update with the current sample)."""
    dt, f, f0 = 1e-5, 100.0, 400.0
    t = np.arange(4001) * dt
    ramp = np.stack([3.0 * t + 0.2, -7.0 * t], axis=-1)[None]
    d = kd.with_bandwidth(ramp, dt, f0)
    np.testing.assert_allclose(d[0, -500:], [[3.0, -7.0]] * 500, rtol=1e-6)
    w, w0 = 2 * np.pi * f, 2 * np.pi * f0
    d = kd.with_bandwidth(np.sin(w * t)[None, :, None], dt, f0)[0, :, 0]
    gain = 1j * w * w0**2 / ((1j * w) ** 2 + np.sqrt(2) * w0 * 1j * w + w0**2)
    expected = np.abs(gain) * np.sin(w * t + np.angle(gain))
    tail = slice(-1000, None)
    assert np.max(np.abs(d[tail] - expected[tail])) < w * (w * dt)   # a sample's phase
