import numpy as np
import pytest

from estim.models.diffamp_em import DiffAmpEbersMoll
from estim.numerics.simulate import simulate


def test_jacobian_matches_finite_differences():
    model = DiffAmpEbersMoll()
    x0 = model.operating_point()
    x = np.stack([x0, x0 + [0.01, 1e-7, 0.1, -0.2]])
    u = np.array([[1.001, 0.999], [1.0, 1.01]])
    eps = 1e-7
    numeric = np.stack([(model.f(x + eps * e, u) - model.f(x - eps * e, u)) / (2 * eps)
                        for e in np.eye(4)], axis=-1)
    J = model.jacobian(x, u)
    assert np.max(np.abs(J - numeric)) <= 1e-6 * np.max(np.abs(J))


def test_dc_operating_point_is_forward_active_and_balanced():
    model = DiffAmpEbersMoll()
    p = model.params
    vE, qL, vC1, vC2 = model.operating_point()
    assert vC1 == pytest.approx(vC2, abs=1e-9) and qL == pytest.approx(0.0, abs=1e-15)
    assert 1.0 - vC1 < 0                                   # base-collector reverse biased
    tail = (vE - p.V_EE) / p.R_E
    ic = (p.V_CC - vC1) / p.R_C1
    assert 2 * ic == pytest.approx(p.alpha_F * tail, rel=1e-6)
    assert 0.6 < 1.0 - vE < 0.7                            # a silicon V_BE


def test_printed_tail_resistor_saturates_both_transistors():
    """circuit-facts.md: with R_E = 100 Ohm the tail current is ~0.1 A and V_BC > 0."""
    vE, _, vC1, vC2 = DiffAmpEbersMoll("thesis_printed").operating_point()
    assert 1.0 - vC1 > 0.5 and 1.0 - vC2 > 0.5


def test_small_signal_gain_matches_hand_formula():
    model = DiffAmpEbersMoll()
    p = model.params
    x0 = model.operating_point()
    ic = (p.V_CC - x0[2]) / p.R_C1
    gm = ic / p.V_T
    expected = gm * (p.R_C1 * (p.R_L / 2) / (p.R_C1 + p.R_L / 2))
    f, vd, dt, steps = 1000.0, 1e-4, 1e-5, 400
    t = np.arange(steps + 1) * dt
    half = 0.5 * vd * np.sin(2 * np.pi * f * t)
    source = np.stack([1.0 + half, 1.0 - half], axis=-1)[None]
    y = model.h(simulate(model, x0, model.source_to_input(source, dt), dt))[0, 200:, 0]
    gain = np.ptp(y) / 2 / vd
    assert gain == pytest.approx(expected, rel=0.02)
    assert 20 * np.log10(gain) == pytest.approx(23.5, abs=0.2)


def test_printed_q_in_volts_keeps_the_output_gain_below_one():
    """Table 3.5's Q = diag(0.01), printed without units, read as voltage variances (D36).
    Read instead as the variance of the charge state q_L (C^2) it is 1e8 V^2 on the load
    capacitor: the first update's
    gain on the output is 1 and the EKF returns the measurement. Mapped by the model's
    state scales (C_L for q_L) the gain stays well below 1."""
    from estim.estimators.ekf import ExtendedKalmanFilter
    from estim.numerics import discretize

    model = DiffAmpEbersMoll()
    u = np.array([1.0, 1.0])
    x = model.operating_point(u=u)
    H = model.h_jacobian(x)
    gains = {}
    for units in ("thesis", "state"):
        ekf = ExtendedKalmanFilter(Q=[0.01] * 4, R=0.1, P0=[0.01] * 4, noise_units=units)
        Q, P0 = ekf.state_covariances(model)
        _, F = discretize.step(model, x[None], u[None], 1e-4, "exponential")
        P = F[0] @ P0 @ F[0].T + Q
        S = H @ P @ H.T + 0.1
        gains[units] = float((H @ P @ H.T / S)[0, 0])
    assert gains["state"] > 0.999999
    assert gains["thesis"] < 0.5
    assert model.state_scales == (1.0, model.params.C_L, 1.0, 1.0)
