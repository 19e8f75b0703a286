"""The batched matrix exponential of :mod:`estim.linalg`, compiled with numba.

The same algorithm, matrix by matrix: Higham's scaling and squaring with the degree-13 Padé
approximant, each matrix scaled by its own ``2^-s`` from its 1-norm, the Padé quotient
solved by Gaussian elimination with partial pivoting, ``s`` squarings; a non-finite or
singular case gives NaN. The numpy form groups the matrices by ``s`` and calls numpy per
group, and on the filters' 4 x 4 to 6 x 6 Jacobians those calls (about 20 per group, and a
LAPACK call per matrix for the solve) were most of an EKF step (bench/bench_ekf_steps.py).
The results differ from the numpy form's by rounding only: each inner product is summed in
index order here, by BLAS there (tests/test_linalg.py holds the two within 1e-13).
"""

from __future__ import annotations

import numpy as np

from estim.kernels import AVAILABLE, jit

__all__ = ["AVAILABLE", "expm"]


@jit
def _multiply(A, B, out):  # pragma: no cover - compiled
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += A[i, k] * B[k, j]
            out[i, j] = s


@jit
def _solve_matrix(M, B):  # pragma: no cover - compiled
    """``M^-1 B`` in place (``B`` holds the result, ``M`` is overwritten); False when a
    pivot is zero or the result is not finite."""
    n = M.shape[0]
    for c in range(n):
        p = c
        big = abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > big:
                big = abs(M[r, c])
                p = r
        if big == 0.0:
            return False
        if p != c:
            for q in range(n):
                M[c, q], M[p, q] = M[p, q], M[c, q]
                B[c, q], B[p, q] = B[p, q], B[c, q]
        for r in range(c + 1, n):
            m = M[r, c] / M[c, c]
            if m != 0.0:
                for q in range(c + 1, n):
                    M[r, q] -= m * M[c, q]
                for q in range(n):
                    B[r, q] -= m * B[c, q]
    for q in range(n):
        for c in range(n - 1, -1, -1):
            acc = B[c, q]
            for k in range(c + 1, n):
                acc -= M[c, k] * B[k, q]
            B[c, q] = acc / M[c, c]
    for c in range(n):
        for q in range(n):
            if not np.isfinite(B[c, q]):
                return False
    return True


@jit
def _expm(flat, b, theta, out):  # pragma: no cover - compiled
    count, n = flat.shape[0], flat.shape[1]
    X = np.empty((n, n))
    A2 = np.empty((n, n))
    A4 = np.empty((n, n))
    A6 = np.empty((n, n))
    T = np.empty((n, n))
    U = np.empty((n, n))
    V = np.empty((n, n))
    for g in range(count):
        A = flat[g]
        norm = 0.0
        for j in range(n):
            col = 0.0
            for i in range(n):
                col += abs(A[i, j])
            norm = max(norm, col) if np.isfinite(col) else np.inf
        if not np.isfinite(norm):
            out[g] = np.nan
            continue
        s = 0
        if norm > theta:
            s = int(np.ceil(np.log2(norm / theta)))
        scale = 2.0 ** s
        for i in range(n):
            for j in range(n):
                X[i, j] = A[i, j] / scale
        _multiply(X, X, A2)
        _multiply(A2, A2, A4)
        _multiply(A4, A2, A6)
        for i in range(n):
            for j in range(n):
                T[i, j] = b[13] * A6[i, j] + b[11] * A4[i, j] + b[9] * A2[i, j]
        _multiply(A6, T, U)
        for i in range(n):
            for j in range(n):
                T[i, j] = U[i, j] + b[7] * A6[i, j] + b[5] * A4[i, j] + b[3] * A2[i, j]
            T[i, i] += b[1]
        _multiply(X, T, U)
        for i in range(n):
            for j in range(n):
                T[i, j] = b[12] * A6[i, j] + b[10] * A4[i, j] + b[8] * A2[i, j]
        _multiply(A6, T, V)
        for i in range(n):
            for j in range(n):
                V[i, j] = V[i, j] + b[6] * A6[i, j] + b[4] * A4[i, j] + b[2] * A2[i, j]
            V[i, i] += b[0]
        R = out[g]
        for i in range(n):
            for j in range(n):
                T[i, j] = V[i, j] - U[i, j]
                R[i, j] = V[i, j] + U[i, j]
        if not _solve_matrix(T, R):
            out[g] = np.nan
            continue
        for _ in range(s):
            _multiply(R, R, T)
            R[:, :] = T


def expm(A: np.ndarray, b: tuple, theta: float) -> np.ndarray:
    """Matrix exponential of every matrix in a stack ``(..., n, n)`` (``b``: the Padé
    coefficients, ``theta``: the largest 1-norm taken unscaled)."""
    shape = A.shape
    flat = np.ascontiguousarray(A, dtype=np.float64).reshape((-1,) + shape[-2:])
    out = np.empty(flat.shape)
    _expm(flat, np.asarray(b, dtype=np.float64), float(theta), out)
    return out.reshape(shape)
