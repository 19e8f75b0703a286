"""Maximum-likelihood noise fitting (estim.experiments.shared.tuning)."""

import numpy as np
import pytest

from estim.estimators.ekf import ExtendedKalmanFilter
from estim.experiments.shared import tuning


def simulate(model, q, r, runs, steps, dt, seed):
    """A discrete linear-Gaussian system with process noise ``q`` (diagonal) per step."""
    Ad, Bd = model.discrete(dt)
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(steps, 1))
    x = np.zeros((runs, 2))
    z = np.empty((runs, steps, 1))
    for k in range(steps):
        x = x @ Ad.T + u[k] @ Bd.T + rng.normal(size=(runs, 2)) * np.sqrt(q)
        z[:, k] = x @ model.C.T + rng.normal(size=(runs, 1)) * np.sqrt(r)
    return z, u


@pytest.mark.slow
def test_fit_recovers_a_known_q_within_its_standard_error(oscillator):
    q_true, r = np.array([4e-3, 1e-2]), 0.05
    z, u = simulate(oscillator, q_true, r, runs=40, steps=300, dt=0.1, seed=21)

    def evaluate(q, r_):
        est = ExtendedKalmanFilter(Q=list(q), R=list(r_), P0=[1e-6, 1e-6], x0=[0.0, 0.0])
        out = est.run(oscillator, z, u, 0.1)
        return tuning.log_likelihood(out.innovation, out.S)

    fit = tuning.fit(evaluate, q0=[1e-1, 1e-4], r0=[r])
    assert fit.identifiable
    assert fit.log_likelihood > fit.log_likelihood_start
    assert np.all(np.isfinite(fit.q_se)) and np.all(fit.q_se < 0.5 * fit.q)
    assert np.all(np.abs(fit.q - q_true) < 3 * fit.q_se), (fit.q, fit.q_se)


def test_fit_says_when_q_and_r_cannot_be_told_apart(linear_model):
    """A state that forgets itself within one step is white noise of variance Q; measured
    with noise R, only Q + R reaches the innovations: the split is not identifiable, the
    sum is."""
    static = linear_model([[-1e6]], [[0.0]], [[1.0]])      # forgets at once: x_k ~ N(0, Q)
    z = np.random.default_rng(22).normal(size=(20, 200, 1)) * np.sqrt(0.3)
    u = np.zeros((200, 1))

    def evaluate(q, r_):
        out = ExtendedKalmanFilter(Q=list(q), R=list(r_), P0=[0.1], x0=[0.0]).run(
            static, z, u, 1.0)
        return tuning.log_likelihood(out.innovation, out.S)

    seen = []
    fit = tuning.fit(evaluate, q0=[0.1], r0=[0.1], fit_r=True,
                     progress=lambda n, best: seen.append((n, best)))
    assert not fit.identifiable
    assert "not identifiable" in fit.message
    assert abs(fit.q[0] + fit.r[0] - 0.3) < 0.05
    # the message says why, and that the fit still raised the likelihood
    assert "some combination of the entries leaves the likelihood flat" in fit.message or \
        "curvature at the optimum is not positive definite" in fit.message, fit.message
    assert f"from {fit.log_likelihood_start:.6g} to {fit.log_likelihood:.6g}" in fit.message
    # progress after every evaluation, with the best log-likelihood so far
    assert [n for n, _ in seen] == list(range(1, fit.evaluations + 1))
    best = [b for _, b in seen]
    assert best == sorted(best) and best[-1] >= fit.log_likelihood


def test_log_likelihood_is_minus_infinity_for_a_broken_run():
    nu = np.zeros((2, 3, 1))
    nu[1, 2, 0] = np.nan
    assert tuning.log_likelihood(nu, np.ones((2, 3, 1, 1))) == -np.inf


def test_a_lost_step_scores_below_any_plausible_step():
    """With R given, a broken run's missing steps cost a 10-sigma innovation each: a batch
    that loses steps scores below the same batch whole, yet stays finite."""
    rng = np.random.default_rng(23)
    nu = rng.normal(size=(2, 50, 1)) * 0.1
    S = np.full((2, 50, 1, 1), 0.01)
    whole = tuning.log_likelihood(nu, S, R=np.array([[0.01]]))
    assert whole == tuning.log_likelihood(nu, S)
    nu[1, 30:] = np.nan
    S[1, 30:] = np.nan
    broken = tuning.log_likelihood(nu, S, R=np.array([[0.01]]))
    assert np.isfinite(broken) and broken < whole - 20 * 0.5 * (tuning.LOST_STEP_NIS - 1)


def test_estim_tune_reports_progress_on_standard_error(capsys):
    import time

    from estim.cli.output import tune_progress

    report = tune_progress(time.perf_counter() - 10, every=5.0)
    report(12, -345.678)
    report(13, -340.0)                      # within 5 s of the last line: not printed
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("tune: 12 likelihood evaluations, best "
                                               "log-likelihood -345.678, 10 s")


def test_estim_tune_takes_q_by_state_name_and_refuses_estimated_values(tmp_path):
    """rlc_current_ekf gives Q and P0 by state name: estim tune fits it (it raised a
    TypeError reading the names as a matrix), its overlay a Q diagonal in the states'
    order; rlc_current_r1 carries R1 as a state: one line before any work."""
    from pathlib import Path

    import yaml
    from click.testing import CliRunner

    from estim.cli.main import main

    configs = Path(__file__).resolve().parents[1] / "configs" / "netlist"
    out = tmp_path / "tuned.yaml"
    result = CliRunner().invoke(main, ["tune", str(configs / "rlc_current_ekf.yaml"),
                                       "--estimator", "EKF", "--runs", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    fitted = yaml.safe_load(out.read_text())["estimators"][0]["settings"]["Q"]
    assert len(fitted) == 2 and all(q > 0 for q in fitted)
    refused = CliRunner().invoke(main, ["tune", str(configs / "rlc_current_r1.yaml"),
                                        "--estimator", "EKF", "--runs", "2"])
    assert refused.exit_code == 2, refused.output
    assert "carry element values (estimate) as states" in refused.output
    assert "Traceback" not in refused.output
