"""Linear Kalman filter (thesis Appendix A.1, eqs A.1-A.7), batched over Monte Carlo runs."""

from __future__ import annotations

import functools

import numpy as np

from estim.config.settings import REQUIRED, matrix, setting, settings_class
from estim.errors import SettingError
from estim.estimators.base import (
    Estimate,
    NoiseCovariances,
    as_matrix,
    batch_input,
    check_covariance,
    joseph_update,
)
from estim.util import lazy

kf_compiled = lazy.load("estim.estimators.kf_compiled")   # numba: imported when a filter runs


COMPILED_RUNS = 10**9
"""The largest batch the KF steps through in its compiled loop (:meth:`KalmanFilter.compiled`):
measured on 2,000 steps, the compiled loop is 2-60x faster than numpy's at 1-30 runs, even at
300 runs for 2-4 states, and 0.4-0.5x as fast at 300-3,000 runs of one state."""


@settings_class
class KalmanFilter(NoiseCovariances, name="kf"):
    """``x_k = A x_{k-1} + B u_{k-1} + v``, ``z_k = C x_k + w`` with known ``A, B, C, Q, R``.

    The model argument of :meth:`run` is not used: the matrices are the settings. The
    initial estimate is the ``x0`` setting; without it, the ``x0`` given to :meth:`run` (the
    analyses pass the actual operating point, as for the EKF), else zero. The shapes of the
    matrices are checked against each other when the filter is made.
    """

    A: float | list = setting(REQUIRED, matrix, doc="state transition per step (n x n)")
    B: float | list = setting(REQUIRED, matrix, doc="input matrix (n x p)")
    C: float | list = setting(REQUIRED, matrix, doc="measurement matrix (m x n)")

    def __post_init__(self) -> None:
        super().__post_init__()
        self.matrices()

    @classmethod
    def example(cls, model) -> KalmanFilter:
        A, B = model.discrete(0.1)
        return cls(A=A, B=B, C=model.C, Q=0.01, R=0.1, P0=1.0, x0=[0.0] * model.n_states)

    def matrices(self) -> tuple[np.ndarray, ...]:
        """``A, B, C, Q, R, P0`` as arrays; ``ValueError`` naming the setting whose shape does
        not fit the others. Made once per filter (its settings are frozen): a run of one
        Monte Carlo run is otherwise mostly this and :meth:`validate`'s checks."""
        return self._matrices

    @functools.cached_property
    def _matrices(self) -> tuple[np.ndarray, ...]:
        A = np.atleast_2d(np.asarray(self.A, float))
        n = A.shape[0]
        if A.shape != (n, n):
            raise SettingError("A", f"expected a square matrix, got shape {A.shape}")
        B = np.asarray(self.B, float)
        if B.ndim > 2 or (B.size % n and B.size != 0) or (B.ndim == 2 and B.shape[0] != n):
            raise SettingError("B", f"expected {n} rows (one per state), got shape {B.shape}")
        B = B.reshape(n, -1)
        C = np.atleast_2d(np.asarray(self.C, float))
        if C.ndim != 2 or C.shape[1] != n:
            raise SettingError("C", f"expected {n} columns (one per state), got shape {C.shape}")
        if self.x0 is not None and np.size(self.x0) != n:
            raise SettingError("x0", f"expected {n} values, got {np.size(self.x0)}")
        out = tuple(np.array(a) for a in (A, B, C, as_matrix(self.Q, n, "Q"),
                                          as_matrix(self.R, C.shape[0], "R"),
                                          as_matrix(self.P0, n, "P0")))
        for a in out:                             # copies (never the caller's arrays), shared
            a.flags.writeable = False             # by every run of this filter
        return out

    def measured(self, model) -> int | None:
        return self.matrices()[2].shape[0]

    def validate(self, model) -> None:
        """The covariances: finite, symmetric, positive (semi)definite; and, where the
        analysis gives the filter a model, the matrices' sizes against it: the estimate is
        compared with the model's states, fed its inputs and its measurements."""
        A, B, C, Q, R, P0 = self.matrices()
        n = A.shape[0]
        if model is not None:
            sizes = (("A", n, model.n_states, "states"), ("C", C.shape[0], model.n_outputs,
                                                           "measured outputs"))
            for name, got, expected, what in sizes:
                if got != expected:
                    raise SettingError(name, f"{got} rows, but the model {model.name} has "
                                     f"{expected} {what}")
            if B.size and B.shape[1] != model.n_inputs:
                raise SettingError("B", f"{B.shape[1]} columns, but the model {model.name} has "
                                 f"{model.n_inputs} inputs")
        self._covariances_checked  # noqa: B018 - raises for a covariance that is not one

    @functools.cached_property
    def _covariances_checked(self) -> bool:
        """The covariances: finite, symmetric, positive (semi)definite (checked once)."""
        A, _, C, Q, R, P0 = self.matrices()
        check_covariance(Q, A.shape[0], "Q")
        check_covariance(P0, A.shape[0], "P0")
        check_covariance(R, C.shape[0], "R", definite=True)
        return True

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float | None = None,
            x0: np.ndarray | None = None) -> Estimate:
        runs = z.shape[0]
        A, B, C, Q, R, P0 = self.matrices()
        n = A.shape[0]
        u = batch_input(u, runs)
        start = self.x0 if self.x0 is not None else (np.zeros(n) if x0 is None else x0)
        x = np.broadcast_to(np.asarray(start, float), (runs, n)).copy()
        loop = kf_compiled.run if self.compiled() else numpy_loop
        x_hat, P_hist, S_hist, innovation, alive = loop(x, P0, z, u, A, B, C, Q, R)
        with np.errstate(all="ignore"):
            y_hat = x_hat @ C.T
        return Estimate(y_hat=y_hat, innovation=innovation, broken=~alive, x_hat=x_hat,
                        P=P_hist, S=S_hist)

    def compiled(self) -> bool:
        """Whether :meth:`run` steps the batch through time in the compiled loop
        (:mod:`estim.estimators.kf_compiled`; numba installed) or in :func:`numpy_loop`.
        Both compute the covariances once for the batch; the compiled loop steps the means
        of 32 runs side by side, where numpy pays a fixed cost per step whatever the batch
        (``bench/peers.py``)."""
        return kf_compiled.AVAILABLE


def numpy_loop(x, P0, z, u, A, B, C, Q, R) -> tuple[np.ndarray, ...]:
    """The filter over the batch, one numpy step for every run at a time: ``x_hat``, ``P``,
    ``S``, the innovations (NaN from a run's first non-finite estimate on) and the runs
    whose estimate stayed finite. ``x (runs, n)``, ``u (runs, steps, p)``.

    ``P``, ``S`` and the gain do not depend on the measurements (eqs A.2-A.4, A.6-A.7), and
    every run starts from the same ``P0``: they are computed once per step for the whole
    batch (a batch of one, with the same operations as a batch of every run), and only the
    means (eqs A.1, A.5) are stepped run by run."""
    runs, steps, m = z.shape
    n = A.shape[0]
    P = np.asarray(P0, float)[None].copy()
    H = C[None]
    x_hat = np.empty((runs, steps, n))
    P_steps = np.empty((steps, n, n))
    S_steps = np.empty((steps, m, m))
    innovation = np.empty((runs, steps, m))
    with np.errstate(all="ignore"):     # an overflowing run is marked broken below
        for k in range(steps):
            x = x @ A.T + u[:, k, :] @ B.T
            P = A @ P @ A.T + Q
            innovation[:, k] = z[:, k] - x @ C.T
            x, P, S_steps[k] = joseph_update(x, P, innovation[:, k], H, R)
            x_hat[:, k] = x
            P_steps[k] = P[0]
    return shared_histories(x_hat, P_steps, S_steps, innovation)


def shared_histories(x_hat, P_steps, S_steps, innovation,
                     first_bad: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """The outputs of a loop whose covariances ``P_steps (steps, n, n)`` and ``S_steps``
    every run shares: ``P`` and ``S`` as read-only views of them with a leading run axis (no
    copy) while every run stays finite; otherwise each run's own copy, NaN (with its
    estimate and innovations) from the run's first non-finite step on. Then the runs that
    stayed finite. ``first_bad``: each run's first non-finite estimate's step where the
    loop found it (its outputs already NaN from there), else found here."""
    runs, steps = x_hat.shape[:2]
    P_hist = np.broadcast_to(P_steps, (runs, *P_steps.shape))
    S_hist = np.broadcast_to(S_steps, (runs, *S_steps.shape))
    finite_P = np.all(np.isfinite(P_steps), axis=(1, 2))
    if first_bad is None:
        bad = ~(np.all(np.isfinite(x_hat), axis=2) & finite_P)
    else:
        bad = (np.arange(steps) >= first_bad[:, None]) | ~finite_P
    if bad.any():
        bad = np.cumsum(bad, axis=1) > 0
        for a in (x_hat, innovation):
            a[bad] = np.nan
        P_hist, S_hist = P_hist.copy(), S_hist.copy()
        P_hist[bad], S_hist[bad] = np.nan, np.nan
    return x_hat, P_hist, S_hist, innovation, ~bad[:, -1]
