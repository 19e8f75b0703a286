"""The integrator's Newton iteration: full (today's) against simplified (one factorisation per
step, as RADAU5 and scipy's Radau), on one Chapter 3 row's actual signal.

    python bench/bench_newton.py [--runs 30]

The row of bench_simulate.py (configs/mosfet_saturation.yaml, sigma 0.25, 1 kHz, 200 samples)
at the config's tolerance. Full Newton re-evaluates the Jacobian at every stage and iteration
and eliminates the 3n x 3n system each time (estim.numerics.radau_compiled); the simplified
variant here factorises ``I - h A (x) J(x_n)`` once per step and iterates with back
substitutions, stopping by scipy's rule (``rate / (1 - rate) * |dZ| < max(10 eps / rtol,
min(0.03, rtol^0.5))`` in the error norm; a step whose iteration diverges or does not settle
in ``max_newton`` iterations is halved). Both are compiled with numba, run in this process and
compared with a tight reference (the compiled integrator at rtol 1e-10). Counted: Newton
iterations and steps, over all runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_filters import timed  # noqa: E402
from bench_simulate import row  # noqa: E402

from estim.numerics import radau_compiled as rc  # noqa: E402
from estim.numerics.kernels import evaluate, jit  # noqa: E402
from estim.numerics.simulate import simulate  # noqa: E402
from estim.numerics.small_matrices import solve_into  # noqa: E402

EPS = np.finfo(float).eps


def _lu(M, piv):
    n = M.shape[0]
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        piv[c] = p
        if p != c:
            for q in range(n):
                M[c, q], M[p, q] = M[p, q], M[c, q]
        for r in range(c + 1, n):
            M[r, c] /= M[c, c]
            for q in range(c + 1, n):
                M[r, q] -= M[r, c] * M[c, q]


def _lu_solve(M, piv, b):
    n = b.shape[0]
    for c in range(n):
        if piv[c] != c:
            b[c], b[piv[c]] = b[piv[c]], b[c]
        for r in range(c + 1, n):
            b[r] -= M[r, c] * b[c]
    for c in range(n - 1, -1, -1):
        for q in range(c + 1, n):
            b[c] -= M[c, q] * b[q]
        b[c] /= M[c, c]


lu, lu_solve = jit(_lu), jit(_lu_solve)


def _step(kind, P, x, u, h, rtol, atol, max_newton, A, E, mu, Z, F, f0, J0, Jw, M, L, G, piv,
          X, err, fresh, counts):
    """One simplified-Newton Radau IIA step: whether it converged; the new state in
    ``x + Z[2]``, the error estimate in ``err``."""
    n = x.shape[0]
    Z[:, :] = 0.0
    if fresh:
        evaluate(kind, x, u, P, f0, J0)
    for i in range(3):
        for a in range(n):
            for j in range(3):
                for b in range(n):
                    M[i * n + a, j * n + b] = -h * A[i, j] * J0[a, b] + (
                        1.0 if i == j and a == b else 0.0)
    lu(M, piv)
    tol = max(10 * EPS / rtol, min(0.03, rtol ** 0.5))
    previous, rate, done = -1.0, -1.0, False
    for iteration in range(max_newton):
        counts[0] += 1
        for i in range(3):
            if iteration == 0:
                F[i] = f0
            else:
                for a in range(n):
                    X[a] = x[a] + Z[i, a]
                evaluate(kind, X, u, P, F[i], Jw)
        for i in range(3):
            for a in range(n):
                g = Z[i, a]
                for j in range(3):
                    g -= h * A[i, j] * F[j, a]
                G[i * n + a] = -g
        lu_solve(M, piv, G)
        acc = 0.0
        for i in range(3):
            for a in range(n):
                acc += (G[i * n + a] / (atol + rtol * abs(x[a] + Z[i, a]))) ** 2
        norm = np.sqrt(acc / (3 * n))
        if not np.isfinite(norm):
            break
        if previous > 0:
            rate = norm / previous
        if rate >= 1.0 or (rate > 0 and rate ** (max_newton - iteration) / (1 - rate) * norm
                           > tol):
            break
        for i in range(3):
            for a in range(n):
                Z[i, a] += G[i * n + a]
        if norm == 0.0 or (rate > 0 and rate / (1 - rate) * norm < tol):
            done = True
            break
        previous = norm
    for a in range(n):
        ze = 0.0
        for j in range(3):
            ze += E[j] * Z[j, a]
        err[a, 0] = f0[a] + ze / h
        for b in range(n):
            L[a, b] = -J0[a, b]
        L[a, a] += mu / h
    solve_into(L, err)
    return done


step = jit(_step)


def _integrate(kind, P, x0, u, dt, rtol, atol, max_newton, A, E, mu, counts):
    runs, steps, _ = u.shape
    n = x0.shape[1]
    out = np.empty((runs, steps, n))
    Z, F = np.empty((3, n)), np.empty((3, n))
    f0, X = np.empty(n), np.empty(n)
    J0, Jw, L = np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    M, G = np.empty((3 * n, 3 * n)), np.empty(3 * n)
    err = np.empty((n, 1))
    piv = np.empty(3 * n, np.int64)
    x = np.empty(n)
    for r in range(runs):
        x[:] = x0[r]
        h = dt / 4
        for k in range(steps):
            t, fresh = 0.0, True
            while t < dt * (1 - 1e-12):
                counts[1] += 1
                hh = min(h, dt - t)
                ok = step(kind, P, x, u[r, k], hh, rtol, atol, max_newton, A, E, mu, Z, F, f0,
                          J0, Jw, M, L, G, piv, X, err, fresh, counts)
                acc = 0.0
                for a in range(n):
                    acc += (err[a, 0] / (atol + rtol * max(abs(x[a]), abs(x[a] + Z[2, a])))) ** 2
                e = np.sqrt(acc / n)
                ok = ok and np.isfinite(e)
                accept = ok and e <= 1.0
                fresh = accept
                if accept:
                    for a in range(n):
                        x[a] += Z[2, a]
                    t += hh
                factor = min(max(0.9 * max(e, 1e-10) ** -0.25, 0.2), 10.0) if ok else 0.5
                h = min(max(hh * factor, h), dt) if accept and hh < h else min(hh * factor, dt)
            out[r, k] = x
    return out


integrate = jit(_integrate)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30)
    args = parser.parse_args(argv)
    model, x0, u, dt, sim = row(args.runs)
    rtol, atol = sim["rtol"], sim["atol"]
    kind, P = model.kernel()
    X0 = np.ascontiguousarray(np.broadcast_to(x0, (args.runs, model.n_states)))
    u = np.ascontiguousarray(u)
    reference = simulate(model, x0, u, dt, rtol=1e-10, atol=1e-12, engine="compiled")
    full, t_full = timed(lambda: simulate(model, x0, u, dt, rtol=rtol, atol=atol,
                                          engine="compiled"))
    rows = [("full Newton (estim)", t_full, full, "-", "-")]
    for max_newton in (7, 12):
        counts = np.zeros(2, np.int64)
        integrate(kind, P, X0[:1], u[:1, :2], dt, rtol, atol, max_newton, rc.RADAU_A,
                  rc.RADAU_E, rc.RADAU_MU, counts)                   # compile
        counts[:] = 0
        out, sec = timed(lambda m=max_newton, c=counts: integrate(
            kind, P, X0, u, dt, rtol, atol, m, rc.RADAU_A, rc.RADAU_E, rc.RADAU_MU, c))
        rows.append((f"simplified Newton, at most {max_newton} iterations", sec, out,
                     int(counts[0]), int(counts[1])))
    print(f"Chapter 3 row: {args.runs} runs x {u.shape[1]} samples, rtol {rtol:g}, atol {atol:g}")
    table = []
    for name, sec, out, iterations, steps in rows:
        error = float(np.max(np.abs(model.h(out) - model.h(reference))))
        print(f"{name:42s} {sec:7.2f} s  x{t_full / sec:5.2f}  max error {error:.2e} V")
        table.append({"Newton iteration": name, "seconds": sec, "speed vs full": t_full / sec,
                      "max error [V]": error, "Newton iterations": iterations,
                      "steps": steps})
    record.save("newton", table, __doc__)


if __name__ == "__main__":
    main()
