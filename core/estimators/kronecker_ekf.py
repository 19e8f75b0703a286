"""EKF on the Kronecker-product model of a circuit (thesis Sec 4.3, eqs 4.34-4.53, A.12-A.16).

The filter builds the Kronecker form of whatever model it is given
(:func:`estim.numerics.kronecker_form.from_model`, about the model's own DC operating point),
discretises it once per sample time (:func:`estim.numerics.kronecker_form.discretize`) and runs,
batched over Monte Carlo runs,

    A.12  d_k|k-1 = F1 d + F2 (d (x) d) + G w + F5 (d (x) w) + Guu (w (x) w) + c
          F_k    = F1 + F2 (I (x) d + d (x) I) + F5 (I (x) w)      (the full Jacobian;
                                                                     eq 4.38 keeps F1 only)
    A.13  P_k|k-1 = F_k P F_k^T + Q
    A.14  K = P H^T (H P H^T + R)^-1
    A.15  x_k|k = x_k|k-1 + K (z - H x_k|k-1)
    A.16  P_k|k = (I - K H) P (I - K H)^T + K R K^T      (Joseph form, symmetrised)

Its arithmetic goes through :mod:`estim.numerics.opcount`, so Table 4.3's counts are read off this
code path. ``order: 1`` drops the quadratic terms (the filter is then the linear KF on the
discretised linearisation). ``jacobian: printed`` uses ``F1`` alone as eq 4.38 does.
"""

from __future__ import annotations

from dataclasses import field

import numpy as np

from estim.config.settings import integer, setting, settings_class, text
from estim.estimators.base import Estimate, GaussianFilter, as_matrix, batch_input, run_batch
from estim.numerics import kronecker_form as kronecker
from estim.numerics import opcount


@settings_class
class KroneckerEKF(GaussianFilter, name="kronecker_ekf"):
    """EKF on eq 4.36 with additive ``Q`` and ``R`` (``L = M = I``)."""

    discretization: str = setting("exponential", text(kronecker.DISCRETIZATIONS),
                                  doc="discretisation of the Kronecker form (euler: eqs 4.38-4.45)")
    order: int = setting(2, integer(1, 2), doc="1: linear terms only; 2: with x (x) x")
    jacobian: str = setting("full", text({"full", "printed"}),
                            doc="full: F1 + the quadratic terms' derivative; printed: F1 alone "
                                "(eq 4.38)")
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def discrete(self, model, dt: float) -> kronecker.DiscreteKronecker:
        """The discretised Kronecker form of ``model`` for sample time ``dt`` (cached)."""
        key = (id(model), float(dt))
        if key not in self._cache:
            terms = kronecker.from_model(model, model.operating_point())
            if self.order == 1:
                terms = terms.linear_only()
            self._cache[key] = (model, kronecker.discretize(terms, dt, self.discretization))
        return self._cache[key][1]

    def cycle(self, D: kronecker.DiscreteKronecker, H: np.ndarray, x: np.ndarray,
              P: np.ndarray, z: np.ndarray, u: np.ndarray, Q: np.ndarray, R: np.ndarray):
        """One prediction and update (A.12-A.16) for ``x (runs, n)``, ``P (runs, n, n)``;
        returns the prediction, the updated state and covariance, ``S`` and the innovation."""
        t = D.terms
        n, p = t.n, t.p
        mm = opcount.matmul
        d = x - t.x_op
        w = u - t.u_op
        quadratic = self.order == 2
        xp = t.x_op + D.c + mm(D.F1, d[..., None], "A.12")[..., 0]
        xp = xp + mm(D.G, w[..., None], "A.12")[..., 0]
        F = np.broadcast_to(D.F1, P.shape)
        if quadratic:
            dd = opcount.mul(d[:, :, None], d[:, None, :], "A.12").reshape(-1, n * n)
            xp = xp + mm(D.F2, dd[..., None], "A.12")[..., 0]
            if self.jacobian == "full":
                T = D.F2.reshape(n, n, n)
                Tsym = T + T.swapaxes(1, 2)
                F = F + mm(Tsym, d[:, None, :, None], "jacobian")[..., 0]
            if np.any(D.F5):
                dw = opcount.mul(d[:, :, None], w[:, None, :], "A.12").reshape(-1, n * p)
                xp = xp + mm(D.F5, dw[..., None], "A.12")[..., 0]
                if self.jacobian == "full":
                    F = F + mm(D.F5.reshape(n, n, p), w[:, None, :, None], "jacobian")[..., 0]
            if np.any(D.Guu):
                ww = opcount.mul(w[:, :, None], w[:, None, :], "A.12").reshape(-1, p * p)
                xp = xp + mm(D.Guu, ww[..., None], "A.12")[..., 0]
        Ft = np.swapaxes(F, -1, -2)
        Pp = mm(mm(F, P, "A.13"), Ft, "A.13") + Q
        Ht = H.T
        PHt = mm(Pp, Ht, "A.14")
        S = mm(H, PHt, "A.14") + R
        K = np.swapaxes(opcount.solve(S, np.swapaxes(PHt, -1, -2), "A.14"), -1, -2)
        nu = z - mm(H, xp[..., None], "A.15")[..., 0]
        xu = xp + mm(K, nu[..., None], "A.15")[..., 0]
        IKH = np.eye(n) - mm(K, H, "A.16")
        Pu = mm(mm(IKH, Pp, "A.16"), np.swapaxes(IKH, -1, -2), "A.16")
        Pu = Pu + mm(mm(K, R, "A.16"), np.swapaxes(K, -1, -2), "A.16")
        return xp, xu, 0.5 * (Pu + np.swapaxes(Pu, -1, -2)), S, nu

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None) -> Estimate:
        runs, _, m = z.shape
        n = model.n_states
        D = self.discrete(model, dt)
        H = np.asarray(model.h_jacobian(D.terms.x_op), float)
        names = self.state_labels(model)
        Q, P0 = as_matrix(self.Q, n, "Q", names), as_matrix(self.P0, n, "P0", names)
        R = as_matrix(self.R, m, "R")
        if self.x0 is not None:
            x0 = np.asarray(self.x0, float)
        elif x0 is None:
            x0 = D.terms.x_op
        x_hat, P_hist, S_hist, innovation, alive = run_batch(
            lambda x, P, zk, uk: self.cycle(D, H, x, P, zk, uk, Q, R),
            x0, P0, z, batch_input(u, runs), self.divergence_bound)
        with np.errstate(all="ignore"):
            y_hat = x_hat @ H.T
        return Estimate(y_hat=y_hat, innovation=innovation, broken=~alive, x_hat=x_hat,
                        P=P_hist, S=S_hist)
