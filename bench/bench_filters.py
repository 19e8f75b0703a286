"""Throughput of estim's batched EKF and RLS against filterpy's EKF looped over runs.

Run on demand (not part of the tests):  pip install '.[bench]' && python bench/bench_filters.py

Both EKFs use the same model (the completed EKV MOSFET, eq 3.12 law) and the same
discretisation (:func:`estim.numerics.discretize.step`), so the ratio measures the batching, not a
different algorithm. filterpy is timed on a subset of the runs and its throughput
(run-steps per second) is compared with ours; both run in this process.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import record

from estim.estimators.ekf import ExtendedKalmanFilter
from estim.estimators.rls import RecursiveLeastSquares
from estim.models.mosfet_ekv import MosfetEKV
from estim.numerics import discretize

Q = [0.0025, 0.002, 0.002, 0.002]
FLOPS_PER_STEP = 5e3
"""Floating-point operations of one EKF step of a 4-state model with the exponential
discretisation: the Pade-13 exponential of the 5x5 augmented matrix (~3 kflop), the
covariance prediction and the Joseph update (~1 kflop each)."""
PEAK_FLOPS = 10e9
"""A round figure for one core of this machine kind (AVX2, two FMA units, ~3 GHz, of which
numpy's small-matrix kernels reach a fraction)."""


def problem(runs: int, steps: int, seed: int = 0):
    model = MosfetEKV(V_IN=0.435, drain_current="weak_saturation")
    x0 = model.operating_point()
    rng = np.random.default_rng(seed)
    dt = 1e-4
    t = np.arange(steps + 1) * dt
    u = model.source_to_input(0.01 * np.sin(2 * np.pi * 1000 * t)[:, None], dt)
    z = x0[3] + 0.1 * rng.standard_normal((runs, steps, 1))
    return model, x0, z, u, dt


def filterpy_ekf(model, x0, z, u, dt, method):
    from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF

    class Stepped(FilterpyEKF):
        def predict_x(self, u=0):
            x, F = discretize.step(model, self.x[None, :, 0], u[None], dt, method)
            self.x, self.F = x[0][:, None], F[0]

    out = np.empty(z.shape)
    H = np.array([[0.0, 0.0, 0.0, 1.0]])
    for r in range(z.shape[0]):
        f = Stepped(dim_x=4, dim_z=1)
        f.x, f.P, f.Q, f.R = x0[:, None].copy(), np.diag(Q), np.diag(Q), np.array([[0.01]])
        for k in range(z.shape[1]):
            f.predict(u[k])
            f.update(z[r, k], HJacobian=lambda x: H, Hx=lambda x: x[3:4])
            out[r, k] = f.x[3]
    return out


def timed(fn):
    start = time.perf_counter()
    value = fn()
    return value, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--filterpy-runs", type=int, default=20)
    parser.add_argument("--method", default="exponential")
    args = parser.parse_args()
    model, x0, z, u, dt = problem(args.runs, args.steps)
    n = args.runs * args.steps
    ekf = ExtendedKalmanFilter(Q=Q, R=0.01, P0=Q, discretization=args.method)
    ours, t_ekf = timed(lambda: ekf.run(model, z, u, dt, x0=x0))
    _, t_rls = timed(lambda: RecursiveLeastSquares().run(model, z, u, dt))
    m = args.filterpy_runs
    ref, t_fp = timed(lambda: filterpy_ekf(model, x0, z[:m], u, dt, args.method))
    agree = np.max(np.abs(ref[:, :, 0] - ours.y_hat[:m, :, 0]))
    fp_rate = m * args.steps / t_fp
    print(f"problem: {args.runs} runs x {args.steps} steps, discretisation {args.method}")
    print(f"filterpy EKF loop : {fp_rate:12.0f} run-steps/s  ({m} runs timed)")
    print(f"estim EKF (batch) : {n / t_ekf:12.0f} run-steps/s  ratio {n / t_ekf / fp_rate:6.1f}x")
    print(f"estim RLS (batch) : {n / t_rls:12.0f} run-steps/s  ratio {n / t_rls / fp_rate:6.1f}x")
    print(f"max |estim - filterpy| on the shared runs: {agree:.2e} V")
    step_us = t_ekf / n * 1e6
    limit_us = FLOPS_PER_STEP / PEAK_FLOPS * 1e6
    print(f"estim EKF step    : {step_us:8.2f} us per run-step; the flop limit of a 4-state "
          f"step (~{FLOPS_PER_STEP / 1e3:.0f} kflop at {PEAK_FLOPS / 1e9:.0f} GFLOP/s) is "
          f"{limit_us:.2f} us: {step_us / limit_us:.1f}x above it")
    record.save("filters", [
        {"filter": f"filterpy EKF, looped over {m} runs", "run-steps per s": fp_rate,
         "x filterpy": 1.0, "max difference from filterpy [V]": "-"},
        {"filter": f"estim EKF, {args.runs} runs batched", "run-steps per s": n / t_ekf,
         "x filterpy": n / t_ekf / fp_rate, "max difference from filterpy [V]": agree},
        {"filter": f"estim RLS, {args.runs} runs batched", "run-steps per s": n / t_rls,
         "x filterpy": n / t_rls / fp_rate, "max difference from filterpy [V]": "-"},
    ], __doc__)


if __name__ == "__main__":
    main()
