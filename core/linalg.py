"""Batched matrix functions.

``scipy.linalg.expm`` accepts stacked matrices but treats them one at a time, which on
the stiff circuit Jacobians of a 1,000-run batch costs far more than the filter itself.
:func:`expm` applies Higham's scaling-and-squaring with the degree-13 Padé approximant
(Higham 2005, the algorithm behind scipy's ``expm``) to the whole stack at once, with one
scaling for the batch. ``tests/test_linalg.py`` compares it with scipy.
"""

from __future__ import annotations

import numpy as np

_B = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
      129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
      40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA_13 = 5.371920351148152


def expm(A: np.ndarray) -> np.ndarray:
    """Matrix exponential of every matrix in a stack ``(..., n, n)``."""
    A = np.asarray(A, float)
    norm = np.max(np.sum(np.abs(A), axis=-2), axis=-1) if A.size else np.zeros(1)
    top = float(np.max(norm)) if np.all(np.isfinite(norm)) else np.inf
    if not np.isfinite(top):
        return np.full(A.shape, np.nan)
    s = max(0, int(np.ceil(np.log2(top / _THETA_13)))) if top > _THETA_13 else 0
    A = A / 2.0**s
    eye = np.eye(A.shape[-1])
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    b = _B
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2)
             + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = (A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye)
    R = np.linalg.solve(V - U, V + U)
    for _ in range(s):
        R = R @ R
    return R
