"""The ensemble Kalman filter with perturbed observations (the stochastic EnKF: Burgers, van
Leeuwen and Evensen 1998; Evensen 2003, eqs 20-27): the Kalman update of
:func:`estim.estimators.base.joseph_update` with the covariances estimated from the members,
each member updated towards its own draw of the measurement so the analysed members keep
the analysed covariance in expectation."""

from __future__ import annotations

import numpy as np

from estim.config.settings import settings_class
from estim.estimators.ensemble import EnsembleFilter, sample_covariance
from estim.estimators.ukf import sqrt_psd
from estim.numerics import linalg


@settings_class
class EnsembleKalmanFilter(EnsembleFilter, name="enkf"):
    """Stochastic EnKF: ``K = P_xy (P_yy + R)^-1`` from the forecast members' sample
    covariances, member ``i`` moved by ``K (z + v_i - h(x_i))`` with ``v_i ~ N(0, R)``."""

    def analyse(self, model, forecast, z, R, rng):
        runs, count, _ = forecast.shape
        predicted = model.h(forecast)                              # (runs, count, m)
        mean_y = predicted.mean(axis=1)
        A = forecast - forecast.mean(axis=1, keepdims=True)
        HA = predicted - mean_y[:, None, :]
        S = np.einsum("rim,rik->rmk", HA, HA) / (count - 1) + R
        Pxy = np.einsum("rin,rim->rnm", A, HA) / (count - 1)
        K = np.swapaxes(linalg.solve(S, np.swapaxes(Pxy, -1, -2)), -1, -2)
        R_root = sqrt_psd(R[None])[0]
        drawn = z[:, None, :] + rng.standard_normal(predicted.shape) @ R_root.T
        members = forecast + (drawn - predicted) @ np.swapaxes(K, -1, -2)
        return members, members.mean(axis=1), sample_covariance(members), S, z - mean_y
