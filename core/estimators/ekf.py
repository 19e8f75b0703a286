"""Extended Kalman filter (thesis Appendix A.2, eqs A.8-A.16), batched over Monte Carlo runs.

The prediction integrates the model over one sample interval with the shared
discretisation (:mod:`estim.numerics.discretize`); ``F_k`` is the Jacobian of that step. The thesis
uses forward Euler (eqs 3.18-3.19), available as ``discretization="euler"``.
"""

from __future__ import annotations

import numpy as np

from estim.config.settings import integer, setting, settings_class, text
from estim.estimators.base import (
    Estimate,
    GaussianFilter,
    as_matrix,
    batch_input,
    joseph_update,
    run_batch,
)
from estim.numerics import discretize
from estim.util import lazy

ekf_compiled = lazy.load("estim.estimators.ekf_compiled")   # numba: imported when a filter runs


def thesis_to_state(M: np.ndarray, model) -> np.ndarray:
    """A covariance given as the thesis prints it, read in volts (D36), in the model's own
    units: ``S M S`` with ``S = diag(model.state_scales)``, so a state that is a charge
    ``q = C v`` gets ``C^2`` times the printed variance; for a model with a
    full map from the thesis' states (a netlist's ``thesis_states``, D77), ``T M T^T``."""
    T = getattr(model, "thesis_map", None)
    if T is not None:
        out = T @ M @ T.T
        return 0.5 * (out + out.T)
    S = np.asarray(model.state_scales, float)
    return S[:, None] * M * S[None, :]


@settings_class
class ExtendedKalmanFilter(GaussianFilter, name="ekf"):
    """EKF with additive process noise ``Q`` and measurement noise ``R`` (L = M = I); ``Q``
    and ``P0`` in the units ``noise_units`` says."""

    discretization: str = setting("exponential", text(discretize.METHODS),
                                  doc="how the prediction integrates the model over a sample "
                                      "interval (euler: the thesis' eqs 3.18-3.19)")
    substeps: int = setting(1, integer(1, 1000), doc="discretisation substeps per interval")
    noise_units: str = setting("thesis", text({"thesis", "state"}),
                               doc="thesis: Q and P0 as the thesis prints them, read as voltage "
                                   "variances (a charge state's entry as its capacitor's "
                                   "voltage, D36), mapped onto the model's states (S Q S); "
                                   "state: as given, in the model's own units")

    def state_labels(self, model) -> tuple:
        """The states ``Q`` and ``P0`` name: a netlist's ``thesis_states`` where the
        thesis' units map onto them (D77), else the model's states."""
        if self.noise_units == "thesis" and getattr(model, "thesis_map", None) is not None:
            return tuple(model.thesis_states)
        return tuple(model.state_names)

    def state_covariances(self, model) -> tuple[np.ndarray, np.ndarray]:
        """``Q`` and ``P0`` in the model's own state units (:func:`thesis_to_state`)."""
        n, names = model.n_states, self.state_labels(model)
        Q, P0 = as_matrix(self.Q, n, "Q", names), as_matrix(self.P0, n, "P0", names)
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

    def compiled_plan(self, model) -> tuple | None:
        """What the compiled loop (:mod:`estim.estimators.ekf_compiled`) needs to run this
        filter on ``model``, or ``None`` for the numpy loop: always for a filter that
        overrides :meth:`cycle` (the UKF, a plugin), whose steps the compiled loop does not
        know."""
        if type(self).cycle is not ExtendedKalmanFilter.cycle:
            return None
        return ekf_compiled.usable(model, self.discretization)

    def run_compiled(self, plan: tuple, x0, P0, z, u, dt, Q, R,
                     why: dict | None = None) -> tuple[np.ndarray, ...]:
        """The batch through the compiled loop: what :func:`~estim.estimators.base.run_batch`
        returns (and fills ``why`` with) for :meth:`cycle`."""
        return ekf_compiled.run(plan, x0, P0, z, u, dt, Q, R, self.discretization,
                                self.substeps, self.divergence_bound, why)

    def start(self, model, m: int, x0: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """``Q``, ``P0`` (in the model's units), ``R`` for ``m`` measured values, and the
        initial estimate: the ``x0`` setting, else the ``x0`` given, else the model's
        operating point."""
        Q, P0 = self.state_covariances(model)
        if self.x0 is not None:
            x0 = np.asarray(self.x0, float)
        elif x0 is None:
            x0 = model.operating_point()
        return Q, P0, as_matrix(self.R, m, "R"), x0

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None) -> Estimate:
        runs, _, m = z.shape
        Q, P0, R, x0 = self.start(model, m, x0)
        plan = self.compiled_plan(model)
        why: dict = {}
        if plan is not None:
            x_hat, P_hist, S_hist, innovation, alive = self.run_compiled(
                plan, x0, P0, z, batch_input(u, runs), dt, Q, R, why)
        else:
            x_hat, P_hist, S_hist, innovation, alive = run_batch(
                lambda x, P, zk, uk: self.cycle(model, x, P, zk, uk, dt, Q, R),
                x0, P0, z, batch_input(u, runs), self.divergence_bound, why=why)
        with np.errstate(all="ignore"):
            y_hat = model.h(x_hat)
        return Estimate(y_hat=y_hat, innovation=innovation, broken=~alive, x_hat=x_hat,
                        P=P_hist, S=S_hist, diagnostics=why)
