"""Where the batched EKF step's time goes, and what bounds it.

    python bench/bench_ekf_steps.py [--runs 1000] [--steps 200]

The EKF of bench_filters.py (the MOSFET model, 4 states, the exponential discretisation),
taken apart: each phase of one cycle (the model's drift and Jacobian, the exponential of the
augmented matrix, the covariance prediction, the Joseph update, the batch's bookkeeping) is
timed on its own over ``steps`` repetitions at the filter's state, in this process. Three
measurements say what bounds the step:

* the phase times against the batch size (runs 10 ... 10,000): the part that does not grow
  with the runs is numpy's call overhead (a fixed cost per call, paid once per step);
* the number of numpy calls per step, and the time of an empty call on a 1-element array;
* each phase's arithmetic rate (flops / s) against a plain matrix product's rate at the
  same sizes, which is the best numpy reaches on stacks of 4 x 4 and 5 x 5 matrices.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_filters import FLOPS_PER_STEP, PEAK_FLOPS, Q, problem  # noqa: E402

from estim.estimators.base import joseph_update
from estim.numerics import linalg


def per_call(fn, repeats: int) -> float:
    """Fastest mean seconds of ``fn()`` over three blocks of ``repeats`` calls."""
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(repeats):
            fn()
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


def phases(runs: int, steps: int) -> dict[str, float]:
    """Seconds per step of each phase of the EKF cycle at ``runs`` runs."""
    model, x0, z, u, dt = problem(runs, 2)
    x = np.broadcast_to(x0, (runs, 4)).copy()
    P = np.broadcast_to(np.diag(Q), (runs, 4, 4)).copy()
    uk, zk = np.broadcast_to(u[0], (runs, u.shape[1])).copy(), z[:, 0]
    Qm, R = np.diag(Q), np.array([[0.01]])
    fx, J = model.f_and_jacobian(x, uk)

    def augmented():
        aug = np.zeros((runs, 5, 5))
        aug[:, :4, :4] = dt * J
        aug[:, :4, 4] = dt * fx
        return aug

    aug = augmented()
    E = linalg.expm(aug)
    F = E[:, :4, :4]
    Pp = F @ P @ np.swapaxes(F, -1, -2) + Qm
    H = model.h_jacobian(x)
    nu = zk - model.h(x)
    alive = np.ones(runs, bool)
    hist = np.full((runs, 4, 4), np.nan)

    def bookkeeping():
        idx = np.flatnonzero(alive)
        xs, Ps = x[idx], P[idx]
        ok = (np.all(np.isfinite(xs), axis=1) & np.all(np.isfinite(Ps), axis=(1, 2))
              & np.all(np.abs(xs) <= 1e6, axis=1) & np.all(np.abs(xs) <= 1e6, axis=1))
        keep = idx[ok]
        x[keep], P[keep] = xs[ok], Ps[ok]
        hist[keep] = Ps[ok]

    return {
        "drift and Jacobian": per_call(lambda: model.f_and_jacobian(x, uk), steps),
        "augmented matrix": per_call(augmented, steps),
        "expm (Pade 13)": per_call(lambda: linalg.expm(aug), steps),
        "covariance prediction": per_call(lambda: F @ P @ np.swapaxes(F, -1, -2) + Qm, steps),
        "measurement": per_call(lambda: (model.h(x), model.h_jacobian(x)), steps),
        "Joseph update": per_call(lambda: joseph_update(x, Pp, nu, H, R), steps),
        "bookkeeping": per_call(bookkeeping, steps),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    sizes = (10, 100, 1000, 10000)
    table = {n: phases(n, max(20, args.steps * 1000 // n)) for n in sizes}
    names = list(table[sizes[0]])
    print("us per run-step by phase and batch size (runs):")
    print(f"{'phase':<24}" + "".join(f"{n:>10}" for n in sizes) + f"{'fixed us':>11}")
    rows = []
    for name in [*names, "total"]:
        cells = [sum(table[n].values()) if name == "total" else table[n][name] for n in sizes]
        fixed = cells[0] - (cells[1] - cells[0]) / (sizes[1] - sizes[0]) * sizes[0]
        per_run = "".join(f"{c / n * 1e6:>10.2f}" for c, n in zip(cells, sizes, strict=True))
        print(f"{name:<24}{per_run}{fixed * 1e6:>11.1f}")
        rows.append({"phase (µs per run-step)": name,
                     **{f"{n} runs": c / n * 1e6 for c, n in zip(cells, sizes, strict=True)},
                     "fixed µs per step": fixed * 1e6})
    record.save("ekf_steps", rows, __doc__)
    one = np.ones(1)
    empty = per_call(lambda: one + one, 20000)
    stack4 = np.random.default_rng(0).standard_normal((args.runs, 4, 4))
    stack5 = np.random.default_rng(0).standard_normal((args.runs, 5, 5))
    mm4 = per_call(lambda: stack4 @ stack4, 500) / args.runs
    mm5 = per_call(lambda: stack5 @ stack5, 500) / args.runs
    print(f"\nan empty numpy call (1-element add): {empty * 1e6:.2f} us")
    print(f"stacked matmul at {args.runs} runs: 4x4 {mm4 * 1e9:.0f} ns ({2 * 4**3 / mm4 / 1e9:.2f}"
          f" GFLOP/s), 5x5 {mm5 * 1e9:.0f} ns ({2 * 5**3 / mm5 / 1e9:.2f} GFLOP/s)")
    total = sum(table[args.runs].values()) / args.runs
    limit = FLOPS_PER_STEP / PEAK_FLOPS
    at_matmul_rate = FLOPS_PER_STEP / (2 * 5**3 / mm5)
    print(f"EKF step at {args.runs} runs: {total * 1e6:.2f} us per run; flop limit "
          f"({FLOPS_PER_STEP / 1e3:.0f} kflop at {PEAK_FLOPS / 1e9:.0f} GFLOP/s) "
          f"{limit * 1e6:.2f} us: {total / limit:.1f}x; at numpy's own stacked-5x5 matmul rate "
          f"the same flops take {at_matmul_rate * 1e6:.2f} us ({total / at_matmul_rate:.1f}x)")


if __name__ == "__main__":
    main()
