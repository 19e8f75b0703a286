"""estim's EKF beside its peers, filterpy and dynamax (JAX), at the run counts people use.

    pip install '.[bench]' dynamax && python bench/peers.py [--rounds 7]

The problem is bench_filters.py's: the EKV MOSFET (eq 3.12 law, 4 states), 200 steps, the
exponential discretisation, measured drain voltage. Every filter runs the same filter:

* estim: ``ExtendedKalmanFilter.run`` on the whole batch (the compiled loop,
  :mod:`estim.estimators.ekf_compiled`, where numba is installed);
* filterpy 2.0's ``ExtendedKalmanFilter``, its prediction given estim's discretisation
  (:func:`estim.numerics.discretize.step`), looped over runs (timed on at most 20 runs and
  scaled: its time is linear in the runs);
* dynamax's ``extended_kalman_filter`` under ``jax.jit`` and ``jax.vmap`` over runs, in
  float64, its dynamics the same exponential step written in JAX with ``F = exp(T J)``
  as its derivative (a custom JVP; JAX's own derivative of the step would add the
  derivative of ``J``, another filter).
  Compilation is excluded: each shape is run once before it is timed.

Throughput is run-steps per second, the median of ``rounds`` rounds in which the three
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
from estim.numerics import discretize  # noqa: E402

RUN_COUNTS = (1, 30, 1000)
STEPS = 200
FILTERPY_RUNS = 20


def dynamax_filter(model, x0, u, dt):
    """``(batch_filter, shift)``: a jitted function of ``z (runs, steps, 1)`` giving the
    filtered means, or ``None`` without dynamax."""
    try:
        import jax
        import jax.numpy as jnp
        from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter
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

    # dynamax updates with z_1 first and predicts after (with the input of the step it
    # predicts to): start it from estim's prediction to t_1
    xp, F = discretize.step(model, x0[None], u[:1], dt)
    Pp = F[0] @ np.diag(Q) @ F[0].T + np.diag(Q)
    params = ParamsNLGSSM(initial_mean=jnp.asarray(xp[0]), initial_covariance=jnp.asarray(Pp),
                          dynamics_function=step, dynamics_covariance=jnp.diag(jnp.array(Q)),
                          emission_function=lambda x, uk: x[3:4],
                          emission_covariance=jnp.array([[0.01]]))
    inputs = jnp.asarray(u)

    def one(z):
        return extended_kalman_filter(params, z, inputs=inputs,
                                      output_fields=["filtered_means"]).filtered_means

    batch = jax.jit(jax.vmap(one))
    return lambda z: np.asarray(batch(jnp.asarray(z)).block_until_ready())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    model, x0, z_all, u, dt = problem(max(RUN_COUNTS), STEPS)
    ekf = ExtendedKalmanFilter(Q=Q, R=0.01, P0=Q, discretization="exponential")
    dyn = dynamax_filter(model, x0, u, dt)
    rows = []
    for runs in RUN_COUNTS:
        z = z_all[:runs]
        fp_runs = min(runs, FILTERPY_RUNS)
        contenders = {
            "estim": (lambda z=z: ekf.run(model, z, u, dt, x0=x0).y_hat[..., 0], runs),
            "filterpy": (lambda z=z[:fp_runs]: filterpy_ekf(model, x0, z, u, dt,
                                                  "exponential")[..., 0], fp_runs),
        }
        if dyn is not None:
            contenders["dynamax"] = (lambda z=z: dyn(z)[..., 3], runs)
        outputs = {name: fn() for name, (fn, _) in contenders.items()}   # compile, warm up
        rates = {name: [] for name in contenders}
        for _ in range(args.rounds):
            for name, (fn, timed_runs) in contenders.items():
                start = time.perf_counter()
                fn()
                rates[name].append(timed_runs * STEPS / (time.perf_counter() - start))
        median = {name: float(np.median(r)) for name, r in rates.items()}
        for name in contenders:
            done = outputs[name].shape[0]
            agree = np.max(np.abs(outputs[name] - outputs["estim"][:done]))
            rows.append({"runs": runs, "filter": name, "run-steps per s": median[name],
                         "estim / this": median["estim"] / median[name],
                         "max difference from estim [V]": float(agree)})
            print(f"{runs:5d} runs  {name:9s} {median[name]:12.0f} run-steps/s   "
                  f"estim/this {median['estim'] / median[name]:8.2f}   "
                  f"max |diff| {agree:.1e} V")
    record.save("peers", rows, __doc__)


if __name__ == "__main__":
    main()
