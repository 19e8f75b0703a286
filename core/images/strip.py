"""Strip Kalman filtering (Azimi-Sadjadi, "New results in strip Kalman filtering",
``shared/seeds/002_…`` from its second title): a vector AR model of the columns of a strip of
``W`` rows (eq 1), identified by the vector Yule-Walker equations (eqs 10-13), and the
Kalman filter of the composite image-and-blur model (eqs 22-36).

With additive noise only (the blur matrices ``A2, B2, C2, D2`` of eq 21 are defined only in
the paper's reference [1]) the blur state is empty, ``A' = I`` and eqs 36a-f are a standard
vector Kalman filter on ``x1``. :func:`filter_36` keeps the general form, so a test can hold
it against a standard Kalman filter on the synchronised model ``[x1(k); x2(k)]``.
"""

from __future__ import annotations

import numpy as np


def covariances(Z: np.ndarray, P: int, unbiased: bool = True) -> list[np.ndarray]:
    """``rho_r = E[Z(k - r) Z'(k)]`` for ``r = 0..P`` from columns ``Z (..., W, N)``; with
    ``unbiased`` the printed ``1/(N - r)`` (eq 13), else ``1/N``, which keeps the block
    Toeplitz matrix of eq 11 positive semidefinite."""
    N = Z.shape[-1]
    out = []
    for r in range(P + 1):
        s = np.einsum("...ik,...jk->...ij", Z[..., :N - r], Z[..., r:])
        out.append(s / ((N - r) if unbiased else N))
    return out


def yule_walker(Z: np.ndarray, P: int, noise_variance: float = 0.0, unbiased: bool = True,
                min_eigenvalue: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``phi (..., P, W, W)``, ``Q_U (..., W, W)`` and ``rho_0 (..., W, W)`` from eqs 11-12 for
    columns ``Z (..., W, N)``, with the white noise's variance taken off ``rho_0``.

    Taken off a strip's sample covariances, the noise leaves the block Toeplitz ``T`` of eq
    11 indefinite (at 5 dB on camera every strip of 8 rows: an image's adjacent rows are so
    alike that its covariance across them has eigenvalues below the noise's), and ``Q_U``
    and the model with it. With ``min_eigenvalue`` the eigenvalues of ``T`` are raised to at
    least that first, which makes ``T`` positive definite and ``Q_U`` (a Schur complement of
    it) too. A clean strip can need it as well: a flat region makes ``T`` singular.
    """
    return _solve(covariances(Z, P, unbiased), P, Z.shape[-2], noise_variance, min_eigenvalue)


def block_toeplitz(rho: list[np.ndarray], P: int) -> np.ndarray:
    """``T`` of eq 11: block ``(i, j)`` is ``rho_{i-j}`` with ``rho_{-r} = rho_r'``."""

    def block(i: int, j: int) -> np.ndarray:
        return rho[i - j] if i >= j else np.swapaxes(rho[j - i], -1, -2)

    return np.concatenate([np.concatenate([block(i, j) for j in range(P + 1)], axis=-1)
                           for i in range(P + 1)], axis=-2)


def _solve(rho: list[np.ndarray], P: int, W: int, noise_variance: float,
           min_eigenvalue: float | None):
    T = block_toeplitz(rho, P) - noise_variance * np.eye((P + 1) * W)
    if min_eigenvalue is not None:
        w, V = np.linalg.eigh(T)
        w = np.maximum(w, min_eigenvalue)
        T = (V * w[..., None, :]) @ np.swapaxes(V, -1, -2)
    Tinv = np.linalg.inv(T)
    Q = np.linalg.inv(Tinv[..., :W, :W])                                   # eq 12b
    phi = np.stack([-Tinv[..., (i + 1) * W:(i + 2) * W, :W] @ Q for i in range(P)], axis=-3)
    return phi, 0.5 * (Q + np.swapaxes(Q, -1, -2)), T[..., :W, :W]


def online_models(Z: np.ndarray, P: int, noise_variance: float, unbiased: bool = True,
                  min_eigenvalue: float | None = None):
    """A model for every column ``k`` of ``Z (strips, W, N)`` from the columns before it: the
    covariances by eq 15's recursion (each ``rho_r(n)`` an average over ``n - r`` products,
    exactly), the parameters by solving eqs 11-12 anew (not by eqs 17-18's approximation,
    see :func:`neumann_inverse`). The first ``P + 2`` columns, too few for a model, use the
    one from columns ``0..P+1``. Returns ``phi (strips, N, P, W, W)``, ``Q`` and ``rho_0``."""
    strips, W, N = Z.shape
    first = min(P + 2, N)
    sums = [np.zeros((strips, W, W)) for _ in range(P + 1)]
    used, model = 0, None
    phis, Qs, rho0s = [], [], []
    for k in range(N):
        n = max(k, first)                            # the model of columns 0 .. n-1
        if n > used:
            while used < n:                          # eq 15: the products ending at `used`
                for r in range(min(P, used) + 1):
                    sums[r] += np.einsum("si,sj->sij", Z[:, :, used - r], Z[:, :, used])
                used += 1
            rho = [sums[r] / ((n - r) if unbiased else n) for r in range(P + 1)]
            model = _solve(rho, P, W, noise_variance, min_eigenvalue)
        phis.append(model[0])
        Qs.append(model[1])
        rho0s.append(model[2])
    return np.stack(phis, axis=1), np.stack(Qs, axis=1), np.stack(rho0s, axis=1)


def neumann_inverse(T: np.ndarray, T_next: np.ndarray, T_inv: np.ndarray) -> np.ndarray:
    """Eq 17: ``(T + dT)^-1 ~ T^-1 (I - dT T^-1)``, the first-order Neumann term (the
    paper calls it the matrix inversion lemma, which would be exact)."""
    return T_inv @ (np.eye(T.shape[-1]) - (T_next - T) @ T_inv)


def companion(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``A1, B1, C1`` of eqs 19-20 (``x1(k) = [Z(k); ...; Z(k - P + 1)]``)."""
    *batch, P, W, _ = phi.shape
    n = P * W
    A1 = np.zeros((*batch, n, n))
    for i in range(P):
        A1[..., :W, i * W:(i + 1) * W] = np.swapaxes(phi[..., i, :, :], -1, -2)
    A1[..., W:, :n - W] += np.eye(n - W)
    B1 = np.zeros((n, W))
    B1[:W] = np.eye(W)
    return A1, B1, B1.T.copy()


def filter_36(Y: np.ndarray, A1, B1, C1, Q_U, A2, B2, C2, D2, sigma_v2: float,
              P0: np.ndarray) -> np.ndarray:
    """Eqs 36a-f for observations ``Y (steps, W)``: the filtered image columns ``Z(k|k)``.

    As printed with two fixes: 36c's ``alpha^2`` is ``sigma_v^2`` and its ``C'`` is
    ``C_bar'``; 36e's ``A''`` is ``A'^T``. 36e is taken as ``A' P A'^T - K S K^T``, the same
    matrix, kept symmetric. ``P0`` is the covariance of ``[x1(0); x2(1)]`` after no data.
    """
    n1, n2 = A1.shape[0], A2.shape[0]
    Cbar = np.hstack([D2 @ C1, C2])
    Aprime = np.block([[np.eye(n1), np.zeros((n1, n2))], [B2 @ C1, A2]])
    F = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1 @ A1, A2]])
    Adirect = np.block([[A1, np.zeros((n1, n2))], [np.zeros((n2, n1)), np.eye(n2)]])
    GQG = np.zeros((n1 + n2, n1 + n2))
    GQG[:n1, :n1] = B1 @ Q_U @ B1.T
    s = np.zeros(n1 + n2)                            # [x1(k-1); x2(k)] after Y(k-1)
    Pa = P0.copy()
    out = np.empty((Y.shape[0], C1.shape[0]))
    for k in range(Y.shape[0]):
        prior_pair = np.concatenate([A1 @ s[:n1], s[n1:]])           # [x1(k|k-1); x2(k|k-1)]
        s_next = F @ s                                               # 36a
        Pb = Adirect @ Pa @ Adirect.T + GQG                          # 36b
        S = Cbar @ Pb @ Cbar.T + sigma_v2 * np.eye(Cbar.shape[0])
        K = np.linalg.solve(S, (Aprime @ Pb @ Cbar.T).T).T           # 36c
        s = s_next + K @ (Y[k] - Cbar @ prior_pair)                  # 36d
        Pa = Aprime @ Pb @ Aprime.T - K @ S @ K.T                    # 36e
        Pa = 0.5 * (Pa + Pa.T)
        out[k] = C1 @ s[:n1]                                         # 36f
    return out


def restore(noisy: np.ndarray, width: int, order: int, sigma_v2: float,
            unbiased: bool = True, floor: float = 0.1,
            model_from: np.ndarray | None = None, online: bool = False) -> dict:
    """Strip Kalman filtering of a zero-mean ``noisy`` image, additive noise only: strips of
    ``width`` rows, each with its own vector AR(``order``) model (eqs 11-13) from the noisy
    strip (noise taken off) or, with ``model_from``, from that image's strip (the paper
    identifies from the original image); in both the eigenvalues of ``T`` are raised to
    ``floor * sigma_v2`` (:func:`yule_walker`). With ``online`` each column is filtered with
    the model of the columns before it (:func:`online_models`). Filtered column
    by column; all strips at once. Rows left over at the bottom form a narrower last strip.
    ``unstable_strips`` counts models with a spectral radius >= 1."""
    rows = noisy.shape[0]
    out = np.empty_like(noisy, dtype=float)
    cut = rows - rows % width
    parts = [(list(range(0, cut, width)), width)] + ([([cut], rows - cut)] if cut < rows else [])
    unstable = 0
    for starts, w in parts:
        Y = np.stack([noisy[s:s + w] for s in starts])
        if online:
            model = online_models(Y, order, sigma_v2, unbiased, floor * sigma_v2)
        elif model_from is None:
            model = yule_walker(Y, order, sigma_v2, unbiased, floor * sigma_v2)
        else:
            model = yule_walker(np.stack([model_from[s:s + w] for s in starts]), order, 0.0,
                                unbiased, floor * sigma_v2)
        filtered, bad = _filter_strips(Y, *model, sigma_v2)
        unstable += bad
        for i, s in enumerate(starts):
            out[s:s + w] = filtered[i]
    return {"image": out, "unstable_strips": unstable}


def _filter_strips(Z: np.ndarray, phi: np.ndarray, Q: np.ndarray, rho0: np.ndarray,
                   sigma_v2: float) -> tuple[np.ndarray, int]:
    """Eqs 36a-f with no blur state, batched over strips ``Z (strips, W, N)``, from ``x1 =
    0`` (the mean) with ``rho_0`` on the diagonal blocks of its covariance."""
    strips, W, N = Z.shape
    P = phi.shape[-3]
    varying = phi.ndim == 5                         # (strips, N, P, W, W): a model per column
    A1, _, _ = companion(phi)
    radius = np.max(np.abs(np.linalg.eigvals(A1)), axis=-1)
    n = P * W
    x = np.zeros((strips, n))
    Pa = np.zeros((strips, n, n))
    for i in range(P):
        Pa[:, i * W:(i + 1) * W, i * W:(i + 1) * W] = rho0[:, 0] if varying else rho0
    GQG = np.zeros((*Q.shape[:-2], n, n))
    GQG[..., :W, :W] = Q
    out = np.empty((strips, W, N))
    eye = np.eye(W)
    A1T = np.swapaxes(A1, -1, -2)
    for k in range(N):
        Ak, AkT, Gk = ((A1[:, k], A1T[:, k], GQG[:, k]) if varying else (A1, A1T, GQG))
        x = np.einsum("sij,sj->si", Ak, x)
        Pb = Ak @ Pa @ AkT + Gk
        S = Pb[:, :W, :W] + sigma_v2 * eye
        K = np.swapaxes(np.linalg.solve(S, np.swapaxes(Pb[:, :, :W], -1, -2)), -1, -2)
        x = x + np.einsum("sij,sj->si", K, Z[:, :, k] - x[:, :W])
        Pa = Pb - K @ S @ np.swapaxes(K, -1, -2)
        Pa = 0.5 * (Pa + np.swapaxes(Pa, -1, -2))
        out[:, :, k] = x[:, :W]
    unstable = radius.max(axis=-1) if varying else radius
    return out, int(np.sum(unstable >= 1.0))
