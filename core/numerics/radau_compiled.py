"""The batched Radau IIA integrator of :mod:`estim.numerics.simulate`, compiled with numba.

The same algorithm, step for step: 3-stage Radau IIA collocation solved by full Newton
iterations, the embedded error estimate, per-run step control with the ``err^(-1/4)`` rule
and step sizes carried over between sample intervals. Only the arithmetic moves from numpy
calls on small arrays (whose call overhead was 90 % of the time) to compiled loops, one run
at a time; results agree with the numpy path to rounding (``tests/test_compiled.py``).

A model opts in with ``Model.kernel()``, which returns the number of its compiled kernel in
:mod:`estim.numerics.kernels` (writing the drift into ``f`` and its Jacobian into ``J``) and the
parameter vector ``P`` it reads. Without numba installed, or for a model without a kernel,
:func:`estim.numerics.simulate.simulate` keeps the numpy path.
"""

from __future__ import annotations

import numpy as np

from estim.numerics import kernels, radau
from estim.numerics.kernels import evaluate, jit, plain
from estim.numerics.small_matrices import copy_matrix, copy_vector, solve_into

AVAILABLE = kernels.AVAILABLE

RADAU_A, RADAU_MU, RADAU_E = radau.A, radau.MU, radau.E

OK, STEP_UNDERFLOW, TOO_MANY_STEPS = 0, 1, 2


def _solve(M, b):
    """``M^-1 b`` in place (``M`` and ``b`` are overwritten; ``b`` holds the result): the
    partial-pivoting elimination of :func:`estim.numerics.small_matrices.solve_into` on ``b``
    as one column. No LAPACK call: at these sizes (3n <= 24) the call's overhead is most of
    the work."""
    solve_into(M, b.reshape((b.shape[0], 1)))


solve = jit(_solve)


def _radau_step(kind, P, x, u, h, newton_tol, max_newton, A, E, mu, work, Js, M, L, fresh):
    """One Radau IIA step of size ``h`` from ``x``: whether Newton converged to a finite
    error estimate. The new state is left in ``work[2]`` (the last stage's ``Z`` plus ``x``)
    and the embedded error estimate in ``work[8]``. ``work``, ``Js``, ``M`` and ``L`` are
    scratch arrays of shapes ``(10, 3n)``, ``(4, n, n)``, ``(3n, 3n)`` and ``(n, n)``, so a
    step allocates nothing; ``work[6]`` and ``Js[3]`` hold the drift and Jacobian at ``x``,
    evaluated here when ``fresh`` (not for a retry from the same ``x`` and ``u`` after a
    rejected step, whose values they still hold). The first Newton iteration starts from
    ``Z = 0``, where every stage sits at ``x``: it takes the values at ``x`` instead of
    evaluating them three times more."""
    n = x.shape[0]
    Z = work[0:3, :n]
    F = work[3:6, :n]
    f0, X, error = work[6, :n], work[7, :n], work[8, :n]
    G = work[9]
    Z[:] = 0.0
    J0 = Js[3]
    if fresh:
        evaluate(kind, x, u, P, f0, J0)
    done = False
    for iteration in range(max_newton):
        for i in range(3):
            if iteration == 0:
                copy_vector(f0, F[i])
                copy_matrix(J0, Js[i])
                continue
            for a in range(n):
                X[a] = x[a] + Z[i, a]
            evaluate(kind, X, u, P, work[3 + i, :n], Js[i])     # F[i], typed as f0 is
        check = 0.0             # stays 0 while every entry is finite (inf * 0 and nan * 0 are nan)
        for i in range(3):
            for a in range(n):
                g = Z[i, a]
                for j in range(3):
                    g -= h * A[i, j] * F[j, a]
                G[i * n + a] = -g
                check += g * 0.0
                for j in range(3):
                    c = h * A[i, j]
                    for b in range(n):
                        m = -c * Js[j, a, b]
                        if i == j and a == b:
                            m += 1.0
                        M[i * n + a, j * n + b] = m
                        check += m * 0.0
        if check != 0.0:
            break
        solve(M, G)
        bad = False
        for q in range(3 * n):
            if not np.isfinite(G[q]):
                bad = True
        if bad:
            break
        size = 0.0
        biggest = 0.0
        for i in range(3):
            for a in range(n):
                Z[i, a] += G[i * n + a]
                size = max(size, abs(G[i * n + a]))
                biggest = max(biggest, abs(Z[i, a]))
        scale = 1.0 + biggest
        if size <= newton_tol * scale:
            done = True
            break
    ok = True
    for a in range(n):
        ze = 0.0
        for j in range(3):
            ze += E[j] * Z[j, a]
        error[a] = f0[a] + ze / h
        ok &= np.isfinite(error[a])
        for b in range(n):
            L[a, b] = -J0[a, b]
            ok &= np.isfinite(L[a, b])
        L[a, a] += mu / h
    if ok:
        solve(L, error)
    else:
        error[:] = np.nan
    finite_error = True
    for a in range(n):
        finite_error &= np.isfinite(error[a])
        Z[2, a] += x[a]
    return done and finite_error


radau_step = jit(_radau_step)


def _integrate(kind, P, x0, u, dt, rtol, atol, newton_tol, max_newton, max_iterations,
               nan_on_failure, A, E, mu):
    runs, steps, _ = u.shape
    n = x0.shape[1]
    out = np.empty((runs, steps, n))
    work = np.empty((10, 3 * n))
    Js = np.empty((4, n, n))
    M = np.empty((3 * n, 3 * n))
    L = np.empty((n, n))
    x = np.empty(n)
    new = work[2, :n]
    error = work[8, :n]
    for r in range(runs):
        copy_vector(x0[r], x)
        h = dt / 4
        iterations = 0
        for k in range(steps):
            uk = u[r, k]
            finite_x = True
            for a in range(n):
                finite_x &= np.isfinite(x[a])
            t = 0.0 if finite_x else dt
            fresh = t <= dt     # always True here, but not a literal, which numba would type
                                # apart and compile radau_step for a second time
            while t < dt * (1 - 1e-12):
                iterations += 1
                if iterations > max_iterations:
                    return out, TOO_MANY_STEPS, r, k
                hh = min(h, dt - t)
                ok = radau_step(kind, P, x, uk, hh, newton_tol, max_newton,
                                A, E, mu, work, Js, M, L, fresh)
                acc = 0.0
                for a in range(n):
                    scale = atol + rtol * max(abs(x[a]), abs(new[a]))
                    acc += (error[a] / scale) ** 2
                err = np.sqrt(acc / n)
                ok = ok and np.isfinite(err)
                accept = ok and err <= 1.0
                fresh = accept
                if accept:
                    copy_vector(new, x)
                    t += hh
                if ok:
                    factor = min(max(0.9 * max(err, 1e-10) ** (-0.25), 0.2), 10.0)
                else:
                    factor = 0.5
                proposal = hh * factor
                if accept and hh < h:
                    h = min(max(proposal, h), dt)
                else:
                    h = min(proposal, dt)
                if not h >= dt * 1e-14:
                    if not nan_on_failure:
                        return out, STEP_UNDERFLOW, r, k
                    x[:] = np.nan
                    t = dt
                    h = dt / 4
            copy_vector(x, out[r, k])
    return out, OK, -1, -1


integrate_runs = jit(_integrate)


def integrate(kind: int, P: np.ndarray, x0: np.ndarray, u: np.ndarray, dt: float, rtol: float,
              atol: float, newton_tol: float, max_newton: int, max_iterations: int,
              nan_on_failure: bool) -> tuple[np.ndarray, int, int, int]:
    """``(states (runs, steps, n), status, run, interval)``: ``status`` is ``OK``,
    ``STEP_UNDERFLOW`` or ``TOO_MANY_STEPS`` (with the run and interval where it happened).

    Every array reaches numba C-contiguous and writable: numba types a read-only array
    apart, and one such input (the perturbation analysis' read-only source) compiled the
    whole integrator a second time on a fresh install (about 19 s), with the same code."""
    return integrate_runs(int(kind), plain(P), plain(x0), plain(u), float(dt), float(rtol),
                          float(atol), float(newton_tol), int(max_newton), int(max_iterations),
                          bool(nan_on_failure), RADAU_A, RADAU_E, RADAU_MU)
