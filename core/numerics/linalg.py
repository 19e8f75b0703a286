"""Batched matrix functions.

``scipy.linalg.expm`` accepts stacked matrices but treats them one at a time, which on
the stiff circuit Jacobians of a 1,000-run batch costs far more than the filter itself.
:func:`expm` applies Higham's scaling-and-squaring with the degree-13 Padé approximant
(Higham 2005, the algorithm behind scipy's ``expm``) to the whole stack at once, each matrix
with its own scaling exponent. ``tests/test_linalg.py`` compares it with scipy.
"""

from __future__ import annotations

import numpy as np

_B = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
      129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
      40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA_13 = 5.371920351148152


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched ``np.linalg.solve`` where a singular matrix gives NaN for its system only."""
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        out = np.full(np.broadcast_shapes(A.shape[:-2], b.shape[:-2]) + b.shape[-2:], np.nan)
        A = np.broadcast_to(A, out.shape[:-2] + A.shape[-2:])
        b = np.broadcast_to(b, out.shape)
        for i in np.ndindex(out.shape[:-2]):
            try:
                out[i] = np.linalg.solve(A[i], b[i])
            except np.linalg.LinAlgError:
                pass
        return out


def _pade13(A: np.ndarray) -> np.ndarray:
    eye = np.eye(A.shape[-1])
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    b = _B
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
             + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye)
    return solve(V - U, V + U)


def expm(A: np.ndarray) -> np.ndarray:
    """Matrix exponential of every matrix in a stack ``(..., n, n)``.

    Each matrix gets its own scaling ``2^-s`` (as in the one-matrix algorithm), so one
    large matrix in a batch does not cost the others accuracy. The Padé approximant is taken
    of the whole scaled stack at once, then each matrix is squared its own ``s`` times (the
    stack's matrix products and solves are one LAPACK/BLAS call per matrix, so each result
    is the one the matrix would get alone). Non-finite matrices give NaN.
    """
    A = np.asarray(A, float)
    shape = A.shape
    flat = A.reshape((-1,) + shape[-2:])
    out = np.full(flat.shape, np.nan)
    with np.errstate(all="ignore"):
        norm = np.max(np.sum(np.abs(flat), axis=-2), axis=-1)
        finite = np.isfinite(norm)
        s = np.zeros(flat.shape[0], int)
        big = finite & (norm > _THETA_13)
        s[big] = np.ceil(np.log2(norm[big] / _THETA_13)).astype(int)
    rows = np.flatnonzero(finite)
    if rows.size:
        s = s[rows]
        if s.min() != s.max():
            order = np.argsort(-s, kind="stable")             # most squarings first
            rows, s = rows[order], s[order]
        R = _pade13(flat[rows] / (2.0 ** s)[:, None, None])
        squared = np.count_nonzero(s[None, :] > np.arange(s[0])[:, None], axis=1)
        for count in squared.tolist():                         # the first count need more
            if count == len(R):
                R = R @ R
            else:
                R[:count] = R[:count] @ R[:count]
        out[rows] = R
    return out.reshape(shape)
