"""The optimal causal filter of an NSHP field (eq 1 of ``shared/seeds/000_…``, zero outside
the image) observed in white noise: a Kalman filter on the wavefront state, the last
``M N + M`` pixels in raster order, whose covariance keeps every cross term that the paper's
reduced filter (:mod:`estim.images.kalman2d`, eq 13b) drops; and Table I's adaptive
recursion driven by it. ``O((M N)^2)`` per pixel: a reference for narrow fields (the tests
measure the reduced filter against it), not a filter for images.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estim.images import nshp


@njit(cache=True)
def _wavefront_row(m, n, cols, lags, cols_q, phi, c, E):  # pragma: no cover
    """The prediction row ``c`` of pixel ``(m, n)`` on the wavefront state (``w[j] =
    u(k - 1 - j)``: the coefficient of each window pixel inside the image) and ``E[t] =
    dc/dphi_t``."""
    c[:] = 0.0
    E[:, :] = 0.0
    for t in range(lags.size):
        if m - (lags[t] - cols_q[t]) // cols >= 0 and 0 <= n - cols_q[t] < cols:
            c[lags[t] - 1] += phi[t]
            E[t, lags[t] - 1] = 1.0


@njit(cache=True)
def _push(x, first):  # pragma: no cover
    """The wavefront vector one pixel on: ``[first, x[:-1]]``."""
    out = np.empty_like(x)
    out[0] = first
    out[1:] = x[:-1]
    return out


@njit(cache=True)
def _push_cov(P, Pc, first):  # pragma: no cover
    """The covariance of the pushed state, ``[[first, Pc[:-1]'], [Pc[:-1], P[:-1, :-1]]]``
    (``Pc``: the new pixel's covariance with the old state)."""
    out = np.empty_like(P)
    out[1:, 1:] = P[:-1, :-1]
    out[0, 1:] = Pc[:-1]
    out[1:, 0] = Pc[:-1]
    out[0, 0] = first
    return out


@njit(cache=True)
def _wavefront_predict(P, w, c, sigma_e2, sigma_v2):  # pragma: no cover
    """Predict the next pixel from the wavefront state: ``(P c, its prediction, the pushed
    state's covariance, the innovation variance S, the gain K)``."""
    Pc = P @ c
    Pn = _push_cov(P, Pc, c @ Pc + sigma_e2)
    S = Pn[0, 0] + sigma_v2
    return Pc, c @ w, Pn, S, Pn[:, 0] / S


@njit(cache=True)
def _wavefront_update(w, prior, Pn, K, S, z):  # pragma: no cover
    """The posterior wavefront state and covariance (kept symmetric) after innovation z."""
    P = Pn - np.outer(K, K) * S
    return _push(w, prior) + K * z, 0.5 * (P + P.T)


@njit(cache=True)
def _exact(y, lags, coeffs, cols_q, sigma_e2, sigma_v2, D):  # pragma: no cover
    rows, cols = y.shape
    w = np.zeros(D)                      # w[j] = u(k - 1 - j) in raster order, zero off the image
    P = np.zeros((D, D))
    out = np.empty((rows, cols))
    z = np.empty((rows, cols))
    s = np.empty((rows, cols))
    c = np.zeros(D)
    E = np.zeros((lags.size, D))
    for m in range(rows):
        for n in range(cols):
            _wavefront_row(m, n, cols, lags, cols_q, coeffs, c, E)
            _, prior, Pn, S, K = _wavefront_predict(P, w, c, sigma_e2, sigma_v2)
            z[m, n] = y[m, n] - prior
            s[m, n] = S
            w, P = _wavefront_update(w, prior, Pn, K, S, z[m, n])
            out[m, n] = w[0]
    return out, z, s


def restore_exact(noisy: np.ndarray, a: np.ndarray, M: int, sigma_e2: float,
                  sigma_v2: float) -> dict:
    """The optimal causal (filtered, not smoothed) estimate of an NSHP field of eq 1 (zero
    outside the image) from ``noisy = u + v``: a Kalman filter on the wavefront state, the
    last ``M N + M`` pixels in raster order, whose covariance keeps every cross term that
    eq 13b drops. ``O((M N)^2)`` per pixel: a reference for narrow fields, not for images.
    Returns the image, the innovations and their variances."""
    y = np.ascontiguousarray(noisy, dtype=float)
    cols = y.shape[1]
    offsets = nshp.window(M)
    lags = np.array([p * cols + q for p, q in offsets], dtype=np.int64)
    cols_q = np.array([q for _, q in offsets], dtype=np.int64)
    out, z, s = _exact(y, lags, np.asarray(a, float), cols_q, float(sigma_e2),
                       float(sigma_v2), int(M * cols + M))
    return {"image": out, "innovation": z, "innovation_variance": s}


@njit(cache=True)
def _adaptive_exact(y, lags, cols_q, phi0, sigma_e2, sigma_v2, D, H0, lambda0,
                    v0):  # pragma: no cover
    rows, cols = y.shape
    d = phi0.size
    w = np.zeros(D)
    P = np.zeros((D, D))
    W = np.zeros((d, D))                 # dw/dphi_j: Sigma_a of the wavefront state
    dP = np.zeros((d, D, D))             # dP/dphi_j, from which kappa = dK/dphi
    phi = phi0.copy()
    H = H0 * np.eye(d)
    lam, v = lambda0, v0
    out = np.empty((rows, cols))
    trace = np.empty((rows * cols, d))
    c = np.zeros(D)
    E = np.zeros((d, D))                 # dc/dphi_j
    psi = np.empty(d)
    k = 0
    for m in range(rows):
        for n in range(cols):
            _wavefront_row(m, n, cols, lags, cols_q, phi, c, E)
            Pc, prior, Pn, S, K = _wavefront_predict(P, w, c, sigma_e2, sigma_v2)
            z = y[m, n] - prior
            for j in range(d):               # Delta (eq 20a): d(y_hat)/dphi_j
                psi[j] = E[j] @ w + c @ W[j]
            for j in range(d):
                dPc = dP[j] @ c                  # dP/dphi_j is symmetric: c' dP c = c' dPc
                dPn = _push_cov(dP[j], dPc + P @ E[j], 2.0 * (E[j] @ Pc) + c @ dPc)
                dS = dPn[0, 0]
                dK = dPn[:, 0] / S - Pn[:, 0] * dS / (S * S)
                W[j] = _push(W[j], psi[j]) + dK * z - K * psi[j]
                dP[j] = dPn - (np.outer(dK, K) + np.outer(K, dK)) * S - np.outer(K, K) * dS
            w, P = _wavefront_update(w, prior, Pn, K, S, z)
            lam = 0.99 * lam + 0.01             # Table I: gain sequence, H, phi
            v = 1.0 / (1.0 + lam / v)
            H = H + v * (np.outer(psi, psi) / S - H)
            phi = phi + v * np.linalg.solve(H, psi) * (z / S)
            out[m, n] = w[0]
            trace[k] = phi
            k += 1
    return out, trace


def restore_adaptive_exact(noisy: np.ndarray, a0: np.ndarray, M: int, sigma_e2: float,
                           sigma_v2: float, settings: dict) -> dict:
    """Table I's recursion (eqs 16-24, full gradient: Delta = d(y_hat)/dphi with kappa =
    dK/dphi carried through dP/dphi) driven by the exact filter of :func:`restore_exact`
    instead of eq 13b's reduced one, once through the field in raster order (no restart
    at every row). ``settings``: ``H0``, ``lambda0``, ``v0`` as for
    :func:`restore_adaptive`. ``O(d (M N)^2)`` per pixel: narrow fields only.

    Returns the filtered image and ``trace``, phi after every pixel (raster order)."""
    y = np.ascontiguousarray(noisy, dtype=float)
    cols = y.shape[1]
    offsets = nshp.window(M)
    out, trace = _adaptive_exact(
        y, np.array([p * cols + q for p, q in offsets], dtype=np.int64),
        np.array([q for _, q in offsets], dtype=np.int64), np.asarray(a0, float),
        float(sigma_e2), float(sigma_v2), int(M * cols + M), float(settings["H0"]),
        float(settings["lambda0"]), float(settings["v0"]))
    return {"image": out, "trace": trace}
