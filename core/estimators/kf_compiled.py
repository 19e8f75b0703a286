"""The linear Kalman filter's time loop compiled with numba (thesis Appendix A.1, eqs
A.1-A.7): the same steps as :meth:`estim.estimators.kf.KalmanFilter.run`. The covariance
recursion, ``P = A P A^T + Q`` and the Joseph-form update
(:func:`estim.estimators.compiled_steps.joseph_update`), does not depend on the
measurements: it runs once, and each run steps only its mean, ``x = A x + B u`` and
``x + K nu``, stopped at its first non-finite estimate (its outputs NaN from that step on).
The numpy loop pays a fixed call overhead per step whatever the batch;
``tests/test_compiled_filters.py`` checks that both agree to rounding.
"""

from __future__ import annotations

import numpy as np

from estim.estimators.compiled_steps import joseph_update, update_scratch
from estim.numerics import kernels
from estim.numerics.kernels import jit, plain
from estim.numerics.small_matrices import copy_matrix, matmul, matmul_t

AVAILABLE = kernels.AVAILABLE


def _gains(P0, steps, A, C, Q, R):
    """The covariance recursion every run shares (eqs A.2-A.4, A.6-A.7): per step the
    updated ``P``, ``S`` and the gain ``K`` (``n x m``), by the same operations as an update
    of one run (:func:`estim.estimators.compiled_steps.joseph_update`, on a zero estimate)."""
    n, m = A.shape[0], C.shape[0]
    scratch = update_scratch(n, m)
    S, Kt, AP = scratch[0], scratch[3], scratch[7]
    P_steps, S_steps = np.empty((steps, n, n)), np.empty((steps, m, m))
    K_steps = np.empty((steps, n, m))
    P = np.empty((n, n))
    copy_matrix(P0, P)
    x, nu = np.zeros(n), np.zeros(m)
    for k in range(steps):
        matmul(A, P, AP)                              # P = A P A^T + Q
        matmul_t(AP, A, P)
        for a in range(n):
            for b in range(n):
                P[a, b] += Q[a, b]
        joseph_update(x, P, nu, C, R, scratch)
        copy_matrix(P, P_steps[k])
        copy_matrix(S, S_steps[k])
        for a in range(n):
            for i in range(m):
                K_steps[k, a, i] = Kt[i, a]
    return P_steps, S_steps, K_steps


BLOCK = 32
"""Runs stepped side by side in :func:`_means`: enough independent sums to hide the
arithmetic's latency, few enough that their outputs stay in the first-level cache (32 was
the fastest of 1-64 on 1,000 runs of 4 states)."""


def _means(x0, z, u, A, B, C, K_steps):
    """Each run's estimate and innovations through the shared gains (eqs A.1, A.5), in
    blocks of :data:`BLOCK` runs stepped side by side (the innermost loops go over a block's
    runs): every run sums its terms in the same order as a run alone. A run's outputs are
    NaN from its first non-finite estimate on, that step given in ``first_bad`` (``steps``
    for a run that stayed finite)."""
    runs, steps, m = z.shape
    n, p = B.shape
    x_hat = np.empty((runs, steps, n))
    innovation = np.empty((runs, steps, m))
    x, xp = np.empty((n, BLOCK)), np.empty((n, BLOCK))
    nu, acc = np.empty((m, BLOCK)), np.empty(BLOCK)
    first_bad = np.full(runs, steps)
    for r0 in range(0, runs, BLOCK):
        nb = min(BLOCK, runs - r0)
        for a in range(n):
            for q in range(nb):
                x[a, q] = x0[r0 + q, a]
        for k in range(steps):
            for a in range(n):                        # x = A x + B u
                for q in range(nb):
                    acc[q] = 0.0
                for b in range(n):
                    w = A[a, b]
                    for q in range(nb):
                        acc[q] += w * x[b, q]
                for q in range(nb):
                    xp[a, q] = acc[q]
                    acc[q] = 0.0
                for j in range(p):
                    w = B[a, j]
                    for q in range(nb):
                        acc[q] += w * u[r0 + q, k, j]
                for q in range(nb):
                    xp[a, q] += acc[q]
            for i in range(m):                        # innovation z - C x
                for q in range(nb):
                    acc[q] = 0.0
                for a in range(n):
                    w = C[i, a]
                    for q in range(nb):
                        acc[q] += w * xp[a, q]
                for q in range(nb):
                    nu[i, q] = z[r0 + q, k, i] - acc[q]
                    innovation[r0 + q, k, i] = nu[i, q]
            for a in range(n):                        # x = x + K nu
                for q in range(nb):
                    acc[q] = 0.0
                for i in range(m):
                    w = K_steps[k, a, i]
                    for q in range(nb):
                        acc[q] += w * nu[i, q]
                for q in range(nb):
                    x[a, q] = xp[a, q] + acc[q]
                    x_hat[r0 + q, k, a] = x[a, q]
        for q in range(nb):                           # a run stops at its first
            finite = True                             # non-finite estimate; once non-finite
            for a in range(n):                        # it stays so (0 * inf is NaN), so a
                finite &= np.isfinite(x[a, q])        # run finite at the end never broke
            if finite:
                continue
            r = r0 + q
            for k in range(steps):
                ok = True
                for a in range(n):
                    ok &= np.isfinite(x_hat[r, k, a])
                if not ok:
                    x_hat[r, k:] = np.nan
                    innovation[r, k:] = np.nan
                    first_bad[r] = k
                    break
    return x_hat, innovation, first_bad


gains = jit(_gains)
means = jit(_means)


def run(x0: np.ndarray, P0: np.ndarray, z: np.ndarray, u: np.ndarray, A: np.ndarray,
        B: np.ndarray, C: np.ndarray, Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, ...]:
    """The filter over the batch: ``x_hat``, ``P``, ``S``, the innovations and the runs
    whose estimate stayed finite (:func:`estim.estimators.kf.shared_histories`).
    ``x0 (runs, n)``, ``u (runs, steps, p)``."""
    from estim.estimators.kf import shared_histories

    A, C = plain(A), plain(C)
    P_steps, S_steps, K_steps = gains(plain(P0), z.shape[1], A, C, plain(Q), plain(R))
    x_hat, innovation, first_bad = means(plain(x0), plain(z), plain(u), A, plain(B), C,
                                         K_steps)
    return shared_histories(x_hat, P_steps, S_steps, innovation, first_bad)
