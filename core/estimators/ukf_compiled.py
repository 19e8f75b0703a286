"""The unscented Kalman filter's time loop compiled with numba, one run at a time: the same
filter as :meth:`estim.estimators.ukf.UnscentedKalmanFilter.cycle` with
:func:`estim.estimators.base.run_batch`'s bookkeeping, step for step.

Per step: ``2n + 1`` scaled sigma points of ``(x, P)`` (the lower Cholesky factor, or where
it fails the symmetric root with negative eigenvalues set to zero, as
:func:`estim.estimators.ukf.sqrt_psd`), each carried over the interval by the EKF's
discretisation (:func:`estim.estimators.compiled_steps.predict`); the weighted moments plus
``Q``; sigma points redrawn from the prediction through the affine output ``H x + c``; the
Joseph-form update with the statistically linearised ``H = P_xz^T P^-1``. A run whose
estimate or prediction becomes non-finite or leaves ``|x| <= bound`` is broken, its outputs
NaN from that step on. ``tests/test_compiled_filters.py`` checks that both loops agree to
rounding.
"""

from __future__ import annotations

import numpy as np

from estim.estimators import breaks
from estim.estimators.compiled_steps import (
    METHODS,
    broke,
    first_bad,
    history,
    joseph_update,
    keep,
    predict,
    predict_scratch,
    update_scratch,
)
from estim.numerics.kernels import jit, plain
from estim.numerics.small_matrices import copy_matrix, copy_vector, solve_into


def _sqrt_psd(P, L):
    """``L`` with ``L L^T = P``: the lower Cholesky factor, or where a pivot is not positive
    the symmetric root ``V sqrt(max(w, 0))`` of ``P = V diag(w) V^T``. ``P`` finite."""
    n = P.shape[0]
    ok = True
    for j in range(n):
        acc = P[j, j]
        for q in range(j):
            acc -= L[j, q] * L[j, q]
        if not acc > 0.0:
            ok = False
            break
        d = np.sqrt(acc)
        L[j, j] = d
        for i in range(j + 1, n):
            acc = P[i, j]
            for q in range(j):
                acc -= L[i, q] * L[j, q]
            L[i, j] = acc / d
        for i in range(j):
            L[i, j] = 0.0
    if ok:
        return
    w, V = np.linalg.eigh(P)
    for i in range(n):
        for j in range(n):
            L[i, j] = V[i, j] * np.sqrt(max(w[j], 0.0))


sqrt_psd = jit(_sqrt_psd)


def _sigma_points(x, P, spread, L, X):
    """``X (2n+1, n)``: ``x``, ``x + spread L[:, i]``, ``x - spread L[:, i]``."""
    n = x.shape[0]
    sqrt_psd(P, L)
    for a in range(n):
        X[0, a] = x[a]
    for i in range(n):
        for a in range(n):
            d = spread * L[a, i]
            X[1 + i, a] = x[a] + d
            X[1 + n + i, a] = x[a] - d


sigma_points = jit(_sigma_points)


def _finite(P):
    n = P.shape[0]
    for a in range(n):
        for b in range(n):
            if not np.isfinite(P[a, b]):
                return False
    return True


finite = jit(_finite)


def _runs(kind, Pk, x0, P0, z, u, dt, Q, R, H, c, method, substeps, bound, wm, wc, spread):
    runs, steps, m = z.shape
    n = x0.shape[1]
    points = 2 * n + 1
    out = history(runs, steps, n, m)
    scratch = update_scratch(n, m)
    S = scratch[0]
    x = np.empty(n)
    xp = np.empty(n)
    xs = np.empty(n)
    P = np.empty((n, n))
    Pw = np.empty((n, n))
    L = np.empty((n, n))
    X = np.empty((points, n))
    Xp = np.empty((points, n))
    Z = np.empty((points, m))
    zp = np.empty(m)
    nu = np.empty(m)
    Pxz = np.empty((n, m))
    Hl = np.empty((m, n))
    steps_scratch = predict_scratch(n)
    for r in range(runs):
        copy_vector(x0[r], x)
        copy_matrix(P0, P)
        for k in range(steps):
            sigma_points(x, P, spread, L, X)
            for j in range(points):                  # each point over the interval
                copy_vector(X[j], xs)
                predict(kind, Pk, xs, u[r, k], dt, method, substeps, steps_scratch)
                copy_vector(xs, Xp[j])
            for a in range(n):                       # weighted mean and covariance + Q
                acc = 0.0
                for j in range(points):
                    acc += wm[j] * Xp[j, a]
                xp[a] = acc
            for a in range(n):
                for b in range(n):
                    acc = 0.0
                    for j in range(points):
                        acc += wc[j] * (Xp[j, a] - xp[a]) * (Xp[j, b] - xp[b])
                    P[a, b] = acc + Q[a, b]
            for a in range(n):
                for b in range(a + 1, n):
                    mean = 0.5 * (P[a, b] + P[b, a])
                    P[a, b] = mean
                    P[b, a] = mean
            bad, a = first_bad(xp, bound)
            if bad >= 0:
                broke(r, k, 1 + bad, a, out)
                break
            if not finite(P):
                broke(r, k, 6, -1, out)
                break
            sigma_points(xp, P, spread, L, X)        # redrawn, through h = H x + c
            for j in range(points):
                for i in range(m):
                    acc = c[i]
                    for a in range(n):
                        acc += H[i, a] * X[j, a]
                    Z[j, i] = acc
            for i in range(m):
                acc = 0.0
                for j in range(points):
                    acc += wm[j] * Z[j, i]
                zp[i] = acc
                nu[i] = z[r, k, i] - zp[i]
            for a in range(n):
                for i in range(m):
                    acc = 0.0
                    for j in range(points):
                        acc += wc[j] * (X[j, a] - xp[a]) * (Z[j, i] - zp[i])
                    Pxz[a, i] = acc
            copy_matrix(P, Pw)                       # H = (P^-1 P_xz)^T
            solve_into(Pw, Pxz)
            for i in range(m):
                for a in range(n):
                    Hl[i, a] = Pxz[a, i]
            copy_vector(xp, x)
            ok = joseph_update(x, P, nu, Hl, R, scratch)
            if not keep(r, k, ok, x, xp, bound, P, S, nu, out):
                break
    return out


runs_compiled = jit(_runs)


def run(plan: tuple, x0: np.ndarray, P0: np.ndarray, z: np.ndarray, u: np.ndarray, dt: float,
        Q: np.ndarray, R: np.ndarray, discretization: str, substeps: int, bound: float,
        weights: tuple[np.ndarray, np.ndarray], spread: float,
        why: dict | None = None) -> tuple[np.ndarray, ...]:
    """:func:`estim.estimators.base.run_batch` of the UKF's cycle for ``plan`` (from
    :func:`estim.estimators.ekf_compiled.usable`) with the sigma points' ``weights`` (mean,
    covariance) and ``spread = sqrt(n + lambda)``: ``x_hat``, ``P``, ``S``, the innovations
    and the runs alive at the end; ``why`` is filled as ``run_batch`` fills it."""
    kind, Pk, H, c = plan
    runs, n = z.shape[0], np.shape(x0)[-1]
    X0 = np.broadcast_to(np.asarray(x0, float), (runs, n))
    out = runs_compiled(int(kind), plain(Pk), plain(X0), plain(P0), plain(z), plain(u),
                        float(dt), plain(Q), plain(R), plain(H), plain(c),
                        METHODS[discretization],
                        int(substeps), float(bound), plain(weights[0]), plain(weights[1]),
                        float(spread))
    if why is not None:
        why.update(breaks.reasons(out[5], out[6], out[7]))
    return out[:5]
