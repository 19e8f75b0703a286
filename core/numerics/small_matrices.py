"""Compiled (numba) routines on one small dense matrix at a time, written into scratch arrays.

The compiled filter loops (:mod:`estim.estimators.ekf_compiled`) step one run through time
inside numba, where a LAPACK or BLAS call on a 5 x 5 matrix costs more than its arithmetic;
so these are plain loops that allocate nothing. Each follows its numpy counterpart in
:mod:`estim.numerics.linalg` step for step (:func:`expm`: Higham's scaling and squaring with
the degree-13 Padé approximant and the same scaling exponent), so the two agree to rounding
(``tests/test_compiled_filters.py``). Without numba the functions are plain Python.
The integrator (:mod:`estim.numerics.radau_compiled`) eliminates with :func:`solve_into` too;
numba's disk cache of a caller does not notice an edit here (as for
:mod:`estim.numerics.kernels`): after one, delete the caches (``find . -name '*.nb[ic]'
-delete``).
"""

from __future__ import annotations

import numpy as np

from estim.numerics import linalg
from estim.numerics.kernels import jit

PADE_B = np.array(linalg._B)
THETA_13 = linalg._THETA_13


def _copy_vector(src, dst):
    """``dst[:] = src`` by a loop: numba's array assignment compiles a shape check with a
    formatted error message, seconds of a first run's compile per function that uses it."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


copy_vector = jit(_copy_vector)


def _copy_matrix(src, dst):
    """``dst[:, :] = src`` by a loop (as :func:`copy_vector`)."""
    for i in range(src.shape[0]):
        for j in range(src.shape[1]):
            dst[i, j] = src[i, j]


copy_matrix = jit(_copy_matrix)


def _matmul(A, B, out):
    """``out = A @ B`` (``out`` must not be ``A`` or ``B``)."""
    n, k = A.shape
    m = B.shape[1]
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for q in range(k):
                acc += A[i, q] * B[q, j]
            out[i, j] = acc


matmul = jit(_matmul)


def _matmul_t(A, B, out):
    """``out = A @ B.T``."""
    n, k = A.shape
    m = B.shape[0]
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for q in range(k):
                acc += A[i, q] * B[j, q]
            out[i, j] = acc


matmul_t = jit(_matmul_t)


def _solve_into(M, B):
    """``B <- M^-1 B`` by Gaussian elimination with partial pivoting (LAPACK ``gesv``'s
    choice of pivot); ``M`` is overwritten. A zero pivot gives inf or NaN, which the caller's
    finiteness check catches."""
    n = M.shape[0]
    m = B.shape[1]
    for c in range(n):
        p = c
        big = abs(M[c, c])
        for r in range(c + 1, n):
            if abs(M[r, c]) > big:
                big = abs(M[r, c])
                p = r
        if p != c:
            for q in range(c, n):
                M[c, q], M[p, q] = M[p, q], M[c, q]
            for q in range(m):
                B[c, q], B[p, q] = B[p, q], B[c, q]
        pivot = M[c, c]
        for r in range(c + 1, n):
            f = M[r, c] / pivot
            if f != 0.0:
                for q in range(c + 1, n):
                    M[r, q] -= f * M[c, q]
                for q in range(m):
                    B[r, q] -= f * B[c, q]
    for c in range(n - 1, -1, -1):
        for q in range(m):
            acc = B[c, q]
            for j in range(c + 1, n):
                acc -= M[c, j] * B[j, q]
            B[c, q] = acc / M[c, c]


solve_into = jit(_solve_into)


def _expm_into(A, out, work):
    """``out = exp(A)`` for one ``(n, n)`` matrix (:func:`estim.numerics.linalg.expm`'s
    algorithm); ``work`` is scratch of shape ``(6, n, n)``. A non-finite ``A`` gives NaN."""
    n = A.shape[0]
    norm = 0.0
    finite = True
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(A[i, j])
        finite &= np.isfinite(col)
        norm = max(norm, col)
    if not finite:
        out[:, :] = np.nan
        return
    s = 0
    if norm > THETA_13:
        s = int(np.ceil(np.log2(norm / THETA_13)))
    b = PADE_B
    scale = 2.0 ** s
    X, A2, A4, A6, U, V = work[0], work[1], work[2], work[3], work[4], work[5]
    for i in range(n):
        for j in range(n):
            X[i, j] = A[i, j] / scale
    matmul(X, X, A2)
    matmul(A2, A2, A4)
    matmul(A4, A2, A6)
    for i in range(n):                      # out holds the inner sums, then U and V
        for j in range(n):
            out[i, j] = b[13] * A6[i, j] + b[11] * A4[i, j] + b[9] * A2[i, j]
    matmul(A6, out, U)
    for i in range(n):
        for j in range(n):
            U[i, j] += b[7] * A6[i, j] + b[5] * A4[i, j] + b[3] * A2[i, j]
        U[i, i] += b[1]
    matmul(X, U, V)                         # V holds A (A6 (...) + ...): the odd part U
    for i in range(n):
        for j in range(n):
            U[i, j] = V[i, j]
            out[i, j] = b[12] * A6[i, j] + b[10] * A4[i, j] + b[8] * A2[i, j]
    matmul(A6, out, V)
    for i in range(n):
        for j in range(n):
            V[i, j] += b[6] * A6[i, j] + b[4] * A4[i, j] + b[2] * A2[i, j]
        V[i, i] += b[0]
    for i in range(n):
        for j in range(n):
            X[i, j] = V[i, j] - U[i, j]
            out[i, j] = V[i, j] + U[i, j]
    solve_into(X, out)
    for _ in range(s):
        matmul(out, out, X)
        copy_matrix(X, out)


expm_into = jit(_expm_into)
