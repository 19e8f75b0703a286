"""Linear Kalman filter (thesis Appendix A.1, eqs A.1-A.7), batched over Monte Carlo runs."""

from __future__ import annotations

import numpy as np
from estim.estimators.base import Estimate, as_matrix, batch_input, check_covariance, joseph_update
from estim.schema import REQUIRED, list_of, matrix, number


class KalmanFilter:
    """``x_k = A x_{k-1} + B u_{k-1} + v``, ``z_k = C x_k + w`` with known ``A, B, C, Q, R``.

    The model argument of :meth:`run` is not used: the matrices are the settings. The
    initial estimate is the ``x0`` setting; without it, the ``x0`` given to :meth:`run` (the
    analyses pass the actual operating point, as for the EKF), else zero.
    """

    SETTINGS = {
        "A": (matrix, REQUIRED),
        "B": (matrix, REQUIRED),
        "C": (matrix, REQUIRED),
        "Q": (matrix, REQUIRED),
        "R": (matrix, REQUIRED),
        "P0": (matrix, REQUIRED),
        "x0": (list_of(number(), max_length=64), None),
    }

    def __init__(self, A, B, C, Q, R, P0, x0=None) -> None:
        self.A = np.atleast_2d(np.asarray(A, float))
        n = self.A.shape[0]
        self.B = np.asarray(B, float).reshape(n, -1)
        self.C = np.atleast_2d(np.asarray(C, float))
        self.Q = as_matrix(Q, n, "Q")
        self.R = as_matrix(R, self.C.shape[0], "R")
        self.x0 = None if x0 is None else np.asarray(x0, float).reshape(n)
        self.P0 = as_matrix(P0, n, "P0")

    def validate(self, model) -> None:
        """The covariances: finite, symmetric, positive (semi)definite."""
        n = self.A.shape[0]
        check_covariance(self.Q, n, "Q")
        check_covariance(self.P0, n, "P0")
        check_covariance(self.R, self.C.shape[0], "R", definite=True)

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float | None = None,
            x0: np.ndarray | None = None) -> Estimate:
        runs, steps, m = z.shape
        n = self.A.shape[0]
        u = batch_input(u, runs)
        start = self.x0 if self.x0 is not None else (np.zeros(n) if x0 is None else x0)
        x = np.broadcast_to(np.asarray(start, float), (runs, n)).copy()
        P = np.broadcast_to(self.P0, (runs, n, n)).copy()
        H = np.broadcast_to(self.C, (runs, m, n))
        x_hat = np.empty((runs, steps, n))
        P_hist = np.empty((runs, steps, n, n))
        S_hist = np.empty((runs, steps, m, m))
        innovation = np.empty((runs, steps, m))
        for k in range(steps):
            x = x @ self.A.T + u[:, k, :] @ self.B.T
            P = self.A @ P @ self.A.T + self.Q
            innovation[:, k] = z[:, k] - x @ self.C.T
            x, P, S_hist[:, k] = joseph_update(x, P, innovation[:, k], H, self.R)
            x_hat[:, k] = x
            P_hist[:, k] = P
        return Estimate(y_hat=x_hat @ self.C.T, innovation=innovation,
                        broken=np.zeros(runs, bool), x_hat=x_hat, P=P_hist, S=S_hist)
