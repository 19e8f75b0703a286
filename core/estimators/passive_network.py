"""The passive-network nonlinear estimator against the Kalman filter (the paper in
``shared/seeds/004_36cda1df439b9ced.txt``, eqs 13-26).

Model (eqs 13-18): ``x' = -x + w``, ``z = x/2 + v``, ``x(0) = 1``, ``q = 1``, ``r = 1/2``.

* eq 19 (the classical estimator): ``x^' = -x^ + V (z - x^/2)``,
  ``V' = -2V - V^2/2 + u`` (eq 20's ``f``). With ``u = q`` it is the Kalman-Bucy filter of the
  model (``V`` is the gain ``P H / R = P``); the paper's ``u = 6`` makes it the filter for
  ``q = 6``.
* eq 22 (the proposed one): ``x^'`` as in eq 19 and
  ``V' = s (z - x^/2) x^ - 2V - V^3/2 + u`` with ``s = -1`` as printed (the antisymmetric
  coupling) or ``s = +1`` (``coupling: flipped``).

Both are integrated by forward Euler at the sample time, as the paper's 500 points at 0.01
suggest. The signal is ``x(t) = A e^{-t} + N`` (eqs 25-26), fed to the estimators as ``z``
(``feed: z``, the model's measurement ``x/2``) or as it is (``feed: x``); the error is
``|x^ - A e^{-t}|``. The discrete KF samples the model exactly (``e^{-T}``,
``(1 - e^{-2T}) q / 2``, ``R = r / T``).
"""

from __future__ import annotations

import numpy as np

from estim.estimators.kf import KalmanFilter


def estimator(z: np.ndarray, dt: float, u: float, x0: float, v0: float, kind: str,
              coupling: int = -1) -> np.ndarray:
    """Eq 19 (``kind="eq19"``) or eq 22 (``"eq22"``) on ``z (runs, steps)``: ``x^`` at every
    sample."""
    runs, steps = z.shape
    x = np.full(runs, float(x0))
    V = np.full(runs, float(v0))
    out = np.empty((runs, steps))
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(steps):
            innovation = z[:, k] - x / 2
            dx = -x + V * innovation
            if kind == "eq19":
                dV = -2 * V - V**2 / 2 + u
            elif kind == "eq22":
                dV = coupling * innovation * x - 2 * V - V**3 / 2 + u
            else:
                raise ValueError(f"kind {kind!r}; expected 'eq19' or 'eq22'")
            x, V = x + dt * dx, V + dt * dV
            out[:, k] = x
    return out


def kalman(z: np.ndarray, dt: float, x0: float, p0: float, q: float = 1.0,
           r: float = 0.5) -> np.ndarray:
    """The discrete Kalman filter of eqs 13-18 sampled exactly at ``dt``."""
    a = float(np.exp(-dt))
    kf = KalmanFilter(A=[[a]], B=[[0.0]], C=[[0.5]], Q=q * (1 - a * a) / 2, R=r / dt,
                      P0=p0, x0=[x0])
    return kf.run(None, z[..., None], np.zeros((z.shape[1], 1))).x_hat[..., 0]
