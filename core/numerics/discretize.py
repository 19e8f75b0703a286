"""Discretisation of a continuous model over one sample interval, batched.

One function serves every model and estimator (thesis eqs 3.18-3.19). Each method returns
the state at the end of the interval and the state-transition Jacobian ``F_k``:

``euler``        ``x + T f``, ``F = I + T J`` - the thesis' "Euler-Maruyama" (eqs 3.18, 3.19).
                 Unstable once ``T`` exceeds twice the fastest circuit time constant.
``rosenbrock``   linearly implicit Euler, ``x + T (I - T J)^-1 f``, ``F = (I - T J)^-1``:
                 L-stable, one batched linear solve per substep.
``exponential``  exponential Euler, ``x + T phi_1(T J) f``, ``F = exp(T J)``: exact for
                 linear models (so the EKF equals the KF with ``A = exp(F T)``), stable for
                 any stiffness; one batched ``expm`` of the augmented matrix per substep.
``radau``        the continuous-discrete EKF: the state is carried over the interval by the
                 stiff integrator of :mod:`estim.numerics.simulate` (accurate for strongly nonlinear
                 models, where one linearised step overshoots), ``F = exp(T J(x))`` at the
                 interval's start (the Jacobian ``F_{k-1}`` of Appendix A's EKF). A run
                 the integrator cannot carry becomes NaN.
"""

from __future__ import annotations

import numpy as np

from estim.numerics import linalg
from estim.numerics.simulate import simulate

METHODS = ("euler", "rosenbrock", "exponential", "radau")


def step(model, x: np.ndarray, u: np.ndarray, dt: float, method: str = "exponential",
         substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Advance ``x`` (``(runs, n)``) over one interval of length ``dt`` with input ``u``.

    Returns ``(x_next, F)`` with ``F`` the Jacobian of ``x_next`` w.r.t. ``x`` (chained over
    substeps), shapes ``(runs, n)`` and ``(runs, n, n)``.
    """
    if method not in METHODS:
        raise ValueError(f"unknown discretisation {method!r}; expected one of {list(METHODS)}")
    if method == "radau":
        _, J = model.f_and_jacobian(x, u)
        x_next = simulate(model, x, np.asarray(u, float)[:, None, :], dt, rtol=1e-6, atol=1e-7,
                          on_failure="nan")[:, 0, :]
        return x_next, linalg.expm(dt * J)
    h = dt / substeps
    n = x.shape[-1]
    eye = np.eye(n)
    F_total = None
    for _ in range(substeps):
        fx, J = model.f_and_jacobian(x, u)
        if method == "euler":
            F = eye + h * J
            x = x + h * fx
        elif method == "rosenbrock":
            M = eye - h * J
            sol = linalg.solve(M, np.concatenate([fx[..., None], np.broadcast_to(eye, M.shape)],
                                                    axis=-1))
            x = x + h * sol[..., 0]
            F = sol[..., 1:]
        else:
            aug = np.zeros(x.shape[:-1] + (n + 1, n + 1))
            aug[..., :n, :n] = h * J
            aug[..., :n, n] = h * fx
            with np.errstate(over="ignore", invalid="ignore"):
                E = linalg.expm(aug)
            x = x + E[..., :n, n]
            F = E[..., :n, :n]
        F_total = F if F_total is None else F @ F_total
    return x, F_total
