"""The linear Kalman filter's time loop compiled with numba, one run at a time (thesis
Appendix A.1, eqs A.1-A.7): the same steps as :meth:`estim.estimators.kf.KalmanFilter.run`,
``x = A x + B u``, ``P = A P A^T + Q``, the Joseph-form update
(:func:`estim.estimators.compiled_steps.joseph_update`), and a run whose estimate becomes
non-finite stopped there, its outputs NaN from that step on. The numpy loop pays a fixed
call overhead per step whatever the batch; ``tests/test_compiled_filters.py`` checks that
both agree to rounding.
"""

from __future__ import annotations

import numpy as np

from estim.estimators.compiled_steps import history, joseph_update, keep, update_scratch
from estim.numerics import kernels
from estim.numerics.kernels import jit, plain
from estim.numerics.small_matrices import copy_matrix, copy_vector, matmul, matmul_t

AVAILABLE = kernels.AVAILABLE


def _runs(x0, P0, z, u, A, B, C, Q, R):
    runs, steps, m = z.shape
    n, p = B.shape
    out = history(runs, steps, n, m)
    scratch = update_scratch(n, m)
    S, AP = scratch[0], scratch[7]
    x = np.empty(n)
    xp = np.empty(n)
    P = np.empty((n, n))
    nu = np.empty(m)
    for r in range(runs):
        copy_vector(x0[r], x)
        copy_matrix(P0, P)
        for k in range(steps):
            for a in range(n):                        # x = A x + B u
                acc = 0.0
                for b in range(n):
                    acc += A[a, b] * x[b]
                xp[a] = acc
                acc = 0.0
                for j in range(p):
                    acc += B[a, j] * u[r, k, j]
                xp[a] += acc
            copy_vector(xp, x)
            matmul(A, P, AP)                          # P = A P A^T + Q
            matmul_t(AP, A, P)
            for a in range(n):
                for b in range(n):
                    P[a, b] += Q[a, b]
            for i in range(m):                        # innovation z - C x
                acc = 0.0
                for a in range(n):
                    acc += C[i, a] * x[a]
                nu[i] = z[r, k, i] - acc
            ok = joseph_update(x, P, nu, C, R, scratch)
            if not keep(r, k, ok, x, x, np.inf, P, S, nu, out):
                break
    return out


runs_compiled = jit(_runs)


def run(x0: np.ndarray, P0: np.ndarray, z: np.ndarray, u: np.ndarray, A: np.ndarray,
        B: np.ndarray, C: np.ndarray, Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, ...]:
    """The filter over the batch: ``x_hat``, ``P``, ``S``, the innovations and the runs
    whose estimate stayed finite. ``x0 (runs, n)``, ``u (runs, steps, p)``."""
    return runs_compiled(plain(x0), plain(P0), plain(z), plain(u), plain(A), plain(B),
                         plain(C), plain(Q), plain(R))
