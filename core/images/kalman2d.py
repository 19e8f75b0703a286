"""The 2-D Kalman filter of eqs 13a-e (``shared/seeds/000_…``) on the NSHP state-space model
of :mod:`estim.images.nshp`, with additive white noise only (``C = e1``: no blur, eq 10).

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
(:func:`estim.images.nshp.left_boundary`, their variances without cross terms). The restored pixel
is the filtered ``X_a(m, n)[0]`` (no smoothing).

The recursion is sequential in both directions, so it is compiled with numba (the project's
compiled path; a 512 x 512 image with M = 1 takes well under a second) rather than
vectorised.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estim.images import nshp


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


BLAS_FROM = 9
"""State size from which the small products go to BLAS (M = 1 has 5 states, M = 2 13)."""


@njit(cache=True)
def _product(A, B, out, add):  # pragma: no cover
    """``out = A @ B`` (``out += A @ B`` with ``add``) by loops: at M = 1 (5 x 5) a BLAS
    call and its temporaries cost more than the arithmetic; from :data:`BLAS_FROM` states
    (M = 2: 13) BLAS is faster again (measured, bench/bench_image.py)."""
    if A.shape[0] >= BLAS_FROM:
        product = A @ B
        for i in range(out.shape[0]):
            for j in range(out.shape[1]):
                out[i, j] = out[i, j] + product[i, j] if add else product[i, j]
        return
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            s = 0.0
            for k in range(A.shape[1]):
                s += A[i, k] * B[k, j]
            out[i, j] = out[i, j] + s if add else s


@njit(cache=True)
def _matvec(A, x, out):  # pragma: no cover
    """``out = A @ x`` by a loop (summed in index order)."""
    for i in range(A.shape[0]):
        s = 0.0
        for k in range(A.shape[1]):
            s += A[i, k] * x[k]
        out[i] = s


@njit(cache=True)
def _sandwich(F, P, out, tmp):  # pragma: no cover
    """``out += F P F'`` (``tmp``: scratch of ``F``'s shape)."""
    n = F.shape[0]
    if n >= BLAS_FROM:
        product = F @ P @ F.T
        for i in range(n):
            for j in range(n):
                out[i, j] += product[i, j]
        return
    _product(F, P, tmp, False)
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += tmp[i, k] * F[j, k]
            out[i, j] += s


@njit(cache=True)
def _step(Xa, Pa, m, c, F10, F01, M, sigma_e2, sigma_v2, y):  # pragma: no cover
    """Eqs 13a-e at pixel ``(m, c)``; stores the posterior and returns ``(x_a, P_a, K,
    innovation, its variance, I - K C, P_b)``."""
    n = F10.shape[0]
    left_x, left_P = Xa[m + 1, c], Pa[m + 1, c]
    up_x, up_P = Xa[m, c + 1 + M], Pa[m, c + 1 + M]
    xb = np.empty(n)
    up = np.empty(n)
    _matvec(F10, left_x, xb)
    _matvec(F01, up_x, up)
    for i in range(n):
        xb[i] += up[i]
    tmp = np.empty((n, n))
    Pb = np.zeros((n, n))
    _sandwich(F10, left_P, Pb, tmp)
    _sandwich(F01, up_P, Pb, tmp)
    Pb[0, 0] += sigma_e2
    S = Pb[0, 0] + sigma_v2
    z = y - xb[0]
    K, xa, L = np.empty(n), np.empty(n), np.zeros((n, n))
    for i in range(n):
        K[i] = Pb[i, 0] / S
        xa[i] = xb[i] + K[i] * z
        L[i, i] = 1.0
    for i in range(n):
        L[i, 0] -= K[i]
    Pj = np.zeros((n, n))
    _sandwich(L, Pb, Pj, tmp)
    P = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            P[i, j] = Pj[i, j] + K[i] * K[j] * sigma_v2
    for i in range(n):
        for j in range(i + 1, n):
            P[i, j] = P[j, i] = 0.5 * (P[i, j] + P[j, i])
    for i in range(n):
        Xa[m + 1, c + 1, i] = xa[i]
        for j in range(n):
            Pa[m + 1, c + 1, i, j] = P[i, j]
    return xa, P, K, z, S, L, Pb


@njit(cache=True)
def _norm(a):  # pragma: no cover
    """The Frobenius norm, summed in C order (as ``np.sqrt(np.sum(a * a))`` in numba)."""
    s = 0.0
    for v in a.ravel():
        s += v * v
    return np.sqrt(s)


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
            xa, P, K, z[m, c], s[m, c], _, _ = _step(Xa, Pa, m, c, A10, A01, M, sigma_e2,
                                                  sigma_v2, y[m, c])
            out[m, c] = xa[0]
            p_norm[m, c] = _norm(P)
            k_norm[m, c] = _norm(K)
    return out, p_norm, k_norm, z, s


def restore(noisy: np.ndarray, A10: np.ndarray, A01: np.ndarray, sigma_e2: float,
            sigma_v2: float, M: int, boundary_variance: float | None = None) -> dict:
    """The filtered image of a zero-mean ``noisy`` one, with the Frobenius norms of ``P_a``
    and ``K`` at every pixel (the paper's Figs 5 and 6), and the innovation ``y - C X_b``
    and the variance the filter gives it (eq 13c's denominator) at every pixel."""
    y = np.ascontiguousarray(noisy, dtype=float)
    var = float(np.var(y) - sigma_v2) if boundary_variance is None else boundary_variance
    out, p_norm, k_norm, z, s = _filter(
        y, np.ascontiguousarray(A10), np.ascontiguousarray(A01), nshp.left_boundary(M),
        float(sigma_e2), float(sigma_v2), max(var, 0.0), int(M))
    return {"image": out, "P_norm": p_norm, "K_norm": k_norm, "innovation": z,
            "innovation_variance": s}


@njit(cache=True)
def _set_phi(F10, F01, pmat, pcol, phi):  # pragma: no cover
    for j in range(phi.size):
        if pmat[j] == 0:
            F10[0, pcol[j]] = phi[j]
        else:
            F01[0, pcol[j]] = phi[j]


@njit(cache=True)
def _regressors(Xa, m, c, pmat, pcol, M, cols):  # pragma: no cover
    """Gamma's first row at pixel ``(m, c)`` (eq 21b): the entries of its left and upper
    local states that each parameter multiplies."""
    left, up = Xa[m + 1, c], Xa[m, min(c + 1 + M, cols + M)]
    out = np.empty(pmat.size)
    for j in range(pmat.size):
        out[j] = left[pcol[j]] if pmat[j] == 0 else up[pcol[j]]
    return out


@njit(cache=True)
def _gain_derivative(F10, F01, pmat, pcol, left_P, up_P, dleft, dup, Pb, K, L, S,
                     sigma_v2):  # pragma: no cover
    """``kappa`` (eq 22b), column ``j`` = dK/dphi_j, and dP_a/dphi_j (13b-e differentiated
    with phi held: the recursive way of eq 22b's note). dA/dphi_j has one entry, in the
    first row, so d(A P A')/dphi_j is ``e1 r' + r e1'`` with ``r = A P[col]``."""
    d, n = pmat.size, F10.shape[0]
    kappa = np.zeros((n, d))
    dPa = np.zeros((d, n, n))
    tmp = np.empty((n, n))
    r = np.empty(n)
    g = np.empty(n)
    _matvec(L, Pb[0], g)                                        # P_b is symmetric
    for i in range(n):                                          # K s_v^2 - L P_b[0]
        g[i] = K[i] * sigma_v2 - g[i]
    for j in range(d):
        if pmat[j] == 0:
            _matvec(F10, left_P[pcol[j]], r)
        else:
            _matvec(F01, up_P[pcol[j]], r)
        dPb = np.zeros((n, n))
        _sandwich(F10, dleft[j], dPb, tmp)
        _sandwich(F01, dup[j], dPb, tmp)
        for k in range(n):
            dPb[0, k] += r[k]
        for k in range(n):
            dPb[k, 0] += r[k]
        for i in range(n):
            kappa[i, j] = dPb[i, 0] / S - Pb[i, 0] * dPb[0, 0] / (S * S)
        _sandwich(L, dPb, dPa[j], tmp)
        for i in range(n):
            for k in range(n):
                dPa[j, i, k] += kappa[i, j] * g[k] + kappa[k, j] * g[i]
    return kappa, dPa


@njit(cache=True)
def _zero(rows, k):  # pragma: no cover
    """``rows[k] = 0``: the ring of two rows of :func:`_adaptive` (its whole row ``k``)."""
    flat = rows.reshape(rows.shape[0], -1)
    for i in range(flat.shape[1]):
        flat[k, i] = 0.0


@njit(cache=True)
def _add(a, b, out):  # pragma: no cover
    """``out = a + b`` for 2-D arrays. Loops, not array expressions, here and in the
    other kernels of this module: numba compiles each array expression into a loop of its
    own, seconds of a first run's compile; the loops do the same arithmetic, element by
    element in the same order."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[i, j] = a[i, j] + b[i, j]


@njit(cache=True)
def _add_first_row(S, row):  # pragma: no cover
    for j in range(row.size):
        S[0, j] += row[j]


@njit(cache=True)
def _adaptive(y, A10, A01, left, pmat, pcol, phi0, sigma_e2, sigma_v2, boundary_variance, M,
              H0, lambda0, v0, mu_u, trace_row, full):  # pragma: no cover
    rows, cols = y.shape
    n, d = A10.shape[0], phi0.size
    Xa, Pa = _states(rows, cols, n, M, boundary_variance)
    out = np.empty((rows, cols))
    p_norm = np.empty((rows, cols))
    k_norm = np.empty((rows, cols))
    trace = np.empty((cols, d))
    sens = np.zeros((rows, cols, d))
    # sensitivities of the stored posteriors, this row and the one above (ring of two):
    # Sigma_a = dX_a/dphi and dP_a/dphi; zero off the image
    Sa_rows = np.zeros((2, cols + M + 1, n, d))
    dP_rows = np.zeros((2, cols + M + 1, d, n, n))
    for m in range(rows):
        here, above = (m + 1) % 2, m % 2
        _zero(Sa_rows, here)
        _zero(dP_rows, here)
        if m > 0:
            _carry_left(Xa, Pa, left, m)
            if full:
                for r in range(left.shape[0]):
                    i, col, jj = left[r, 0], left[r, 1], left[r, 2]
                    for q in range(d):
                        Sa_rows[here, 0, i, q] = Sa_rows[above, col + 1, jj, q]
                        dP_rows[here, 0, q, i, i] = dP_rows[above, col + 1, q, jj, jj]
        phi = np.empty(d)                        # the adaptation restarts at every row
        H = np.empty((d, d))
        for i in range(d):
            phi[i] = phi0[i]
            for j in range(d):
                H[i, j] = H0 * (1.0 if i == j else 0.0)
        lam, v = lambda0, v0
        Sb = np.zeros((n, d))                    # Sigma_b(0) = Gamma(0): first row -mu, mu, ...
        for j in range(d):
            Sb[0, j] = mu_u
        Sb[0, 0] = -mu_u
        F10, F01 = A10.copy(), A01.copy()
        _set_phi(F10, F01, pmat, pcol, phi)
        if full and m > 0:                       # eq 21a at the row's first pixel too
            Sb = np.empty((n, d))
            _add(F10 @ Sa_rows[here, 0], F01 @ Sa_rows[above, 1 + M], Sb)
            _add_first_row(Sb, _regressors(Xa, m, 0, pmat, pcol, M, cols))
        for c in range(cols):
            xa, P, K, z, Rz, L, Pb = _step(Xa, Pa, m, c, F10, F01, M, sigma_e2, sigma_v2,
                                           y[m, c])
            if full:                             # _step leaves the left and upper states
                kappa, dPa = _gain_derivative(F10, F01, pmat, pcol, Pa[m + 1, c],
                                              Pa[m, c + 1 + M], dP_rows[here, c],
                                              dP_rows[above, c + 1 + M], Pb, K, L, Rz,
                                              sigma_v2)
            # Table I, in its order: Delta, H, phi, Sigma_a, Gamma, Sigma_b(k+1)
            lam = 0.99 * lam + 0.01
            v = 1.0 / (1.0 + lam / v)
            delta = np.empty(d)
            for i in range(d):
                delta[i] = Sb[0, i]
            for i in range(d):
                for j in range(d):
                    H[i, j] = H[i, j] + v * (delta[i] * delta[j] / Rz - H[i, j])
            step = np.linalg.solve(H, delta)
            scale = z / Rz
            for i in range(d):
                phi[i] = phi[i] + v * step[i] * scale
            Sa = np.empty((n, d))
            _product(L, Sb, Sa, False)
            if full:
                for i in range(n):
                    for j in range(d):
                        Sa[i, j] += kappa[i, j] * z
                for i in range(n):
                    for j in range(d):
                        Sa_rows[here, c + 1, i, j] = Sa[i, j]
                for q in range(d):
                    for i in range(n):
                        for j in range(n):
                            dP_rows[here, c + 1, q, i, j] = dPa[q, i, j]
            _set_phi(F10, F01, pmat, pcol, phi)
            # Sigma_b for the next pixel (eq 21a): A10 Sigma_a(left) + A01 Sigma_a(above)
            # + Gamma, the regressors of the next pixel
            Sb = np.empty((n, d))
            _product(F10, Sa, Sb, False)
            if full:
                _product(F01, Sa_rows[above, min(c + 2 + M, cols + M)], Sb, True)
            _add_first_row(Sb, _regressors(Xa, m, c + 1, pmat, pcol, M, cols))
            out[m, c] = xa[0]
            for j in range(d):
                sens[m, c, j] = Sa[0, j]
            p_norm[m, c] = _norm(P)
            k_norm[m, c] = _norm(K)
            if m == trace_row:
                for j in range(d):
                    trace[c, j] = phi[j]
    return out, p_norm, k_norm, trace, sens


def restore_adaptive(noisy: np.ndarray, a0: np.ndarray, sigma_e2: float, sigma_v2: float,
                     M: int, settings: dict, trace_row: int = 0,
                     boundary_variance: float | None = None) -> dict:
    """The adaptive filter: eqs 13a-e with the parameters identified pixel by pixel by the
    stochastic Newton recursion of Table I (eqs 16-24), restarted from ``a0`` at every row.

    ``settings``: ``H0`` (eq 25's ``rho^-1``; the paper's experiment uses 1), ``lambda0``
    (0.95, eq 24), ``v0`` (not given), ``mu_u`` (the first row of ``Sigma_b(0)``) and
    ``gradient``: ``full`` is Table I as printed, ``Sigma_a = (I - K C) Sigma_b + kappa z``
    with ``kappa = dK/dphi`` (eq 22b) computed recursively (the covariance recursion
    differentiated with phi held, ``dP_a/dphi`` kept per stored state) and ``Sigma_b =
    A10 Sigma_a(left) + A01 Sigma_a(above) + Gamma`` (eq 21a) at every pixel, the printed
    ``Sigma_b(0)`` (with ``mu_u``) at the image's first; ``approximate`` leaves out
    ``kappa`` and the row above's sensitivity (the rows above as fixed data) and starts
    every row from the printed ``Sigma_b(0)``. ``R_z`` is
    the filter's own prediction-error variance ``C P_b C' + s_v^2``. No stability
    projection: a run whose image is not finite is reported as diverged by the caller.
    Returns the image, the norms of Figs 5-6, the parameters along ``trace_row`` (Fig 7)
    and ``sensitivity``, the recursion's d(restored pixel)/dphi (first row of Sigma_a).
    """
    A10, A01, _ = nshp.state_matrices(a0, M)
    pmat, pcol = nshp.parameter_positions(M)
    y = np.ascontiguousarray(noisy, dtype=float)
    var = float(np.var(y) - sigma_v2) if boundary_variance is None else boundary_variance
    out, p_norm, k_norm, trace, sens = _adaptive(
        y, A10, A01, nshp.left_boundary(M), pmat, pcol, np.asarray(a0, float),
        float(sigma_e2), float(sigma_v2), max(var, 0.0), int(M), float(settings["H0"]),
        float(settings["lambda0"]), float(settings["v0"]), float(settings["mu_u"]),
        int(trace_row), settings.get("gradient", "full") == "full")
    return {"image": out, "P_norm": p_norm, "K_norm": k_norm, "trace": trace,
            "sensitivity": sens}
