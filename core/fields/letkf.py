"""Local ensemble transform Kalman filter (LETKF; Hunt, Kostelich and Szunyogh 2007) with
Gaspari-Cohn observation tapering, for the field filter of Chapter 5 (D61).

The grid is cut into cubes of ``block`` points per side. Each cube gets its own ETKF
analysis (:mod:`estim.fields.etkf`) from the sensors around it, each sensor's observations
weighted by the Gaspari-Cohn taper ``rho(d)`` of its distance ``d`` from the cube's centre
(R^-1 multiplied by ``rho``, as DAPPER's ``local_analyses`` does with ``sqrt(rho)`` on the
normalised anomalies):

    Pt_b^-1 = (m - 1) / infl I + sum_s rho_bs Yp_s R_s^-1 Yp_s^T        (m x m, per cube b)
    w_b     = Pt_b sum_s rho_bs Yp_s R_s^-1 (y_s - yf_s)
    T_b     = [(m - 1) Pt_b]^{1/2}                                       (symmetric)
    E_a     = x + (w_b + T_b) A         on the cube's points

A cube no sensor reaches (``rho = 0`` for all) keeps its forecast. With a taper of 1
everywhere every cube's transform is the global ETKF's (tested). The cubes' analyses are
batched: one ``(cubes, m, m)`` symmetric eigen-decomposition per step.

The Gaspari-Cohn function (Gaspari and Cohn 1999, eq 4.10) has half-width ``c``: 1 at 0,
about 0.21 at ``c``, zero from ``2c``. DAPPER's ``dist2coeff(d, radius, 'GC')`` uses
``c = 1.82 radius`` (bench/crosscheck_dapper.py compares the two).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.numerics.kernels import jit


def gaspari_cohn(distance: np.ndarray, half_width: float) -> np.ndarray:
    """The fifth-order piecewise rational taper of half-width ``half_width``."""
    r = np.abs(np.asarray(distance, float)) / half_width
    out = np.zeros_like(r)
    inner = r <= 1
    outer = (r > 1) & (r < 2)
    a = r[inner]
    out[inner] = -0.25 * a**5 + 0.5 * a**4 + 0.625 * a**3 - 5 / 3 * a**2 + 1
    b = r[outer]
    out[outer] = (b**5 / 12 - 0.5 * b**4 + 0.625 * b**3 + 5 / 3 * b**2 - 5 * b + 4
                  - 2 / (3 * b))
    return out


@dataclass(frozen=True)
class Localisation:
    """The cubes' grid points ``(cubes, block^3)``, each cube's centre ``(cubes, 3)``, the
    distance and the taper of every sensor for every cube ``(cubes, sensors)``, for the
    cubes some sensor reaches (``active``: their numbers among all cubes)."""

    points: np.ndarray
    centres: np.ndarray
    distances: np.ndarray
    taper: np.ndarray
    active: np.ndarray
    cubes: int


def localisation(n: int, xyz: np.ndarray, sensors_xyz: np.ndarray, block: int,
                 half_width: float) -> Localisation:
    """Cubes of ``block`` points per side on an ``n``-point grid whose point coordinates are
    ``xyz`` (C order, ``(n^3, 3)``); ``block`` must divide ``n``."""
    if n % block:
        raise ValueError(f"block {block} does not divide the grid's {n} points per side")
    nb = n // block
    index = np.arange(n**3).reshape(n, n, n)
    cubes = index.reshape(nb, block, nb, block, nb, block).transpose(0, 2, 4, 1, 3, 5)
    points = cubes.reshape(nb**3, block**3)
    centres = xyz[points].mean(axis=1)
    dist = np.linalg.norm(centres[:, None, :] - sensors_xyz[None], axis=-1)
    taper = gaspari_cohn(dist, half_width)
    active = np.flatnonzero(taper.max(axis=1) > 0)
    return Localisation(points=points[active], centres=centres[active],
                        distances=dist[active], taper=taper[active], active=active,
                        cubes=nb**3)


def transforms(Yp: np.ndarray, innovation: np.ndarray, R: np.ndarray, taper: np.ndarray,
               inflation: float = 1.0) -> np.ndarray:
    """Each cube's ensemble transform ``W_b = w_b + T_b`` ``(cubes, m, m)``: row ``i`` of
    ``W_b @ A`` is member ``i``'s analysed anomaly.

    ``Yp (m, sensors, k)``: predicted-observation anomalies, ``k`` readings per sensor;
    ``innovation (sensors, k)``: ``y - yf``; ``R (sensors, k)``: observation variances;
    ``taper (cubes, sensors)``."""
    m, sensors = Yp.shape[:2]
    scaled = Yp / R                                              # Yp R^-1
    outer = (np.ascontiguousarray(scaled.transpose(1, 0, 2))
             @ np.ascontiguousarray(Yp.transpose(1, 2, 0)))     # (sensors, m, m)
    upper = np.triu_indices(m)                                   # Pinv is symmetric
    half = taper @ outer.reshape(sensors, m * m)[:, upper[0] * m + upper[1]]
    Pinv = np.empty((taper.shape[0], m, m))
    Pinv[:, upper[0], upper[1]] = half
    Pinv[:, upper[1], upper[0]] = half
    Pinv += (m - 1) / inflation * np.eye(m)
    rhs = taper @ np.einsum("msk,sk->sm", scaled, innovation)   # (cubes, m)
    s, V = np.linalg.eigh(Pinv)
    w = np.einsum("bij,bj->bi", V, np.einsum("bji,bj->bi", V, rhs) / s)
    T = (V * np.sqrt((m - 1) / s)[:, None, :]) @ V.transpose(0, 2, 1)
    return T + w[:, None, :]


@jit
def _analyse_cubes(X, points, W, means):  # pragma: no cover - compiled
    """In place: for each cube, gather its anomalies ``(m, fields x points)``, multiply by
    the cube's transform, add the mean back; the analysed ensemble mean of every row at
    the cube's points into ``means (fields, n^3)``. Member by member (one member's field is
    contiguous; the members of one point lie a field apart), each column's sums still taken
    over the members in order."""
    m, fields = X.shape[0], X.shape[1]
    cubes, size = points.shape
    width = fields * size
    A = np.empty((m, width))
    mean = np.empty(width)
    total = np.empty(width)
    for c in range(cubes):
        mean[:] = 0.0
        for i in range(m):
            for f in range(fields):
                for q in range(size):
                    x = X[i, f, points[c, q]]
                    A[i, f * size + q] = x
                    mean[f * size + q] += x
        for col in range(width):
            mean[col] = mean[col] / m
        for i in range(m):
            for col in range(width):
                A[i, col] -= mean[col]
        B = np.dot(np.ascontiguousarray(W[c]), A)
        total[:] = 0.0
        for i in range(m):
            for f in range(fields):
                for q in range(size):
                    col = f * size + q
                    v = mean[col] + B[i, col]
                    X[i, f, points[c, q]] = v
                    total[col] += v
        for f in range(fields):
            for q in range(size):
                means[f, points[c, q]] = total[f * size + q] / m


@jit
def _analysed_mean(first, points, W, out):  # pragma: no cover - compiled
    """The analysed ensemble mean of the row ``first (m, n^3)`` at the cubes' points:
    ``mean + (1^T W / m) A``, a vector, not a matrix, product (member by member, as in
    :func:`_analyse_cubes`)."""
    m = first.shape[0]
    cubes, size = points.shape
    wbar = np.empty(m)
    x = np.empty(size)
    acc = np.empty(size)
    for c in range(cubes):
        for j in range(m):
            s = 0.0
            for i in range(m):
                s += W[c, i, j]
            wbar[j] = s / m
        x[:] = 0.0
        for i in range(m):
            for q in range(size):
                x[q] += first[i, points[c, q]]
        for q in range(size):
            x[q] = x[q] / m
        acc[:] = 0.0
        for j in range(m):
            for q in range(size):
                acc[q] += wbar[j] * (first[j, points[c, q]] - x[q])
        for q in range(size):
            out[points[c, q]] = x[q] + acc[q]


def analyse(X: np.ndarray, local: Localisation, W: np.ndarray) -> np.ndarray:
    """Apply each cube's transform to its points: ``X (m, fields, n^3)`` -> analysed copy
    (cubes no sensor reaches keep their forecast)."""
    out = np.array(X, dtype=float, order="C", copy=True)
    _analyse_cubes(out, local.points, np.ascontiguousarray(W, dtype=float),
                   np.empty(out.shape[1:]))
    return out


def analyse_levels(levels: np.ndarray, first: np.ndarray, local: Localisation,
                   W: np.ndarray) -> np.ndarray:
    """:func:`analyse` of the rows ``[first, A(t), Phi(t), A(t + dt), Phi(t + dt)]`` where
    only the leapfrog's ``levels (m, 2, 2, n^3)`` (C order, analysed in place) go on and
    of ``first (m, n^3)`` (``A(t - dt)``) only the analysed mean is wanted. Returns the
    analysed ensemble mean of the five rows ``(5, n^3)``; equal to :func:`analyse` to
    rounding (tested)."""
    if not (levels.flags.c_contiguous and levels.dtype == np.float64):
        raise ValueError("levels must be a C-ordered float64 array: they are analysed in place")
    m, points = levels.shape[0], levels.shape[-1]
    means = np.empty((5, points))
    if local.points.size < points:                       # cubes no sensor reaches
        means[0] = first.mean(axis=0)
        means[1:] = levels.mean(axis=0).reshape(4, points)
    W = np.ascontiguousarray(W, dtype=float)
    _analyse_cubes(levels.reshape(m, 4, points), local.points, W, means[1:])
    _analysed_mean(first, local.points, W, means[0])
    return means


def effective_rank(X: np.ndarray, threshold: float = 1e-6) -> int:
    """Singular values of the anomalies ``X - mean`` ``(m, ...)`` above ``threshold`` times
    the largest (from the members' Gram matrix: ``m`` eigenvalues, not an SVD of the
    field)."""
    A = (X - X.mean(axis=0)).reshape(X.shape[0], -1)
    return rank_of_gram(A @ A.T, threshold)


def effective_rank_on_basis(coef: np.ndarray, basis: np.ndarray,
                            threshold: float = 1e-6) -> int:
    """:func:`effective_rank` of members ``X_i = sum_b coef[i, b] basis[b]``, from the
    coefficients ``(m, b)`` and the basis ``(b, ...)``: the Gram matrix of the anomalies is
    ``D (B B^T) D^T`` with ``D`` the coefficients' anomalies."""
    D = coef - coef.mean(axis=0)
    B = basis.reshape(basis.shape[0], -1)
    return rank_of_gram(D @ (B @ B.T) @ D.T, threshold)


def rank_of_gram(gram: np.ndarray, threshold: float = 1e-6) -> int:
    """How many singular values (square roots of the Gram matrix' eigenvalues) exceed
    ``threshold`` times the largest."""
    sv = np.sqrt(np.clip(np.linalg.eigvalsh(gram), 0.0, None))
    return int(np.sum(sv > threshold * sv.max())) if sv.max() > 0 else 0
