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
def _states(rows, cols, n, M, boundary_variance):  # pragma: no cover
    """Posterior local states and covariances, ``[m + 1, c + 1]`` for pixel ``(m, c)``; the
    states off the image are the mean with ``boundary_variance I``."""
    Xa = np.zeros((rows + 1, cols + M + 1, n))
    Pa = np.zeros((rows + 1, cols + M + 1, n, n))
    for m in range(rows + 1):
        for j in range(cols + M + 1):
            if m == 0 or j == 0 or j > cols:
                for i in range(n):
                    Pa[m, j, i, i] = boundary_variance
    return Xa, Pa


@njit(cache=True)
def _carry_left(Xa, Pa, left, m):  # pragma: no cover
    """The state left of row ``m`` takes the pixels of the rows above that it holds."""
    for r in range(left.shape[0]):
        i, col, j = left[r, 0], left[r, 1], left[r, 2]
        Xa[m + 1, 0, i] = Xa[m, col + 1, j]
        Pa[m + 1, 0, i, i] = Pa[m, col + 1, j, j]


@njit(cache=True)
def _step(Xa, Pa, m, c, F10, F01, M, sigma_e2, sigma_v2, y):  # pragma: no cover
    """Eqs 13a-e at pixel ``(m, c)``; stores the posterior and returns ``(x_a, P_a, K,
    innovation, its variance, I - K C)``."""
    n = F10.shape[0]
    left_x, left_P = Xa[m + 1, c], Pa[m + 1, c]
    up_x, up_P = Xa[m, c + 1 + M], Pa[m, c + 1 + M]
    xb = F10 @ left_x + F01 @ up_x
    Pb = F10 @ left_P @ F10.T + F01 @ up_P @ F01.T
    Pb[0, 0] += sigma_e2
    S = Pb[0, 0] + sigma_v2
    K = Pb[:, 0] / S
    z = y - xb[0]
    xa = xb + K * z
    L = np.eye(n)
    L[:, 0] -= K
    P = L @ Pb @ L.T + np.outer(K, K) * sigma_v2
    P = 0.5 * (P + P.T)
    Xa[m + 1, c + 1] = xa
    Pa[m + 1, c + 1] = P
    return xa, P, K, z, S, L


@njit(cache=True)
def _filter(y, A10, A01, left, sigma_e2, sigma_v2, boundary_variance, M):  # pragma: no cover
    rows, cols = y.shape
    Xa, Pa = _states(rows, cols, A10.shape[0], M, boundary_variance)
    out = np.empty((rows, cols))
    p_norm = np.empty((rows, cols))
    k_norm = np.empty((rows, cols))
    z = np.empty((rows, cols))
    s = np.empty((rows, cols))
    for m in range(rows):
        if m > 0:
            _carry_left(Xa, Pa, left, m)
        for c in range(cols):
            xa, P, K, z[m, c], s[m, c], _ = _step(Xa, Pa, m, c, A10, A01, M, sigma_e2,
                                                  sigma_v2, y[m, c])
            out[m, c] = xa[0]
            p_norm[m, c] = np.sqrt(np.sum(P * P))
            k_norm[m, c] = np.sqrt(np.sum(K * K))
    return out, p_norm, k_norm, z, s


def restore(noisy: np.ndarray, A10: np.ndarray, A01: np.ndarray, sigma_e2: float,
            sigma_v2: float, M: int, boundary_variance: float | None = None) -> dict:
    """The filtered image of a zero-mean ``noisy`` one, with the Frobenius norms of ``P_a``
    and ``K`` at every pixel (the paper's Figs 5 and 6), and the innovation ``y - C X_b``
    and the variance the filter gives it (eq 13c's denominator) at every pixel."""
    y = np.ascontiguousarray(noisy, dtype=float)
    var = float(np.var(y) - sigma_v2) if boundary_variance is None else boundary_variance
    out, p_norm, k_norm, z, s = _filter(y, np.ascontiguousarray(A10), np.ascontiguousarray(A01),
                                  nshp.left_boundary(M), float(sigma_e2), float(sigma_v2),
                                  max(var, 0.0), int(M))
    return {"image": out, "P_norm": p_norm, "K_norm": k_norm, "innovation": z,
            "innovation_variance": s}


@njit(cache=True)
def _adaptive(y, A10, A01, left, pmat, pcol, phi0, sigma_e2, sigma_v2, boundary_variance, M,
              H0, lambda0, v0, mu_u, trace_row):  # pragma: no cover
    rows, cols = y.shape
    n, d = A10.shape[0], phi0.size
    Xa, Pa = _states(rows, cols, n, M, boundary_variance)
    out = np.empty((rows, cols))
    p_norm = np.empty((rows, cols))
    k_norm = np.empty((rows, cols))
    trace = np.empty((cols, d))
    for m in range(rows):
        if m > 0:
            _carry_left(Xa, Pa, left, m)
        phi = phi0.copy()                        # the adaptation restarts at every row
        H = H0 * np.eye(d)
        lam, v = lambda0, v0
        Sb = np.zeros((n, d))                    # Sigma_b(0) = Gamma(0): first row -mu, mu, ...
        Sb[0, :] = mu_u
        Sb[0, 0] = -mu_u
        F10, F01 = A10.copy(), A01.copy()
        for j in range(d):
            if pmat[j] == 0:
                F10[0, pcol[j]] = phi[j]
            else:
                F01[0, pcol[j]] = phi[j]
        for c in range(cols):
            xa, P, K, z, Rz, L = _step(Xa, Pa, m, c, F10, F01, M, sigma_e2, sigma_v2, y[m, c])
            # Table I, in its order: Delta, H, phi, Sigma_a, Gamma, Sigma_b(k+1)
            lam = 0.99 * lam + 0.01
            v = 1.0 / (1.0 + lam / v)
            delta = Sb[0, :].copy()
            H = H + v * (np.outer(delta, delta) / Rz - H)
            phi = phi + v * np.linalg.solve(H, delta) * (z / Rz)
            Sa = L @ Sb                              # kappa z left out: dK/dphi not tracked
            for j in range(d):
                if pmat[j] == 0:
                    F10[0, pcol[j]] = phi[j]
                else:
                    F01[0, pcol[j]] = phi[j]
            # Sigma_b for the next pixel: the left state's sensitivity (the row above is
            # fixed data after the restart) plus Gamma, the regressors of the next pixel
            Sb = F10 @ Sa
            for j in range(d):
                if pmat[j] == 0:
                    Sb[0, j] += xa[pcol[j]]
                else:
                    Sb[0, j] += Xa[m, min(c + 2 + M, cols + M), pcol[j]]
            out[m, c] = xa[0]
            p_norm[m, c] = np.sqrt(np.sum(P * P))
            k_norm[m, c] = np.sqrt(np.sum(K * K))
            if m == trace_row:
                trace[c] = phi
    return out, p_norm, k_norm, trace


def restore_adaptive(noisy: np.ndarray, a0: np.ndarray, sigma_e2: float, sigma_v2: float,
                     M: int, settings: dict, trace_row: int = 0,
                     boundary_variance: float | None = None) -> dict:
    """The adaptive filter: eqs 13a-e with the parameters identified pixel by pixel by the
    stochastic Newton recursion of Table I (eqs 16-24), restarted from ``a0`` at every row.

    ``settings``: ``H0`` (eq 25's ``rho^-1``; the paper's experiment uses 1), ``lambda0``
    (0.95, eq 24), ``v0`` (not given) and ``mu_u`` (the first row of ``Sigma_b(0)``).
    ``R_z`` is the filter's own prediction-error variance ``C P_b C' + s_v^2``; ``kappa =
    dK/dphi`` (eq 22b) is left out, as in the approximate recursive prediction-error
    methods; after a restart the rows above are fixed data, so their sensitivities are zero
    and ``Sigma_b = A10 Sigma_a(k-1) + Gamma``. No stability projection: a run whose image
    is not finite is reported as diverged by the caller.
    """
    A10, A01, _ = nshp.state_matrices(a0, M)
    pmat, pcol = nshp.parameter_positions(M)
    y = np.ascontiguousarray(noisy, dtype=float)
    var = float(np.var(y) - sigma_v2) if boundary_variance is None else boundary_variance
    out, p_norm, k_norm, trace = _adaptive(
        y, A10, A01, nshp.left_boundary(M), pmat, pcol, np.asarray(a0, float),
        float(sigma_e2), float(sigma_v2), max(var, 0.0), int(M), float(settings["H0"]),
        float(settings["lambda0"]), float(settings["v0"]), float(settings["mu_u"]),
        int(trace_row))
    return {"image": out, "P_norm": p_norm, "K_norm": k_norm, "trace": trace}
