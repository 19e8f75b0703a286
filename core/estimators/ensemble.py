"""What the ensemble and particle filters share (not registered itself): the members drawn
around the initial estimate, each member moved through the model's discretised step with
its own process noise, and the batch bookkeeping of :func:`estim.estimators.base.run_batch`
(broken runs frozen, their outputs NaN), which carries the members from step to step.

A filter of this kind is one module: a subclass of :class:`EnsembleFilter` that says how its
members meet a measurement (:meth:`EnsembleFilter.analyse`); :mod:`estim.estimators.enkf`
and :mod:`estim.estimators.bootstrap_pf` are the two shipped. Its random numbers come from
the ``rng`` its ``run`` takes (the analyses pass each estimator a generator of its own from
the work unit's seed, :data:`estim.estimators.base.GENERATOR_KEY`).
"""

from __future__ import annotations

import numpy as np

from estim.config.settings import integer, setting, settings_class
from estim.estimators.base import Estimate, batch_input, run_batch
from estim.estimators.ekf import ExtendedKalmanFilter
from estim.estimators.ukf import sqrt_psd
from estim.numerics import discretize


@settings_class
class EnsembleFilter(ExtendedKalmanFilter):
    """A filter of members moved through the model (not registered itself): the EKF's
    settings (``Q``, ``R``, ``P0``, their units, the discretisation, the bound of a broken
    run) and the number of members."""

    members: int = setting(100, integer(2, 100_000), doc="members of the ensemble (particles)")

    def analyse(self, model, forecast: np.ndarray, z: np.ndarray, R: np.ndarray,
                rng: np.random.Generator) -> tuple[np.ndarray, ...]:
        """The members after the measurement ``z (runs, m)``, from the ``forecast (runs,
        members, n)``: returns the new members, the updated estimate and covariance, the
        innovation covariance ``S`` and the innovation."""
        raise NotImplementedError

    def propagate(self, model, members: np.ndarray, u: np.ndarray, dt: float,
                  Q_root: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Each member through one interval of the model (the EKF's discretisation) plus
        its own process noise ``N(0, Q)``: ``(runs, members, n)``."""
        runs, count, n = members.shape
        flat = members.reshape(runs * count, n)
        moved, _ = discretize.step(model, flat, np.repeat(u, count, axis=0), dt,
                                   self.discretization, self.substeps)
        return moved.reshape(runs, count, n) + rng.standard_normal((runs, count, n)) @ Q_root.T

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None, rng: np.random.Generator | None = None) -> Estimate:
        """The batch; ``rng``: the generator of every draw (none given: a fixed seed, 0)."""
        rng = np.random.default_rng(0) if rng is None else rng
        runs, _, m = z.shape
        Q, P0, R, x0 = self.start(model, m, x0)
        n = model.n_states
        start = np.broadcast_to(np.asarray(x0, float), (runs, n))
        Q_root, P0_root = sqrt_psd(np.stack([Q, P0]))
        members = start[:, None, :] + rng.standard_normal((runs, self.members, n)) @ P0_root.T

        def cycle(x, P, zk, uk, carried):
            forecast = self.propagate(model, carried, uk, dt, Q_root, rng)
            new, xu, Pu, S, nu = self.analyse(model, forecast, zk, R, rng)
            return forecast.mean(axis=1), xu, Pu, S, nu, new

        x_hat, P_hist, S_hist, innovation, alive = run_batch(
            cycle, start, P0, z, batch_input(u, runs), self.divergence_bound, carry=members)
        with np.errstate(all="ignore"):
            y_hat = model.h(x_hat)
        return Estimate(y_hat=y_hat, innovation=innovation, broken=~alive, x_hat=x_hat,
                        P=P_hist, S=S_hist)


def sample_covariance(members: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """The covariance of ``members (runs, count, n)`` about their (weighted) mean: unbiased
    ``/ (count - 1)`` without ``weights``, else ``sum_i w_i d_i d_i^T``."""
    if weights is None:
        d = members - members.mean(axis=1, keepdims=True)
        return np.einsum("rik,ril->rkl", d, d) / (members.shape[1] - 1)
    d = members - np.einsum("ri,rik->rk", weights, members)[:, None, :]
    return np.einsum("ri,rik,ril->rkl", weights, d, d)
