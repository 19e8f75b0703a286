"""The steps the compiled filter loops share (numba, one run at a time, into scratch arrays
that the caller allocates once): the prediction by the shared discretisation and the
measurement update in Joseph form (thesis Appendix A, eqs A.5-A.7 and A.14-A.16).

Each follows its numpy counterpart step for step (:func:`estim.numerics.discretize.step`,
:func:`estim.estimators.base.joseph_update`), so the compiled loops
(:mod:`~estim.estimators.ekf_compiled`, :mod:`~estim.estimators.ukf_compiled`,
:mod:`~estim.estimators.kf_compiled`) agree with the numpy ones to rounding
(``tests/test_compiled_filters.py``). As for :mod:`estim.numerics.kernels`, numba's disk
cache of a caller does not notice an edit here: delete the caches after one.
"""

from __future__ import annotations

import numpy as np

from estim.numerics.kernels import evaluate, jit
from estim.numerics.small_matrices import (
    copy_matrix,
    copy_vector,
    expm_into,
    matmul,
    matmul_t,
    solve_into,
)

METHODS = {"euler": 0, "rosenbrock": 1, "exponential": 2}
"""The discretisations the compiled prediction knows, by number (``radau`` is numpy's)."""


def _predict_scratch(n):
    """Scratch for :func:`predict`: the drift, its Jacobian, the step's ``F`` (first, as the
    caller reads it), a substep's, the augmented matrix and its exponential, the
    exponential's work and a product."""
    return (np.empty((n, n)), np.empty(n), np.empty((n, n)), np.empty((n, n)),
            np.empty((n + 1, n + 1)), np.empty((n + 1, n + 1)), np.empty((6, n + 1, n + 1)),
            np.empty((n, n)))


predict_scratch = jit(_predict_scratch)


def _predict(kind, Pk, x, uk, dt, method, substeps, scratch):
    """``x <- x(t + dt)`` by ``substeps`` steps of the discretisation; ``F``, the first
    array of ``scratch`` (:func:`predict_scratch`), gets the step's Jacobian (chained over
    substeps)."""
    F, f, J, Ft, aug, E, work, tmp = scratch
    n = x.shape[0]
    h = dt / substeps
    for step in range(substeps):
        evaluate(kind, x, uk, Pk, f, J)
        if method == 0:
            for a in range(n):
                for b in range(n):
                    Ft[a, b] = h * J[a, b]
                Ft[a, a] += 1.0
            for a in range(n):
                x[a] += h * f[a]
        elif method == 1:
            for a in range(n):
                for b in range(n):
                    aug[a, b] = -h * J[a, b]
                    E[a, b + 1] = 0.0
                aug[a, a] += 1.0
                E[a, 0] = f[a]
                E[a, a + 1] = 1.0
            solve_into(aug[:n, :n], E[:n, :n + 1])
            for a in range(n):
                x[a] += h * E[a, 0]
                for b in range(n):
                    Ft[a, b] = E[a, b + 1]
        else:
            for a in range(n + 1):
                for b in range(n + 1):
                    aug[a, b] = 0.0
            for a in range(n):
                for b in range(n):
                    aug[a, b] = h * J[a, b]
                aug[a, n] = h * f[a]
            expm_into(aug, E, work)
            for a in range(n):
                x[a] += E[a, n]
                for b in range(n):
                    Ft[a, b] = E[a, b]
        if step == 0:
            copy_matrix(Ft, F)
        else:
            matmul(Ft, F, tmp)
            copy_matrix(tmp, F)


predict = jit(_predict)


def _history(runs, steps, n, m):
    """What a filter returns for a batch, before any step: ``x_hat``, ``P``, ``S`` and the
    innovations all NaN, every run alive, and for each run the cause, state and step of its
    break (:func:`broke`; 0 and -1 while it has not broken)."""
    return (np.full((runs, steps, n), np.nan), np.full((runs, steps, n, n), np.nan),
            np.full((runs, steps, m, m), np.nan), np.full((runs, steps, m), np.nan),
            np.ones(runs, np.bool_), np.zeros(runs, np.int64), np.full(runs, -1, np.int64),
            np.full(runs, -1, np.int64))


history = jit(_history)


def _broke(r, k, cause, state, out):
    """Mark run ``r`` broken at step ``k`` in :func:`history`'s ``out``, with the cause (its
    number in :data:`estim.estimators.breaks.CAUSES`) and the state (-1: none)."""
    out[4][r] = False
    out[5][r] = cause
    out[6][r] = state
    out[7][r] = k


broke = jit(_broke)


def _first_bad(v, bound):
    """``(cause offset, index)`` of the first entry of ``v`` not finite (0) or beyond
    ``bound`` (1), else ``(-1, -1)``."""
    for a in range(v.shape[0]):
        if not np.isfinite(v[a]):
            return 0, a
    for a in range(v.shape[0]):
        if abs(v[a]) > bound:
            return 1, a
    return -1, -1


first_bad = jit(_first_bad)


def _record(r, k, x, P, S, nu, out):
    """Step ``k`` of run ``r`` into :func:`history`'s ``out``."""
    copy_vector(x, out[0][r, k])
    copy_matrix(P, out[1][r, k])
    copy_matrix(S, out[2][r, k])
    copy_vector(nu, out[3][r, k])


record = jit(_record)


def _keep(r, k, ok, x, xp, bound, P, S, nu, out):
    """Whether run ``r`` goes on after step ``k``: its prediction ``xp`` is finite and within
    ``bound``, its update succeeded (``ok``), and its estimate ``x`` is finite and within
    ``bound``. Records the step into :func:`history`'s ``out`` if so, else marks the run
    broken with the first of these that failed (:func:`broke`)."""
    bad, a = first_bad(xp, bound)
    if bad >= 0:
        broke(r, k, 1 + bad, a, out)
        return False
    if not ok:
        broke(r, k, 3, -1, out)
        return False
    bad, a = first_bad(x, bound)
    if bad >= 0:
        broke(r, k, 4 + bad, a, out)
        return False
    record(r, k, x, P, S, nu, out)
    return True


keep = jit(_keep)


def _update_scratch(n, m):
    """Scratch for :func:`joseph_update` (``S`` first: it holds the innovation covariance
    after an update; ``FP`` and ``tmp``, ``n x n``, serve the callers between updates)."""
    return (np.empty((m, m)), np.empty((m, n)), np.empty((m, m)), np.empty((m, n)),
            np.empty((n, m)), np.empty((n, m)), np.empty((n, n)), np.empty((n, n)),
            np.empty((n, n)))


update_scratch = jit(_update_scratch)


def _joseph_update(x, P, nu, H, R, scratch):
    """In place: ``x <- x + K nu`` and ``P <- (I-KH) P (I-KH)^T + K R K^T`` (symmetrised)
    with ``K = P H^T S^-1``; ``S <- H P H^T + R`` (the prior ``P``), ``S`` the first array
    of ``scratch`` (:func:`update_scratch`). Returns whether every entry of the new ``P`` is
    finite."""
    S, HP, Sw, Kt, K, KR, IKH, FP, tmp = scratch
    n, m = x.shape[0], nu.shape[0]
    matmul(H, P, HP)                          # S = H P H^T + R
    matmul_t(HP, H, S)
    for i in range(m):
        for j in range(m):
            S[i, j] += R[i, j]
    copy_matrix(S, Sw)
    copy_matrix(HP, Kt)
    solve_into(Sw, Kt)                        # K^T = S^-1 H P
    for a in range(n):
        for i in range(m):
            K[a, i] = Kt[i, a]
        acc = 0.0
        for i in range(m):
            acc += K[a, i] * nu[i]
        x[a] += acc
    for a in range(n):                        # Joseph form (I-KH) P (I-KH)^T + K R K^T
        for b in range(n):
            acc = 0.0
            for i in range(m):
                acc += K[a, i] * H[i, b]
            IKH[a, b] = -acc
        IKH[a, a] += 1.0
    matmul(IKH, P, FP)
    matmul_t(FP, IKH, tmp)
    matmul(K, R, KR)
    matmul_t(KR, K, P)
    for a in range(n):
        for b in range(n):
            P[a, b] += tmp[a, b]
    ok = True
    for a in range(n):
        for b in range(a, n):
            mean = 0.5 * (P[a, b] + P[b, a])
            P[a, b] = mean
            P[b, a] = mean
            ok &= np.isfinite(mean)
    return ok


joseph_update = jit(_joseph_update)
