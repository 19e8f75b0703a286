"""Unscented Kalman filter, batched over Monte Carlo runs (not in the thesis; issue 11).

Julier and Uhlmann's unscented transform with the scaled sigma points of van der Merwe
(2004): ``2n + 1`` points ``x``, ``x +- sqrt((n + lambda) P)`` columns, ``lambda = alpha^2
(n + kappa) - n``, mean weights ``lambda/(n+lambda)`` and ``1/(2(n+lambda))``, covariance
weight of the centre ``lambda/(n+lambda) + 1 - alpha^2 + beta``.

Per step, for every run at once:

* prediction: each sigma point is carried over the sample interval by the same
  discretisation as the EKF (:mod:`estim.numerics.discretize`), its Jacobian unused; the predicted
  mean and covariance are the weighted sample moments plus ``Q`` (additive noise, as in the
  EKF of Appendix A.2);
* update: sigma points are redrawn from the prediction and passed through ``h``; ``S`` and
  the cross covariance ``P_xz`` are their weighted moments, ``K = P_xz S^-1``. The covariance
  is updated in Joseph form with the statistically linearised ``H = P_xz^T P^-1`` (which is
  the model's ``C`` for a linear model, so the filter is then exactly the KF).

Settings are the EKF's (``Q`` and ``P0`` by default as the thesis prints them, read as voltage
variances: D36) plus ``alpha``, ``beta`` and ``kappa``.
"""

from __future__ import annotations

import numpy as np

from estim.config.settings import number, setting, settings_class
from estim.estimators.base import joseph_update
from estim.estimators.ekf import ExtendedKalmanFilter, ekf_compiled
from estim.numerics import discretize, linalg
from estim.util import lazy

ukf_compiled = lazy.load("estim.estimators.ukf_compiled")   # numba: imported when a filter runs


def sqrt_psd(P: np.ndarray) -> np.ndarray:
    """Lower square roots ``L L^T = P`` of a stack of covariances: Cholesky, and where it
    fails (a semidefinite ``P``) the symmetric root of ``P`` with negative eigenvalues
    (rounding) set to zero. Non-finite ``P`` gives NaN."""
    out = np.full(P.shape, np.nan)
    finite = np.all(np.isfinite(P), axis=(-2, -1))
    try:
        out[finite] = np.linalg.cholesky(P[finite])
        return out
    except np.linalg.LinAlgError:
        pass
    for i in np.flatnonzero(finite):
        try:
            out[i] = np.linalg.cholesky(P[i])
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(P[i])
            out[i] = V * np.sqrt(np.clip(w, 0.0, None))
    return out


@settings_class
class UnscentedKalmanFilter(ExtendedKalmanFilter, name="ukf"):
    """UKF with additive ``Q`` and ``R``; see the module docstring. Settings: the EKF's and
    the sigma points' scaling."""

    alpha: float = setting(1e-3, number(positive=True, maximum=10.0),
                           doc="spread of the sigma points: about alpha sqrt(n P) from the "
                               "estimate (1e-3, Wan and van der Merwe's choice, keeps them "
                               "where a junction's exponential stays in range; 1 is the "
                               "unscaled transform, D39)")
    beta: float = setting(2.0, number(minimum=0.0, maximum=100.0),
                          doc="prior knowledge of the distribution (2: Gaussian)")
    kappa: float = setting(0.0, number(minimum=-100.0, maximum=100.0),
                           doc="secondary scaling of the sigma points")

    def validate(self, model) -> None:
        super().validate(model)
        if not model.n_states + self.scaling(model.n_states) > 0:
            raise ValueError(f"alpha^2 (n + kappa) must be positive (n = {model.n_states})")

    def scaling(self, n: int) -> float:
        """``lambda = alpha^2 (n + kappa) - n``."""
        return self.alpha**2 * (n + self.kappa) - n

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance weights of the ``2n + 1`` sigma points."""
        lam = self.scaling(n)
        wm = np.full(2 * n + 1, 0.5 / (n + lam))
        wm[0] = lam / (n + lam)
        wc = wm.copy()
        wc[0] += 1.0 - self.alpha**2 + self.beta
        return wm, wc

    def sigma_points(self, x: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``(runs, 2n+1, n)`` sigma points of means ``x (runs, n)`` and covariances ``P``."""
        n = x.shape[-1]
        L = np.sqrt(n + self.scaling(n)) * sqrt_psd(P)
        cols = np.swapaxes(L, -1, -2)
        return np.concatenate([x[:, None, :], x[:, None, :] + cols, x[:, None, :] - cols],
                              axis=1)

    def compiled_plan(self, model) -> tuple | None:
        """As the EKF's: the compiled loop (:mod:`estim.estimators.ukf_compiled`) where the
        model has a kernel and an affine output and the discretisation is not ``radau``;
        ``None`` (the numpy loop) for a subclass that overrides :meth:`cycle`."""
        if type(self).cycle is not UnscentedKalmanFilter.cycle:
            return None
        return ekf_compiled.usable(model, self.discretization)

    def run_compiled(self, plan: tuple, x0, P0, z, u, dt, Q, R,
                     why: dict | None = None) -> tuple[np.ndarray, ...]:
        n = np.shape(x0)[-1]
        return ukf_compiled.run(plan, x0, P0, z, u, dt, Q, R,
                                self.discretization, self.substeps,
                                self.divergence_bound, self.weights(n),
                                np.sqrt(n + self.scaling(n)), why)

    def cycle(self, model, x: np.ndarray, P: np.ndarray, z: np.ndarray, u: np.ndarray,
              dt: float, Q: np.ndarray, R: np.ndarray):
        """Unscented prediction and update (module docstring); the batch bookkeeping is the
        EKF's :meth:`~estim.estimators.ekf.ExtendedKalmanFilter.run`."""
        runs, n = x.shape
        wm, wc = self.weights(n)
        points = 2 * n + 1
        X = self.sigma_points(x, P)
        Xp, _ = discretize.step(model, X.reshape(-1, n), np.repeat(u, points, axis=0), dt,
                                self.discretization, self.substeps)
        Xp = Xp.reshape(runs, points, n)
        xp = np.einsum("i,rin->rn", wm, Xp)
        D = Xp - xp[:, None, :]
        Pp = np.einsum("i,rin,rim->rnm", wc, D, D) + Q
        Pp = 0.5 * (Pp + np.swapaxes(Pp, -1, -2))
        X = self.sigma_points(xp, Pp)
        Z = model.h(X)
        zp = np.einsum("i,rim->rm", wm, Z)
        Pxz = np.einsum("i,rin,rim->rnm", wc, X - xp[:, None, :], Z - zp[:, None, :])
        H = np.swapaxes(linalg.solve(Pp, Pxz), -1, -2)
        nu = z - zp
        xu, Pu, S = joseph_update(xp, Pp, nu, H, R)
        return xp, xu, Pu, S, nu
