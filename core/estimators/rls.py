"""Recursive least squares with a variable forgetting factor (thesis eqs 1.12-1.17).

RLS estimates the measured output as a linear function of a regressor built from the
known input: ``phi_k = [1, u_{k-1}, ..., u_{k-M}]`` in thesis indexing (the leading 1 when
``bias``; see :meth:`RecursiveLeastSquares.regressors` for array indexing), with the
noisy measurement ``z_k`` as the desired signal ``d_k`` (eq 1.12). Per step, batched:

    zeta_k   = d_k - phi_k^T W_{k-1}                       (1.13, a priori error)
    K_k      = P_{k-1} phi_k / (1 + phi_k^T P_{k-1} phi_k)      (1.14)
    W_k      = W_{k-1} + K_k zeta_k                         (1.15)
    lambda_k = 1 - (1 - phi_k^T K_k) |zeta_k|^2 / chi       (1.16), clipped to
               [lambda_min, 1]
    P_k      = (P_{k-1} - K_k phi_k^T P_{k-1}) / lambda_k   (1.17)

This is the variable-forgetting RLS of Fortescue, Kershenbaum and Ydstie (1981), the form
the thesis prints: the forgetting enters ``P`` after the update (1.17), so the gain's
denominator is ``1 + phi^T P phi`` as printed. Fixes to the printed form (notes.md item 17):
``W_{k-1}`` in 1.13, ``M`` taps in both the weights and the regressor, and ``lambda_k``
bounded to ``[lambda_min, 1]``. The regressor is the filter's input ``u`` (for the MOSFET,
the slope of the nominal source on each interval). The estimate is the a posteriori output
``phi_k^T W_k``; the residual is ``zeta_k``.
"""

from __future__ import annotations

import numpy as np

from core.estimators.base import Estimate, batch_input
from core.schema import boolean, integer, number


class RecursiveLeastSquares:
    """RLS-VFF output estimator; see the module docstring for the recursion."""

    SETTINGS = {
        "order": (integer(1, 200), None),
        "chi": (number(positive=True, maximum=1e12), None),
        "lambda0": (number(positive=True, maximum=1.0), None),
        "lambda_min": (number(positive=True, maximum=1.0), None),
        "delta": (number(positive=True, maximum=1e12), None),
        "bias": (boolean, None),
    }

    def __init__(self, order: int = 10, chi: float = 1.0, lambda0: float = 0.99,
                 lambda_min: float = 0.9, delta: float = 100.0, bias: bool = True) -> None:
        self.order = int(order)
        self.chi = float(chi)
        self.lambda0 = float(lambda0)
        self.lambda_min = float(lambda_min)
        self.delta = float(delta)
        self.bias = bool(bias)

    def validate(self, model) -> None:
        """Raise ``ValueError`` for settings that cannot run."""
        if self.order < 1:
            raise ValueError(f"order must be >= 1, got {self.order}")
        if not 0 < self.lambda_min <= 1:
            raise ValueError(f"lambda_min must be in (0, 1], got {self.lambda_min}")
        if not self.lambda_min <= self.lambda0 <= 1:
            raise ValueError(f"lambda0 must be in [lambda_min, 1], got {self.lambda0}")
        if not (self.chi > 0 and self.delta > 0):
            raise ValueError("chi and delta must be positive")

    def regressors(self, u: np.ndarray) -> np.ndarray:
        """``(runs, steps, q)`` regressors: row ``k`` is ``[1, u[k], u[k-1], ..., u[k-M+1]]``.

        ``u[k]`` is the input on the interval that ends at measurement ``z[k]`` (the thesis'
        ``u_{k-1}``); inputs before the first interval are zero.
        """
        runs, steps, p = u.shape
        padded = np.concatenate([np.zeros((runs, self.order - 1, p)), u], axis=1)
        taps = [padded[:, self.order - 1 - j: self.order - 1 - j + steps, :]
                for j in range(self.order)]
        phi = np.concatenate(taps, axis=-1)
        if self.bias:
            phi = np.concatenate([np.ones((runs, steps, 1)), phi], axis=-1)
        return phi

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float | None = None,
            x0: np.ndarray | None = None) -> Estimate:
        runs, steps, m = z.shape
        phi = self.regressors(batch_input(u, runs))
        q = phi.shape[-1]
        W = np.zeros((runs, q, m))
        P = np.broadcast_to(self.delta * np.eye(q), (runs, q, q)).copy()
        lam = np.full(runs, self.lambda0)
        y_hat = np.empty((runs, steps, m))
        innovation = np.empty((runs, steps, m))
        for k in range(steps):
            ph = phi[:, k, :]
            zeta = z[:, k, :] - np.einsum("rq,rqm->rm", ph, W)
            Pph = np.einsum("rab,rb->ra", P, ph)
            denom = 1.0 + np.einsum("ra,ra->r", ph, Pph)
            K = Pph / denom[:, None]
            W = W + K[:, :, None] * zeta[:, None, :]
            gain = np.einsum("ra,ra->r", ph, K)
            lam = np.clip(1.0 - (1.0 - gain) * np.sum(zeta**2, axis=1) / self.chi,
                          self.lambda_min, 1.0)
            P = (P - K[:, :, None] * Pph[:, None, :]) / lam[:, None, None]
            P = 0.5 * (P + np.swapaxes(P, -1, -2))
            y_hat[:, k] = np.einsum("rq,rqm->rm", ph, W)
            innovation[:, k] = zeta
        return Estimate(y_hat=y_hat, innovation=innovation, diverged=~np.all(
            np.isfinite(y_hat), axis=(1, 2)))
