from pathlib import Path

import numpy as np
import pytest
from scipy import linalg

from estim.config import registry
from estim.estimators.base import Estimate
from estim.estimators.ekf import ExtendedKalmanFilter
from estim.estimators.kf import KalmanFilter
from estim.estimators.rls import RecursiveLeastSquares
from estim.estimators.ukf import UnscentedKalmanFilter
from estim.models.mosfet_ekv import MosfetEKV
from estim.numerics import discretize

ROOT = Path(__file__).resolve().parents[1]


def test_kf_reaches_closed_form_steady_state_scalar():
    a, c, q, r = 0.9, 1.0, 0.04, 0.25
    kf = KalmanFilter(A=a, B=0.0, C=c, Q=q, R=r, x0=0.0, P0=10.0)
    z = np.random.default_rng(0).normal(size=(1, 300, 1))
    est = kf.run(None, z, np.zeros((300, 1)))
    prior = linalg.solve_discrete_are(np.array([[a]]), np.array([[c]]), np.array([[q]]),
                                      np.array([[r]]))[0, 0]
    gain = prior * c / (c * c * prior + r)
    posterior = (1 - gain * c) * prior
    assert est.P_diag[0, -1, 0] == pytest.approx(posterior, rel=1e-10)
    assert est.P_diag[0, 5, 0] != pytest.approx(posterior, rel=1e-3)


def test_ekf_on_linear_model_equals_kf(oscillator):
    dt = 0.05
    rng = np.random.default_rng(1)
    z = rng.normal(size=(3, 200, 1))
    u = rng.normal(size=(200, 1))
    Ad, Bd = oscillator.discrete(dt)
    settings = dict(Q=[1e-3, 2e-3], R=0.1, P0=[1.0, 1.0])
    kf = KalmanFilter(A=Ad, B=Bd, C=oscillator.C, x0=[0.5, 0.0], **settings)
    ekf = ExtendedKalmanFilter(x0=[0.5, 0.0], discretization="exponential", **settings)
    a, b = kf.run(oscillator, z, u, dt), ekf.run(oscillator, z, u, dt)
    np.testing.assert_allclose(b.x_hat, a.x_hat, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.P_diag, a.P_diag, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(b.innovation, a.innovation, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("params, atol", [
    (dict(alpha=1.0), 1e-10), (dict(alpha=0.5, beta=0.0, kappa=1.0), 1e-10),
    # the default spread: the centre's weight is -1e6, so the weighted sums cancel to
    # 1e6 times the rounding of a state of about 1 (2e-10 seen): the same equality, at that floor
    (dict(), 2e-9)])
def test_ukf_on_linear_model_equals_kf(oscillator, params, atol):
    dt = 0.05
    rng = np.random.default_rng(11)
    z, u = rng.normal(size=(3, 200, 1)), rng.normal(size=(200, 1))
    Ad, Bd = oscillator.discrete(dt)
    settings = dict(Q=[1e-3, 2e-3], R=0.1, P0=[1.0, 1.0], x0=[0.5, 0.0])
    a = KalmanFilter(A=Ad, B=Bd, C=oscillator.C, **settings).run(oscillator, z, u, dt)
    b = UnscentedKalmanFilter(**settings, **params).run(oscillator, z, u, dt)
    np.testing.assert_allclose(b.x_hat, a.x_hat, rtol=0, atol=atol)
    np.testing.assert_allclose(b.P, a.P, rtol=0, atol=atol)
    np.testing.assert_allclose(b.S, a.S, rtol=0, atol=atol)


def test_ukf_differs_from_ekf_on_a_nonlinear_model():
    """The sigma points see the curvature of the exponential law that the EKF's Jacobian
    does not: the two filters agree closely but not exactly."""
    model = MosfetEKV(V_IN=0.435, drain_current="weak_saturation")
    x0 = model.operating_point()
    rng = np.random.default_rng(12)
    z = x0[3] + 0.1 * rng.normal(size=(2, 40, 1))
    u = 50 * rng.normal(size=(40, 1))
    settings = dict(Q=[0.0025, 0.002, 0.002, 0.002], R=0.01, P0=[0.0025, 0.002, 0.002, 0.002])
    a = ExtendedKalmanFilter(**settings).run(model, z, u, 1e-4, x0=x0)
    b = UnscentedKalmanFilter(**settings).run(model, z, u, 1e-4, x0=x0)
    gap = np.abs(a.y_hat - b.y_hat).max()
    assert 1e-6 < gap < 0.5


def test_kf_and_ekf_start_from_the_x0_given_to_run(oscillator):
    """Without an ``x0`` setting both filters start from the run's ``x0`` (the analyses pass
    the actual operating point there) and still agree."""
    dt = 0.05
    rng = np.random.default_rng(3)
    z, u = rng.normal(size=(2, 30, 1)), rng.normal(size=(30, 1))
    Ad, Bd = oscillator.discrete(dt)
    settings = dict(Q=[1e-9, 1e-9], R=0.1, P0=[1e-9, 1e-9])
    start = np.array([2.0, -1.0])
    a = KalmanFilter(A=Ad, B=Bd, C=oscillator.C, **settings).run(oscillator, z, u, dt, x0=start)
    b = ExtendedKalmanFilter(**settings).run(oscillator, z, u, dt, x0=start)
    np.testing.assert_allclose(a.x_hat, b.x_hat, rtol=1e-9, atol=1e-12)
    assert np.abs(a.x_hat[:, 0, 0] - (Ad @ start + Bd @ u[0])[0]).max() < 1e-3


def test_continuous_discrete_ekf_on_linear_model_matches_kf(oscillator):
    dt = 0.05
    rng = np.random.default_rng(7)
    z, u = rng.normal(size=(2, 40, 1)), rng.normal(size=(40, 1))
    Ad, Bd = oscillator.discrete(dt)
    settings = dict(Q=[1e-3, 2e-3], R=0.1, P0=[1.0, 1.0], x0=[0.5, 0.0])
    a = KalmanFilter(A=Ad, B=Bd, C=oscillator.C, **settings).run(oscillator, z, u, dt)
    b = ExtendedKalmanFilter(discretization="radau", **settings).run(oscillator, z, u, dt)
    np.testing.assert_allclose(b.x_hat, a.x_hat, atol=1e-6)


def test_euler_discretisation_is_the_thesis_first_order_form(oscillator):
    x = np.array([[1.0, -0.5]])
    u = np.array([[0.2]])
    xn, F = discretize.step(oscillator, x, u, 0.01, "euler")
    np.testing.assert_allclose(F[0], np.eye(2) + 0.01 * oscillator.A)
    np.testing.assert_allclose(xn, x + 0.01 * oscillator.f(x, u))


@pytest.mark.parametrize("method", ["rosenbrock", "exponential"])
def test_stable_discretisations_converge_to_exact_flow(oscillator, method):
    x = np.array([[1.0, -0.5]])
    u = np.array([[0.2]])
    Ad, Bd = oscillator.discrete(0.1)
    exact = x @ Ad.T + u @ Bd.T
    coarse = np.abs(discretize.step(oscillator, x, u, 0.1, method, 1)[0] - exact).max()
    fine = np.abs(discretize.step(oscillator, x, u, 0.1, method, 16)[0] - exact).max()
    assert fine <= coarse * 0.2 or fine < 1e-12


def test_rls_recovers_known_fir_in_noise():
    rng = np.random.default_rng(2)
    taps = np.array([0.5, -0.3, 0.2, 0.1])
    u = rng.normal(size=(2000, 1))
    y = np.convolve(u[:, 0], taps)[: len(u)]      # z[k] follows the input interval u[k]
    sigma = 0.1
    z = (y + sigma * rng.normal(size=y.shape))[None, :, None]
    rls = RecursiveLeastSquares(order=4, chi=1e9, forgetting="fixed", lambda0=1.0, lambda_min=1.0,
                                bias=False)
    est = rls.run(None, z, u)
    err = est.y_hat[0, -500:, 0] - y[-500:]
    assert np.sqrt(np.mean(err**2)) < 0.1 * sigma
    assert np.sqrt(np.mean(est.innovation[0, -500:, 0] ** 2)) == pytest.approx(sigma, rel=0.15)


def test_batched_and_single_run_filtering_agree():
    model = MosfetEKV(V_IN=0.435, drain_current="weak_saturation")
    x0 = model.operating_point()
    rng = np.random.default_rng(3)
    z = x0[3] + 0.1 * rng.normal(size=(4, 60, 1))
    u = 50 * rng.normal(size=(60, 1))
    for est in (ExtendedKalmanFilter(Q=1e-3, R=0.01, P0=1e-3), RecursiveLeastSquares()):
        batch = est.run(model, z, u, 1e-4, x0=x0)
        for r in range(4):
            one = est.run(model, z[r:r + 1], u, 1e-4, x0=x0)
            np.testing.assert_allclose(one.y_hat[0], batch.y_hat[r], rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(one.innovation[0], batch.innovation[r], rtol=1e-12,
                                       atol=1e-14)


@pytest.mark.parametrize("name", sorted(registry.ESTIMATORS))
def test_every_estimator_returns_an_estimate(name, oscillator):
    """The conformance test over the registry: each estimator's own example settings."""
    cls = registry.ESTIMATORS[name]
    est = cls.example(oscillator)
    est.validate(oscillator)
    z = np.random.default_rng(4).normal(size=(5, 30, 1))
    out = est.run(oscillator, z, np.zeros((30, 1)), 0.1)
    assert isinstance(out, Estimate)
    assert out.y_hat.shape == z.shape and out.innovation.shape == z.shape
    assert out.broken.shape == (5,)
    assert set(est.to_spec()) == set(cls.schema()), "every setting is in its spec"


def test_joseph_covariance_stays_symmetric_positive_definite(oscillator):
    ekf = ExtendedKalmanFilter(Q=[1e-6, 1e-6], R=1e-4, P0=[10.0, 10.0], x0=[0.0, 0.0])
    z = np.random.default_rng(5).normal(size=(2, 400, 1))
    est = ekf.run(oscillator, z, np.zeros((400, 1)), 0.05)
    np.testing.assert_array_equal(est.P, np.swapaxes(est.P, -1, -2))
    assert np.all(np.linalg.eigvalsh(est.P) > 0)


def test_printed_taylor_model_diverges_and_is_reported():
    model = MosfetEKV(V_IN=0.435, drain_current="taylor_saturation")
    x0 = MosfetEKV(V_IN=0.435).operating_point()
    z = x0[3] + 0.1 * np.random.default_rng(6).normal(size=(3, 50, 1))
    est = ExtendedKalmanFilter(Q=0.002, R=0.01, P0=0.002).run(model, z, np.zeros((50, 1)),
                                                               1e-3, x0=x0)
    assert est.broken.all()
    assert np.isnan(est.y_hat[:, -1]).all()


def test_q_and_p0_by_state_name_are_the_diagonal_in_the_models_order():
    """``{state: variance}`` (``"*"`` for the rest) gives the same filter as the diagonal in
    the model's state order, whatever order the names come in."""
    model = MosfetEKV(V_IN=0.435, drain_current="weak_saturation")
    x0 = model.operating_point()
    rng = np.random.default_rng(4)
    z = x0[3] + 0.05 * rng.standard_normal((3, 40, 1))
    u = np.zeros((40, 1))
    listed = ExtendedKalmanFilter(Q=[1e-4, 2e-4, 2e-4, 3e-4], R=0.01, P0=[1e-3, 2e-3, 2e-3, 2e-3],
                                  noise_units="state")
    named = ExtendedKalmanFilter(Q={"v_D": 3e-4, "v_G": 1e-4, "*": 2e-4}, R=0.01,
                                 P0={"v_G": 1e-3, "v_B": 2e-3, "v_S": 2e-3, "v_D": 2e-3},
                                 noise_units="state")
    a = listed.run(model, z, u, 1e-4, x0)
    b = named.run(model, z, u, 1e-4, x0)
    np.testing.assert_array_equal(a.x_hat, b.x_hat)
    np.testing.assert_array_equal(a.P, b.P)


@pytest.mark.parametrize("Q, message", [
    ({"v_G": 1e-4, "v_X": 1e-4, "*": 1e-4}, "Q: no state named 'v_X'; the states are v_G, "
                                            "v_B, v_S, v_D"),
    ({"v_G": 1e-4, "v_D": 1e-4}, "Q: no variance for v_B, v_S: name every state or give '*'"),
    ({"v_G": -1.0, "*": 1e-4}, "Q: expected a mapping of state names to variances (numbers "
                               ">= 0), got"),
])
def test_a_wrong_state_name_in_a_config_is_one_error_at_its_key_path(Q, message):
    """An unknown name, or a state left without a variance, fails when the config is loaded,
    at the setting's key path, naming the model's states."""
    from estim.config.loading import load_file
    from estim.errors import ConfigError

    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    with pytest.raises(ConfigError) as caught:
        load_file(root / "configs" / "mosfet_saturation.yaml",
                  {"estimators.0.settings.Q": Q, "estimators.0.settings.noise_units": "state"})
    assert "estimators[0].settings.Q" in str(caught.value)
    assert message in str(caught.value)


def test_a_kf_refuses_q_by_state_name():
    """A KF's matrices are its settings: it has no model whose states could name the rows."""
    from estim.errors import SettingError

    with pytest.raises(SettingError, match="given by state name, but this filter has no model"):
        KalmanFilter(A=[[1.0]], B=[[0.0]], C=[[1.0]], Q={"x": 1.0}, R=1.0, P0=1.0)


def test_the_default_sigma_point_spread_keeps_the_amplifiers_ukf_where_alpha_1_breaks_it():
    """Issue 47, item 7: the unscaled transform (alpha 1) puts the UKF's sigma points so far
    out on the amplifier's emitter node that every run of a row breaks (D39); the default
    spread runs the same row with no run broken, as the config's own alpha 0.1 does."""
    import pandas as pd
    import yaml

    import estim

    spec = yaml.safe_load((ROOT / "configs" / "diffamp_ekf.yaml").read_text())
    entry = next(e for e in spec["estimators"] if e["label"] == "UKF")

    def ukf_row(alpha):
        entry["settings"].pop("alpha", None)
        if alpha is not None:
            entry["settings"]["alpha"] = alpha
        tables = estim.run(spec, quick=True).tables
        return tuple(t[t["estimator"] == "UKF"].iloc[0] for t in (tables["rmse"],
                                                                  tables["health"]))

    (wide, why), (default, fine) = ukf_row(1.0), ukf_row(None)
    assert wide["diverged"] == wide["runs"] and not np.isfinite(wide["rmse"])
    assert default["diverged"] == 0 and np.isfinite(default["rmse"])
    # health.csv says where and why (issue 47, item 7): the emitter node's prediction
    assert (why["first_break_state"], why["first_break_cause"]) == ("v_E",
                                                                   "prediction not finite")
    assert why["first_break_step"] >= 1 and pd.isna(fine["first_break_step"])
