"""The nonsymmetric half-plane (NSHP) autoregressive image model of Azimi-Sadjadi and Bannour
(``shared/seeds/000_…``, eqs 1-10) and its noise-corrected Yule-Walker identification.

Eq 1: ``u(m, n) = sum_{(p, q) in W} a_{p,q} u(m - p, n - q) + e(m, n)`` over the window
``W = {(0, q): 1 <= q <= M} U {(p, q): 1 <= p <= M, -M <= q <= M}`` (the printed window reads
"1 < p <= M": with it the window would miss the row above). The local state of eq 4 holds
the ``2M^2 + 2M + 1`` pixels of the window and the current one, in the printed order

    u(m, n), u(m, n-1), ..., u(m, n-M),
    u(m-1, n+M), ..., u(m-1, n-M), ..., u(m-M, n+M), ..., u(m-M, n-M),

and eq 5 propagates it, ``X(m, n) = A10 X(m, n-1) + A01 X(m-1, n+M) + B e(m, n)``.
:func:`state_matrices` builds ``A10`` and ``A01`` from that definition (which pixel of the
new state sits where in the two old ones) instead of from the printed blocks 6-8, whose
eq 8b prints ``a_{2,-M}`` where every block ``i`` needs ``a_{i,-M}``; a test checks the
state-space form against eq 1 pixel for pixel.
"""

from __future__ import annotations

import numpy as np


def window(M: int) -> list[tuple[int, int]]:
    """The offsets ``(p, q)`` of ``W`` in the parameter order of eq 4 (the state's order
    without its first entry)."""
    return [(0, q) for q in range(1, M + 1)] + [(p, q) for p in range(1, M + 1)
                                                for q in range(-M, M + 1)]


def state_offsets(M: int) -> list[tuple[int, int]]:
    """The offset ``(p, q)`` of each local-state entry: entry ``i`` is ``u(m - p, n - q)``."""
    return [(0, 0)] + window(M)


def state_matrices(a: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``A10``, ``A01`` and ``B`` of eq 5 for the parameters ``a`` (ordered as
    :func:`window`)."""
    offsets = state_offsets(M)
    where = {o: i for i, o in enumerate(offsets)}
    n = len(offsets)
    A10, A01 = np.zeros((n, n)), np.zeros((n, n))

    def source(p: int, q: int) -> tuple[np.ndarray, int]:
        # u(m-p, n-q) is in X(m, n-1) at offset (p, q-1), else in X(m-1, n+M) at (p-1, q+M)
        if (p, q - 1) in where:
            return A10, where[(p, q - 1)]
        return A01, where[(p - 1, q + M)]

    for coeff, (p, q) in zip(a, window(M), strict=True):
        matrix, j = source(p, q)
        matrix[0, j] += coeff
    for i, (p, q) in enumerate(offsets[1:], start=1):
        matrix, j = source(p, q)
        matrix[i, j] = 1.0
    B = np.zeros(n)
    B[0] = 1.0
    return A10, A01, B


def left_boundary(M: int) -> np.ndarray:
    """Rows ``(i, col, j)``: entry ``i`` of the state left of a row, ``X(m, -1)``, is the pixel
    ``u(m - p, col)`` of a row above, which is entry ``j`` (offset ``(p - 1, 0)``) of
    ``X(m - 1, col)``. Its other entries lie off the image. Eq 5 alone would start each row
    from a state that forgets the ``M`` first pixels of the rows above."""
    offsets = state_offsets(M)
    where = {o: i for i, o in enumerate(offsets)}
    return np.array([(i, -1 - q, where[(p - 1, 0)]) for i, (p, q) in enumerate(offsets)
                     if p >= 1 and q <= -1], dtype=np.int64).reshape(-1, 3)


def simulate(a: np.ndarray, M: int, e: np.ndarray) -> np.ndarray:
    """A field from eq 1 driven by ``e (rows, cols)``, zero outside the image."""
    rows, cols = e.shape
    u = np.zeros((rows + M, cols + 2 * M))          # M rows above, M columns each side
    win = window(M)
    for m in range(rows):
        for n in range(cols):
            mm, nn = m + M, n + M
            u[mm, nn] = e[m, n] + sum(c * u[mm - p, nn - q]
                                      for c, (p, q) in zip(a, win, strict=True))
    return u[M:, M:cols + M]


def simulate_state_space(a: np.ndarray, M: int, e: np.ndarray) -> np.ndarray:
    """The same field from eq 5, local state by local state (zero states outside)."""
    rows, cols = e.shape
    A10, A01, B = state_matrices(a, M)
    size = A10.shape[0]
    X = np.zeros((rows + 1, cols + M + 1, size))    # X[m + 1, n + 1]; zeros off the image
    for m in range(rows):
        for i, col, j in left_boundary(M):
            X[m + 1, 0, i] = X[m, col + 1, j]
        for n in range(cols):
            X[m + 1, n + 1] = A10 @ X[m + 1, n] + A01 @ X[m, n + 1 + M] + B * e[m, n]
    return X[1:, 1:cols + 1, 0]


def autocorrelation(image: np.ndarray, M: int) -> dict[tuple[int, int], float]:
    """Sample autocorrelation ``r(p, q) = mean u(m, n) u(m - p, n - q)`` for every lag the
    normal equations need (``|p| <= M``, ``|q| <= 2M``), of a zero-mean image."""
    rows, cols = image.shape
    r = {}
    for p in range(-M, M + 1):
        for q in range(-2 * M, 2 * M + 1):
            a = image[max(p, 0):rows + min(p, 0), max(q, 0):cols + min(q, 0)]
            b = image[max(-p, 0):rows + min(-p, 0), max(-q, 0):cols + min(-q, 0)]
            r[(p, q)] = float(np.mean(a * b))
    return r


def yule_walker(noisy: np.ndarray, M: int, noise_variance: float) -> tuple[np.ndarray, float]:
    """Parameters and driving variance ``sigma_e^2`` from a noisy zero-mean image, by the
    normal equations of eq 3 with the white noise's variance taken off ``r(0, 0)``."""
    r = autocorrelation(noisy, M)
    r[(0, 0)] -= noise_variance
    win = window(M)
    R = np.array([[r[(p - pp, q - qq)] for (pp, qq) in win] for (p, q) in win])
    rhs = np.array([r[o] for o in win])
    a = np.linalg.solve(R, rhs)
    sigma_e2 = r[(0, 0)] - float(a @ rhs)
    return a, max(sigma_e2, 1e-12 * r[(0, 0)])


def parameter_positions(M: int) -> tuple[np.ndarray, np.ndarray]:
    """Where each parameter sits in eq 5: ``(matrix, column)`` with matrix 0 for ``A10`` and
    1 for ``A01`` (first row in both); :func:`state_matrices` fills the same places."""
    A10, A01, _ = state_matrices(np.arange(1.0, 2 * M * M + 2 * M + 1), M)
    matrix, column = [], []
    for j in range(2 * M * M + 2 * M):
        hit10, hit01 = np.flatnonzero(A10[0] == j + 1), np.flatnonzero(A01[0] == j + 1)
        matrix.append(0 if hit10.size else 1)
        column.append(int(hit10[0] if hit10.size else hit01[0]))
    return np.array(matrix, dtype=np.int64), np.array(column, dtype=np.int64)


def names(M: int) -> list[str]:
    """Parameter names ``a_{p,q}`` in :func:`window` order (``a01``, ``a1,-1``, ...)."""
    return [f"a{p}{q}" if q >= 0 else f"a{p},{q}" for p, q in window(M)]
