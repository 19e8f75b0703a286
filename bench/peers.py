"""estim beside its peers: the KF, EKF and UKF beside filterpy and dynamax (JAX) at the run
counts people use; the stiff integrator beside scipy and ngspice
(:mod:`peers_integrator`); the LETKF beside DAPPER (:mod:`peers_letkf`).

    pip install '.[bench]' && python bench/peers.py [--rounds 7] \
        [--parts filters integrator letkf] [--dapper-python .venv-dapper/bin/python]

Each part records its own table (peers.csv; peers_integrator.csv and
peers_integrator_matched.csv; peers_letkf.csv). The filters:

The problem is bench_filters.py's: the EKV MOSFET (eq 3.12 law, 4 states), 200 steps, the
exponential discretisation, measured drain voltage. Every library runs the same filter:

* **EKF**. estim: ``ExtendedKalmanFilter.run`` on the whole batch (the compiled loop,
  :mod:`estim.estimators.ekf_compiled`, where numba is installed); filterpy 2.0's
  ``ExtendedKalmanFilter``, its prediction given estim's discretisation
  (:func:`estim.numerics.discretize.step`); dynamax's ``extended_kalman_filter``, its
  dynamics the same exponential step written in JAX with ``F = exp(T J)`` as its derivative
  (a custom JVP; JAX's own derivative of the step would add the derivative of ``J``,
  another filter).
* **UKF** (alpha 1e-3, beta 2, kappa 0: van der Merwe's small spread; at estim's default
  alpha = 1 dynamax's update ``P - K S K^T``, not in Joseph form, loses positive
  definiteness within 3 steps on this circuit and its Cholesky factor is NaN from there).
  estim: ``UnscentedKalmanFilter.run``
  (:mod:`estim.estimators.ukf_compiled`); filterpy's ``UnscentedKalmanFilter`` with
  ``MerweScaledSigmaPoints``, its sigma points redrawn from the prediction before each
  update (estim's and dynamax's filter; filterpy's own update reuses the propagated ones);
  dynamax's ``unscented_kalman_filter``, its dynamics the exponential step in JAX.
* **KF**: the circuit linearised at its operating point and discretised exactly
  (``exp`` of ``[[J, b], [0, 0]] T``), input the source's slope. estim: ``KalmanFilter.run``
  (its compiled loop, :mod:`estim.estimators.kf_compiled`: the covariances once for the
  batch, the means of 32 runs side by side); filterpy's ``KalmanFilter``; dynamax's
  ``lgssm_filter``.

filterpy is looped over runs (timed on at most 20 runs and scaled: its time is linear in
the runs); dynamax runs under ``jax.jit`` and ``jax.vmap`` over runs, in float64, and its
compilation is excluded: each shape is run once before it is timed. dynamax updates with
``z_1`` first and predicts after, so it starts from the filter's own prediction to ``t_1``.

Throughput is run-steps per second, the median of ``rounds`` rounds in which the libraries
alternate, in this process. Agreement is the largest difference of the filtered drain
voltage from estim's on the runs both made.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_filters import Q, filterpy_ekf, problem  # noqa: E402

from estim.estimators.ekf import ExtendedKalmanFilter  # noqa: E402
from estim.estimators.kf import KalmanFilter  # noqa: E402
from estim.estimators.ukf import UnscentedKalmanFilter  # noqa: E402
from estim.numerics import discretize  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RUN_COUNTS = (1, 30, 1000)
STEPS = 200
FILTERPY_RUNS = 20


def jax_dynamics(model, dt):
    """``(jax, jnp, step)``: the exponential step of the MOSFET (eq 3.12 law) in JAX, its
    derivative ``F = exp(T J)`` as the EKF's; ``None`` without dynamax."""
    try:
        import dynamax  # noqa: F401
        import jax
        import jax.numpy as jnp
    except ImportError:
        return None
    jax.config.update("jax_enable_x64", True)
    kind, P = model.kernel()
    P = jnp.asarray(P)
    Is, eta, UT, VT0 = P[1], P[2], P[3], P[4]
    Cinv = P[5:21].reshape(4, 4)
    g, i0, b = P[21:25], P[25:29], P[29:33]
    assert float(P[0]) == 2.0, "the weak_saturation law (eq 3.12)"

    def drift(x, uk):
        vG, vB, vS = x[0], x[1], x[2]
        a_s = ((vG - vB - VT0) / eta - (vS - vB)) / (2 * UT)
        current = Is * jnp.exp(2 * a_s)
        i = g * x + i0 + jnp.array([0.0, 0.0, current, -current])
        return Cinv @ i + uk[0] * b

    jac = jax.jacfwd(drift)
    n = 4

    def exponential(x, uk):
        aug = jnp.zeros((n + 1, n + 1))
        aug = aug.at[:n, :n].set(dt * jac(x, uk)).at[:n, n].set(dt * drift(x, uk))
        return jax.scipy.linalg.expm(aug)

    @jax.custom_jvp
    def step(x, uk):
        return x + exponential(x, uk)[:n, n]

    @step.defjvp
    def step_jvp(primals, tangents):        # F = exp(T J), as estim's EKF (not d/dx of J)
        x, uk = primals
        E = exponential(x, uk)
        return x + E[:n, n], E[:n, :n] @ tangents[0]

    return jax, jnp, step


def batched(jax, jnp, one):
    """``one`` (a filter of one run's ``z``) under ``jit`` and ``vmap``, as numpy in and out."""
    batch = jax.jit(jax.vmap(one))
    return lambda z: np.asarray(batch(jnp.asarray(z)).block_until_ready())


def dynamax_ekf(model, x0, u, dt):
    """A jitted function of ``z (runs, steps, 1)`` giving dynamax's EKF's filtered means, or
    ``None`` without dynamax."""
    made = jax_dynamics(model, dt)
    if made is None:
        return None
    jax, jnp, step = made
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter

    xp, F = discretize.step(model, x0[None], u[:1], dt)
    Pp = F[0] @ np.diag(Q) @ F[0].T + np.diag(Q)
    params = ParamsNLGSSM(initial_mean=jnp.asarray(xp[0]), initial_covariance=jnp.asarray(Pp),
                          dynamics_function=step, dynamics_covariance=jnp.diag(jnp.array(Q)),
                          emission_function=lambda x, uk: x[3:4],
                          emission_covariance=jnp.array([[0.01]]))
    inputs = jnp.asarray(u)
    return batched(jax, jnp, lambda z: extended_kalman_filter(
        params, z, inputs=inputs, output_fields=["filtered_means"]).filtered_means)


def ukf_prediction(ukf, model, x0, u, dt):
    """The UKF's predicted mean and covariance at ``t_1`` from ``(x0, P0 = Q)``."""
    Qm = np.diag(Q)
    X = ukf.sigma_points(x0[None], Qm[None])[0]
    Xp, _ = discretize.step(model, X, np.repeat(u[:1], len(X), axis=0), dt)
    wm, wc = ukf.weights(len(x0))
    xp = wm @ Xp
    D = Xp - xp
    return xp, (wc[:, None] * D).T @ D + Qm


def dynamax_ukf(ukf, model, x0, u, dt):
    """A jitted function of ``z`` giving dynamax's UKF's filtered means, or ``None``."""
    made = jax_dynamics(model, dt)
    if made is None:
        return None
    jax, jnp, step = made
    from dynamax.nonlinear_gaussian_ssm import (
        ParamsNLGSSM,
        UKFHyperParams,
        unscented_kalman_filter,
    )

    xp, Pp = ukf_prediction(ukf, model, x0, u, dt)
    params = ParamsNLGSSM(initial_mean=jnp.asarray(xp), initial_covariance=jnp.asarray(Pp),
                          dynamics_function=step, dynamics_covariance=jnp.diag(jnp.array(Q)),
                          emission_function=lambda x, uk: x[3:4],
                          emission_covariance=jnp.array([[0.01]]))
    hyper = UKFHyperParams(alpha=ukf.alpha, beta=ukf.beta, kappa=ukf.kappa)
    inputs = jnp.asarray(u)
    return batched(jax, jnp, lambda z: unscented_kalman_filter(
        params, z, hyper, inputs=inputs, output_fields=["filtered_means"]).filtered_means)


def filterpy_ukf(ukf, model, x0, z, u, dt):
    from filterpy.kalman import MerweScaledSigmaPoints
    from filterpy.kalman import UnscentedKalmanFilter as FilterpyUKF

    def fx(x, _dt, u):
        return discretize.step(model, x[None], u[None], dt)[0][0]

    points = MerweScaledSigmaPoints(4, alpha=ukf.alpha, beta=ukf.beta, kappa=ukf.kappa)
    out = np.empty(z.shape)
    for r in range(z.shape[0]):
        f = FilterpyUKF(dim_x=4, dim_z=1, dt=dt, hx=lambda x: x[3:4], fx=fx, points=points)
        f.x, f.P, f.Q, f.R = x0.copy(), np.diag(Q), np.diag(Q), np.array([[0.01]])
        for k in range(z.shape[1]):
            f.predict(u=u[k])
            f.sigmas_f = points.sigma_points(f.x, f.P)      # redrawn, as estim's and dynamax's
            f.update(z[r, k])
            out[r, k] = f.x[3]
    return out


def linearised(model, x0, dt):
    """``A, B, C`` of the circuit linearised at ``x0``, discretised exactly over ``dt``."""
    import scipy.linalg

    n = len(x0)
    u0 = np.zeros(model.n_inputs)
    _, J = model.f_and_jacobian(x0, u0)
    b = model.f(x0, np.ones(model.n_inputs)) - model.f(x0, u0)     # the drift is affine in u
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = J * dt, b * dt
    E = scipy.linalg.expm(aug)
    return E[:n, :n], E[:n, n:], np.array([[0.0, 0.0, 0.0, 1.0]])


def filterpy_kf(A, B, C, x0, z, u):
    from filterpy.kalman import KalmanFilter as FilterpyKF

    out = np.empty(z.shape)
    for r in range(z.shape[0]):
        f = FilterpyKF(dim_x=4, dim_z=1, dim_u=1)
        f.F, f.B, f.H = A, B, C
        f.x, f.P, f.Q, f.R = x0[:, None].copy(), np.diag(Q), np.diag(Q), np.array([[0.01]])
        for k in range(z.shape[1]):
            f.predict(u=u[k][:, None])
            f.update(z[r, k])
            out[r, k] = f.x[3, 0]
    return out


def dynamax_kf(A, B, C, x0, u):
    """A jitted function of ``z`` giving dynamax's Kalman filter's filtered means, or
    ``None``."""
    try:
        import jax
        import jax.numpy as jnp
        from dynamax.linear_gaussian_ssm import ParamsLGSSM, lgssm_filter
        from dynamax.linear_gaussian_ssm.inference import (
            ParamsLGSSMDynamics,
            ParamsLGSSMEmissions,
            ParamsLGSSMInitial,
        )
    except ImportError:
        return None
    jax.config.update("jax_enable_x64", True)
    Qm = np.diag(Q)
    xp, Pp = A @ x0 + B @ u[0], A @ Qm @ A.T + Qm
    params = ParamsLGSSM(
        initial=ParamsLGSSMInitial(mean=jnp.asarray(xp), cov=jnp.asarray(Pp)),
        dynamics=ParamsLGSSMDynamics(weights=jnp.asarray(A), bias=jnp.zeros(4),
                                     input_weights=jnp.asarray(B), cov=jnp.asarray(Qm)),
        emissions=ParamsLGSSMEmissions(weights=jnp.asarray(C), bias=jnp.zeros(1),
                                       input_weights=jnp.zeros((1, 1)),
                                       cov=jnp.array([[0.01]])))
    inputs = jnp.asarray(u)
    return batched(jax, jnp, lambda z: lgssm_filter(params, z, inputs).filtered_means)


def compare(label, contenders_of, rounds: int) -> list[dict]:
    """Rows of run-steps per second for each library at each run count: ``contenders_of(
    runs)`` gives ``{name: (fn, timed_runs)}``, each ``fn()`` the filtered drain voltage of
    its runs; estim first."""
    rows = []
    for runs in RUN_COUNTS:
        contenders = contenders_of(runs)
        outputs = {name: fn() for name, (fn, _) in contenders.items()}   # compile, warm up
        rates = {name: [] for name in contenders}
        for _ in range(rounds):
            for name, (fn, timed_runs) in contenders.items():
                start = time.perf_counter()
                fn()
                rates[name].append(timed_runs * STEPS / (time.perf_counter() - start))
        median = {name: float(np.median(r)) for name, r in rates.items()}
        for name in contenders:
            done = outputs[name].shape[0]
            agree = np.max(np.abs(outputs[name] - outputs["estim"][:done]))
            rows.append({"filter": label, "runs": runs, "library": name,
                         "run-steps per s": median[name],
                         "estim / this": median["estim"] / median[name],
                         "max difference from estim [V]": float(agree)})
            print(f"{label:4s} {runs:5d} runs  {name:9s} {median[name]:12.0f} run-steps/s   "
                  f"estim/this {median['estim'] / median[name]:8.2f}   "
                  f"max |diff| {agree:.1e} V")
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--filters", nargs="+", choices=("KF", "EKF", "UKF"),
                        default=("KF", "EKF", "UKF"),
                        help="only these filters: printed, not recorded")
    parser.add_argument("--parts", nargs="+", choices=("filters", "integrator", "letkf"),
                        default=("filters", "integrator", "letkf"))
    parser.add_argument("--dapper-python", default=str(ROOT / ".venv-dapper/bin/python"),
                        help="DAPPER's interpreter, for the LETKF part")
    args = parser.parse_args(argv)
    if "integrator" in args.parts:
        import peers_integrator

        peers_integrator.main(["--rounds", str(min(args.rounds, 3))])
    if "letkf" in args.parts:
        import peers_letkf

        peers_letkf.main(["--rounds", str(min(args.rounds, 3)),
                          "--dapper-python", args.dapper_python])
    if "filters" not in args.parts:
        return
    model, x0, z_all, u, dt = problem(max(RUN_COUNTS), STEPS)
    ekf = ExtendedKalmanFilter(Q=Q, R=0.01, P0=Q, discretization="exponential")
    ukf = UnscentedKalmanFilter(Q=Q, R=0.01, P0=Q, discretization="exponential", alpha=1e-3)
    A, B, C = linearised(model, x0, dt)
    kf = KalmanFilter(A=A.tolist(), B=B.tolist(), C=C.tolist(), Q=Q, R=0.01, P0=Q,
                      x0=x0.tolist())
    peers = {"EKF": dynamax_ekf(model, x0, u, dt), "UKF": dynamax_ukf(ukf, model, x0, u, dt),
             "KF": dynamax_kf(A, B, C, x0, u)}
    ours = {"EKF": lambda z: ekf.run(model, z, u, dt, x0=x0).y_hat[..., 0],
            "UKF": lambda z: ukf.run(model, z, u, dt, x0=x0).y_hat[..., 0],
            "KF": lambda z: kf.run(None, z, u).y_hat[..., 0]}
    theirs = {"EKF": lambda z: filterpy_ekf(model, x0, z, u, dt, "exponential")[..., 0],
              "UKF": lambda z: filterpy_ukf(ukf, model, x0, z, u, dt)[..., 0],
              "KF": lambda z: filterpy_kf(A, B, C, x0, z, u)[..., 0]}

    rows = []
    for label in args.filters:
        def contenders_of(runs, label=label):
            z = z_all[:runs]
            fp = min(runs, FILTERPY_RUNS)
            out = {"estim": (lambda: ours[label](z), runs),
                   "filterpy": (lambda: theirs[label](z[:fp]), fp)}
            if peers[label] is not None:
                out["dynamax"] = (lambda: peers[label](z)[..., 3], runs)
            return out
        rows += compare(label, contenders_of, args.rounds)
    if len(args.filters) == 3:
        record.save("peers", rows, __doc__)


if __name__ == "__main__":
    main()
