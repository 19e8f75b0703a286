"""Extended Kalman filter (thesis Appendix A.2, eqs A.8-A.16), batched over Monte Carlo runs.

The prediction integrates the model over one sample interval with the shared
discretisation (:mod:`estim.discretize`); ``F_k`` is the Jacobian of that step. The thesis
uses forward Euler (eqs 3.18-3.19), available as ``discretization="euler"``.
"""

from __future__ import annotations

import numpy as np
from estim import discretize
from estim.estimators.base import (
    Estimate,
    as_matrix,
    batch_input,
    check_covariance,
    joseph_update,
    run_batch,
)
from estim.schema import REQUIRED, integer, list_of, matrix, number, text


def thesis_to_state(M: np.ndarray, model) -> np.ndarray:
    """A covariance given in the thesis' state units (volts) in the model's own units:
    ``S M S`` with ``S = diag(model.state_scales)``, so a state that is a charge ``q = C v``
    where the thesis has ``v`` gets ``C^2`` times the printed variance."""
    S = np.asarray(model.state_scales, float)
    return S[:, None] * M * S[None, :]


class ExtendedKalmanFilter:
    """EKF with additive process noise ``Q`` and measurement noise ``R`` (L = M = I).

    Parameters
    ----------
    Q, R, P0 : scalar, diagonal list or full matrix.
    x0 : initial estimate; ``None`` takes the ``x0`` given to :meth:`run` (the analyses pass
        the actual circuit's DC operating point), else the model's own operating point.
    discretization : one of :data:`estim.discretize.METHODS`.
    substeps : discretisation substeps per sample interval.
    divergence_bound : a run whose prediction or estimate leaves ``|x| <= bound`` (or becomes
        non-finite) is marked broken and frozen (from that step on its estimates are NaN).
        This only catches numerical breakdown; divergence is judged by
        :func:`estim.health.diverged`.
    noise_units : ``thesis`` (default): ``Q`` and ``P0`` are in the thesis' state units and
        mapped onto the model's states (:meth:`state_covariances`); ``state``: as given.
    """

    SETTINGS = {
        "Q": (matrix, REQUIRED),
        "R": (matrix, REQUIRED),
        "P0": (matrix, REQUIRED),
        "x0": (list_of(number(), max_length=64), None),
        "discretization": (text(discretize.METHODS), None),
        "substeps": (integer(1, 1000), None),
        "divergence_bound": (number(positive=True, maximum=1e12), None),
        "noise_units": (text({"thesis", "state"}), None),
    }

    def __init__(self, Q, R, P0, x0=None, discretization: str = "exponential",
                 substeps: int = 1, divergence_bound: float = 1e3,
                 noise_units: str = "thesis") -> None:
        if discretization not in discretize.METHODS:
            raise ValueError(f"discretization {discretization!r}; expected one of "
                             f"{list(discretize.METHODS)}")
        self.Q, self.R, self.P0, self.x0 = Q, R, P0, x0
        self.discretization = discretization
        self.substeps = int(substeps)
        self.divergence_bound = float(divergence_bound)
        self.noise_units = noise_units

    def validate(self, model) -> None:
        """Raise ``ValueError`` for settings that cannot run with ``model``."""
        n, m = model.n_states, model.n_outputs
        check_covariance(self.Q, n, "Q")
        check_covariance(self.P0, n, "P0")
        check_covariance(self.R, m, "R", definite=True)
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")
        if self.x0 is not None and np.size(self.x0) != n:
            raise ValueError(f"x0: expected {n} values for {list(model.state_names)}")

    def state_covariances(self, model) -> tuple[np.ndarray, np.ndarray]:
        """``Q`` and ``P0`` in the model's own state units (:func:`thesis_to_state`)."""
        n = model.n_states
        Q, P0 = as_matrix(self.Q, n, "Q"), as_matrix(self.P0, n, "P0")
        if self.noise_units == "thesis":
            Q, P0 = thesis_to_state(Q, model), thesis_to_state(P0, model)
        return Q, P0

    def cycle(self, model, x: np.ndarray, P: np.ndarray, z: np.ndarray, u: np.ndarray,
              dt: float, Q: np.ndarray, R: np.ndarray):
        """One prediction and update for the runs given (eqs A.10-A.16): returns the
        prediction ``xp``, the updated ``x`` and ``P``, the innovation covariance ``S`` and
        the innovation. :meth:`run` keeps the batch and its bookkeeping; a filter that
        differs only here (the UKF) overrides this."""
        xp, F = discretize.step(model, x, u, dt, self.discretization, self.substeps)
        Pp = F @ P @ np.swapaxes(F, -1, -2) + Q
        nu = z - model.h(xp)
        xu, Pu, S = joseph_update(xp, Pp, nu, model.h_jacobian(xp), R)
        return xp, xu, Pu, S, nu

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None) -> Estimate:
        runs, _, m = z.shape
        Q, P0 = self.state_covariances(model)
        R = as_matrix(self.R, m, "R")
        if self.x0 is not None:
            x0 = np.asarray(self.x0, float)
        elif x0 is None:
            x0 = model.operating_point()
        x_hat, P_hist, S_hist, innovation, alive = run_batch(
            lambda x, P, zk, uk: self.cycle(model, x, P, zk, uk, dt, Q, R),
            x0, P0, z, batch_input(u, runs), self.divergence_bound)
        with np.errstate(all="ignore"):
            y_hat = model.h(x_hat)
        return Estimate(y_hat=y_hat, innovation=innovation, broken=~alive, x_hat=x_hat,
                        P=P_hist, S=S_hist)
