"""The estimator interface and the result every estimator returns.

An estimator is a frozen dataclass whose fields are its settings, each declared once with
its check, default, unit and doc (:mod:`estim.config.settings`); it registers itself by name::

    @settings_class
    class IteratedEKF(ExtendedKalmanFilter, name="iekf"):
        iterations: int = setting(3, integer(1, 50), doc="Gauss-Newton iterations")

``run(model, z, u, dt, x0)`` takes the measurements ``z`` of shape ``(runs, steps, m)`` at
``t_1 .. t_steps`` and the input ``u`` of shape ``(steps, p)`` or ``(runs, steps, p)`` on the
intervals before them, and an optional initial state ``x0`` at ``t_0`` (filters without a
state ignore it), and returns an :class:`Estimate` for the whole batch. ``validate(model)``
raises ``ValueError`` for settings that cannot run with ``model`` (a covariance of the wrong
size); ``example(model)`` gives a working instance for a test model.
"""

from __future__ import annotations

import functools
import inspect
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from estim.config import registry
from estim.config.settings import (
    REQUIRED,
    Settings,
    covariance,
    number,
    setting,
    settings_class,
    vector,
)
from estim.errors import SettingError
from estim.estimators import breaks
from estim.numerics import linalg


class Estimator(Settings):
    """Base of every estimator (see the module docstring)."""

    name: ClassVar[str] = ""

    def __init_subclass__(cls, name: str | None = None, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "run" in cls.__dict__:               # a plugin's run is checked the same way
            cls.run = _checked_run(cls.__dict__["run"])
        if name is not None:
            cls.name = name
            registry.ESTIMATORS.register(name, cls)

    def validate(self, model) -> None:
        """Raise ``ValueError`` (``"setting: why"``) for settings that cannot run with
        ``model``; the settings' own checks ran when the estimator was made."""

    def measured(self, model) -> int | None:
        """How many measured values each step of ``z`` holds for ``model`` (None: any)."""
        return None

    def run(self, model, z: np.ndarray, u: np.ndarray, dt: float,
            x0: np.ndarray | None = None) -> Estimate:
        raise NotImplementedError

    @classmethod
    def example(cls, model) -> Estimator:
        """A working instance for ``model`` (a small linear test model): the conformance test
        runs every registered estimator through it."""
        raise NotImplementedError(f"{cls.__name__} gives no example")


GENERATOR_KEY = 2**32 + 1
"""An estimator that draws random numbers gets its own ``numpy.random.Generator`` from the
work unit's seed: ``spawn_key=(*unit, GENERATOR_KEY, i)`` for the batch's key ``unit`` and
the estimator's place ``i`` in the config, a key space no noise draw reaches."""


def takes_generator(estimator: Estimator) -> bool:
    """Whether ``estimator.run`` takes ``rng`` (an ensemble or particle filter): the analyses
    then pass it a generator of its own (:data:`GENERATOR_KEY`), so its draws repeat with the
    config's seed whatever ``--jobs`` or executor, and filters that take none get none."""
    return "rng" in inspect.signature(type(estimator).run).parameters


def check_inputs(estimator: Estimator, model, z, u, dt, x0) -> tuple[np.ndarray, np.ndarray]:
    """``z`` and ``u`` as float arrays, after the checks every ``run`` gets before any work
    (the settings against ``model``: :meth:`Estimator.validate`; ``z`` of shape ``(runs,
    steps, m)``, ``u`` of ``(steps, p)`` or ``(runs, steps, p)`` with as many steps, ``dt``
    a positive finite number, ``x0`` finite): a :class:`SettingError` naming the argument."""
    estimator.validate(model)
    try:
        z = np.asarray(z, float)
        u = np.asarray(u, float)
    except (TypeError, ValueError):
        raise SettingError("z", "z and u must be arrays of numbers") from None
    if z.ndim != 3 or 0 in z.shape:
        raise SettingError("z", f"expected shape (runs, steps, m), got {z.shape}")
    m = estimator.measured(model)
    if m is not None and z.shape[2] != m:
        raise SettingError("z", f"{z.shape[2]} values per step, but {m} are measured")
    if u.ndim not in (2, 3) or u.shape[-2] != z.shape[1] or (
            u.ndim == 3 and u.shape[0] not in (1, z.shape[0])):
        raise SettingError("u", f"expected shape ({z.shape[1]}, p) or ({z.shape[0]}, "
                           f"{z.shape[1]}, p) for z of shape {z.shape}, got {u.shape}")
    n_inputs = getattr(model, "n_inputs", None)
    if isinstance(n_inputs, int) and u.shape[-1] != n_inputs and u.shape[-1] != 0:
        raise SettingError("u", f"{u.shape[-1]} inputs per step, but the model has {n_inputs}")
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(u))):
        raise SettingError("z", "z and u must be finite")
    if dt is not None and (isinstance(dt, bool) or not isinstance(dt, (int, float, np.number))
                           or not math.isfinite(dt) or not dt > 0):
        raise SettingError("dt", f"expected a positive finite number, got {dt!r}")
    if x0 is not None and not np.all(np.isfinite(np.asarray(x0, float))):
        raise SettingError("x0", "must be finite")
    return z, u


def _checked_run(run):
    """``run`` with :func:`check_inputs` first."""
    @functools.wraps(run)
    def checked(self, model, z, u, dt=None, x0=None, **kwargs):
        z, u = check_inputs(self, model, z, u, dt, x0)
        return run(self, model, z, u, dt, x0, **kwargs)
    return checked


@settings_class
class NoiseCovariances(Estimator):
    """The settings every Kalman-type filter shares (not registered itself): additive noise
    covariances and the initial estimate."""

    Q: float | list | dict = setting(REQUIRED, covariance(by_name=True), unit="state^2",
                                     doc="process noise covariance per step: a number, a "
                                         "diagonal, a matrix, or {state name: variance} "
                                         "('*': the states not named)")
    R: float | list = setting(REQUIRED, covariance(definite=True), unit="output^2",
                     doc="measurement noise covariance: a number, a diagonal or a matrix")
    P0: float | list | dict = setting(REQUIRED, covariance(by_name=True), unit="state^2",
                                      doc="covariance of the initial estimate (as Q)")
    x0: list | None = setting(None, vector(), unit="state",
                              doc="initial estimate; none: the x0 the analysis passes (the "
                                  "actual operating point), else the model's own (a KF: 0)")


@settings_class
class GaussianFilter(NoiseCovariances):
    """A Kalman-type filter of a model (not registered itself): the noise covariances and
    the bound that marks a broken run."""

    divergence_bound: float = setting(1e3, number(positive=True, maximum=1e12), unit="state",
                                      doc="a run whose estimate leaves |x| <= bound (or is not "
                                          "finite) is broken and frozen")

    @classmethod
    def example(cls, model) -> GaussianFilter:
        return cls(Q=0.01, R=0.1, P0=1.0, x0=[0.0] * model.n_states)

    def measured(self, model) -> int | None:
        return model.n_outputs

    def state_labels(self, model) -> tuple:
        """The names of the states whose variances ``Q`` and ``P0`` give, in their order
        (the model's states)."""
        return tuple(model.state_names)

    def validate(self, model) -> None:
        """The covariances and ``x0`` against the model's size."""
        n, m = model.n_states, model.n_outputs
        check_covariance(self.Q, n, "Q", states=self.state_labels(model))
        check_covariance(self.P0, n, "P0", states=self.state_labels(model))
        check_covariance(self.R, m, "R", definite=True)
        if self.x0 is not None and np.size(self.x0) != n:
            raise SettingError("x0", f"expected {n} values for {list(model.state_names)}")


@dataclass(frozen=True)
class Estimate:
    """Filter output over a Monte Carlo batch.

    Attributes
    ----------
    y_hat : ``(runs, steps, m)`` posterior estimate of the measured output.
    innovation : ``(runs, steps, m)`` prior residual ``z_k - y_hat_{k|k-1}`` (eq 3.84).
    broken : ``(runs,)`` runs the filter could not carry on: the estimate became non-finite
        or left the filter's numerical bound. From that step on the run's outputs are NaN.
        Divergence in the statistical sense is judged from the outputs by
        :func:`estim.experiments.shared.health.diverged`, not here.
    x_hat : ``(runs, steps, n)`` posterior state estimate, or ``None`` for output-only filters.
    P : ``(runs, steps, n, n)`` posterior state covariance, or ``None``.
    S : ``(runs, steps, m, m)`` innovation covariance the filter assumed, or ``None`` for a
        filter with no noise model (RLS). A filter whose covariances do not depend on the
        data (the KF) may give ``P`` and ``S`` as read-only views of one copy shared by the
        runs.
    diagnostics : per-run extras, name -> ``(runs,)`` (RLS: regressor excitation).
    """

    y_hat: np.ndarray
    innovation: np.ndarray
    broken: np.ndarray
    x_hat: np.ndarray | None = None
    P: np.ndarray | None = None
    S: np.ndarray | None = None
    diagnostics: dict = field(default_factory=dict)

    @property
    def P_diag(self) -> np.ndarray | None:
        """``(runs, steps, n)`` diagonal of the posterior covariance, or ``None``."""
        return None if self.P is None else np.diagonal(self.P, axis1=-2, axis2=-1)


def run_batch(cycle, x0: np.ndarray, P0: np.ndarray, z: np.ndarray, u: np.ndarray,
              bound: float, carry: np.ndarray | None = None,
              why: dict | None = None) -> tuple[np.ndarray, ...]:
    """The batch bookkeeping every state filter shares: ``cycle(x, P, z_k, u_k)`` (one
    prediction and update for the runs still alive, returning the prediction, the updated
    state and covariance, ``S`` and the innovation) is applied step by step; a run whose
    estimate or prediction becomes non-finite or leaves ``|x| <= bound`` is marked broken
    and frozen, its outputs NaN from that step on. Returns ``x_hat``, ``P``, ``S``, the
    innovations and the runs still alive at the end.

    ``carry``: what an ensemble or particle filter carries from step to step beside its
    estimate (its members, ``(runs, members, n)``); ``cycle`` is then called with the alive
    runs' part of it last and returns the new part last, kept for the runs that go on.
    ``why``: a dict filled with each run's break (:func:`estim.estimators.breaks.reasons`)."""
    runs, steps, m = z.shape
    n = np.shape(x0)[-1]
    x = np.broadcast_to(x0, (runs, n)).copy()
    P = np.broadcast_to(P0, (runs, n, n)).copy()
    x_hat = np.full((runs, steps, n), np.nan)
    P_hist = np.full((runs, steps, n, n), np.nan)
    S_hist = np.full((runs, steps, m, m), np.nan)
    innovation = np.full((runs, steps, m), np.nan)
    alive = np.ones(runs, bool)
    cause, state, step = np.zeros(runs, int), np.full(runs, -1), np.full(runs, -1)
    for k in range(steps):
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        with np.errstate(all="ignore"):
            if carry is None:
                xp, xu, Pu, S, nu = cycle(x[idx], P[idx], z[idx, k], u[idx, k])
            else:
                xp, xu, Pu, S, nu, carried = cycle(x[idx], P[idx], z[idx, k], u[idx, k],
                                                   carry[idx])
        ok = (np.all(np.isfinite(xu), axis=1) & np.all(np.isfinite(Pu), axis=(1, 2))
              & np.all(np.abs(xu) <= bound, axis=1) & np.all(np.abs(xp) <= bound, axis=1))
        alive[idx[~ok]] = False
        for i in np.flatnonzero(~ok):
            cause[idx[i]], state[idx[i]] = breaks.cause_of(xp[i], xu[i], Pu[i], bound)
            step[idx[i]] = k
        keep = idx[ok]
        x[keep], P[keep] = xu[ok], Pu[ok]
        if carry is not None:
            carry[keep] = carried[ok]
        x_hat[keep, k] = xu[ok]
        P_hist[keep, k] = Pu[ok]
        S_hist[keep, k] = S[ok]
        innovation[keep, k] = nu[ok]
    if why is not None:
        why.update(breaks.reasons(cause, state, step))
    return x_hat, P_hist, S_hist, innovation, alive


def batch_input(u: np.ndarray, runs: int) -> np.ndarray:
    """Broadcast an input of shape ``(steps, p)`` or ``(runs, steps, p)`` to the batch."""
    u = np.asarray(u, float)
    if u.ndim == 2:
        u = u[None]
    return np.broadcast_to(u, (runs,) + u.shape[1:])


def as_matrix(value, n: int, name: str, states: tuple | None = None) -> np.ndarray:
    """A covariance given as a scalar, a diagonal list, a full matrix or, where the filter's
    model names its ``states``, ``{state name: variance}`` (``"*"``: every state not named)
    -> ``(n, n)``; :class:`SettingError` naming what does not fit."""
    if isinstance(value, dict):
        return _by_name(value, n, name, states)
    a = np.asarray(value, float)
    if a.ndim == 0:
        return a * np.eye(n)
    if a.ndim == 1 and a.size == n:
        return np.diag(a)
    if a.shape == (n, n):
        return a
    raise SettingError(name, f"expected a scalar, {n} diagonal entries or an {n}x{n} matrix")


def _by_name(value: dict, n: int, name: str, states: tuple | None) -> np.ndarray:
    """The diagonal covariance of ``{state name: variance}`` over ``states``."""
    if states is None:
        raise SettingError(name, "given by state name, but this filter has no model whose "
                                 "states name its rows: give a number, a list or a matrix")
    unknown = [k for k in value if k != "*" and k not in states]
    if unknown:
        raise SettingError(name, f"no state named {', '.join(map(repr, unknown))}; the "
                                 f"states are {', '.join(states)} ('estim settings CONFIG' "
                                 "lists them)")
    missing = [s for s in states if s not in value]
    if missing and "*" not in value:
        raise SettingError(name, f"no variance for {', '.join(missing)}: name every state "
                                 "or give '*' for the rest")
    return np.diag([float(value.get(s, value.get("*"))) for s in states])


def check_covariance(value, n: int, name: str, definite: bool = False,
                     states: tuple | None = None) -> np.ndarray:
    """``value`` as an ``(n, n)`` covariance (by state name over ``states``, as
    :func:`as_matrix`); ``ValueError`` unless finite, symmetric and positive semidefinite
    (positive definite with ``definite``)."""
    M = as_matrix(value, n, name, states)
    if not np.all(np.isfinite(M)):
        raise SettingError(name, "entries must be finite")
    if not np.allclose(M, M.T, rtol=1e-12, atol=0.0):
        raise SettingError(name, "not symmetric")
    lowest = float(np.linalg.eigvalsh(M)[0])
    scale = float(np.max(np.abs(M), initial=0.0))
    if lowest < -1e-12 * scale or (definite and not lowest > 0):
        kind = "positive definite" if definite else "positive semidefinite"
        raise SettingError(name, f"not {kind} (smallest eigenvalue {lowest:.3g})")
    return M


def joseph_update(x: np.ndarray, P: np.ndarray, innovation: np.ndarray, H: np.ndarray,
                  R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurement update (eqs A.5-A.7, A.14-A.16) in Joseph form, batched.

    ``x (runs, n)``, ``P (runs, n, n)``, ``innovation (runs, m)``, ``H (runs, m, n)``,
    ``R (m, m)``. The covariance is ``(I-KH) P (I-KH)^T + K R K^T``, symmetrised. Returns
    the updated state and covariance and the innovation covariance ``S = H P H^T + R``.
    """
    Ht = np.swapaxes(H, -1, -2)
    S = H @ P @ Ht + R
    K = np.swapaxes(linalg.solve(S, H @ P), -1, -2)
    x = x + (K @ innovation[..., None])[..., 0]
    IKH = np.eye(P.shape[-1]) - K @ H
    P = IKH @ P @ np.swapaxes(IKH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return x, 0.5 * (P + np.swapaxes(P, -1, -2)), S
