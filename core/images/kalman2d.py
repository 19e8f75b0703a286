"""The 2-D Kalman filter of eqs 13a-e (``shared/seeds/000_…``) on the NSHP state-space model
of :mod:`core.images.nshp`, with additive white noise only (``C = e1``: no blur, eq 10).

Pixel by pixel in raster order:

    X_b(m, n) = A10 X_a(m, n-1) + A01 X_a(m-1, n+M)                        (13a)
    P_b(m, n) = A10 P_a(m, n-1) A10' + A01 P_a(m-1, n+M) A01' + B B' s_e^2  (13b)
    K = P_b C' / (C P_b C' + s_v^2)                                        (13c)
    X_a = X_b + K (y - C X_b),  P_a = (I - K C) P_b (I - K C)' + K s_v^2 K'  (13d, 13e)

Eq 13b leaves out the cross-covariance of the two past local states (they share pixels):
the filter is the paper's reduced one, not the optimal filter of the image, and says so.
13e is taken in Joseph form and kept symmetric. Local states off the image are the image
mean (zero after its removal) with covariance ``boundary_variance I``, except that the state
left of each row carries the filtered pixels of the rows above that it holds
(:func:`core.images.nshp.left_boundary`, their variances without cross terms). The restored pixel
is the filtered ``X_a(m, n)[0]`` (no smoothing).

The recursion is sequential in both directions, so it is compiled with numba (the project's
compiled path; a 512 x 512 image with M = 1 takes well under a second) rather than
vectorised.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from core.images import nshp


@njit(cache=True)
def _filter(y, A10, A01, left, sigma_e2, sigma_v2, boundary_variance, M):  # pragma: no cover
    rows, cols = y.shape
    n = A10.shape[0]
    Xa = np.zeros((rows + 1, cols + M + 1, n))
    Pa = np.zeros((rows + 1, cols + M + 1, n, n))
    for m in range(rows + 1):
        for j in range(cols + M + 1):
            if m == 0 or j == 0 or j > cols:
                for i in range(n):
                    Pa[m, j, i, i] = boundary_variance
    out = np.empty((rows, cols))
    p_norm = np.empty((rows, cols))
    k_norm = np.empty((rows, cols))
    for m in range(rows):
        if m > 0:
            for r in range(left.shape[0]):
                i, col, j = left[r, 0], left[r, 1], left[r, 2]
                Xa[m + 1, 0, i] = Xa[m, col + 1, j]
                Pa[m + 1, 0, i, i] = Pa[m, col + 1, j, j]
        for c in range(cols):
            left_x, left_P = Xa[m + 1, c], Pa[m + 1, c]
            up_x, up_P = Xa[m, c + 1 + M], Pa[m, c + 1 + M]
            xb = A10 @ left_x + A01 @ up_x
            Pb = A10 @ left_P @ A10.T + A01 @ up_P @ A01.T
            Pb[0, 0] += sigma_e2
            S = Pb[0, 0] + sigma_v2
            K = Pb[:, 0] / S
            xa = xb + K * (y[m, c] - xb[0])
            L = np.eye(n)
            L[:, 0] -= K
            P = L @ Pb @ L.T + np.outer(K, K) * sigma_v2
            P = 0.5 * (P + P.T)
            Xa[m + 1, c + 1] = xa
            Pa[m + 1, c + 1] = P
            out[m, c] = xa[0]
            p_norm[m, c] = np.sqrt(np.sum(P * P))
            k_norm[m, c] = np.sqrt(np.sum(K * K))
    return out, p_norm, k_norm


def restore(noisy: np.ndarray, A10: np.ndarray, A01: np.ndarray, sigma_e2: float,
            sigma_v2: float, M: int, boundary_variance: float | None = None) -> dict:
    """The filtered image of a zero-mean ``noisy`` one, with the Frobenius norms of ``P_a``
    and ``K`` at every pixel (the paper's Figs 5 and 6)."""
    y = np.ascontiguousarray(noisy, dtype=float)
    var = float(np.var(y) - sigma_v2) if boundary_variance is None else boundary_variance
    out, p_norm, k_norm = _filter(y, np.ascontiguousarray(A10), np.ascontiguousarray(A01),
                                  nshp.left_boundary(M), float(sigma_e2), float(sigma_v2),
                                  max(var, 0.0), int(M))
    return {"image": out, "P_norm": p_norm, "K_norm": k_norm}
