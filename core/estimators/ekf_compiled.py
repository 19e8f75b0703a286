"""The EKF's time loop compiled with numba, one run at a time (thesis Appendix A.2, eqs
A.8-A.16).

The same filter as :meth:`estim.estimators.ekf.ExtendedKalmanFilter.cycle` with
:func:`estim.estimators.base.run_batch`'s bookkeeping, step for step: the prediction by the
shared discretisation (``euler``, ``rosenbrock`` or ``exponential``, eqs 3.18-3.19 and
:mod:`estim.numerics.discretize`), ``P = F P F^T + Q``, the Joseph-form update, and a run
whose estimate or prediction becomes non-finite or leaves ``|x| <= bound`` marked broken
with NaN outputs from that step on. The numpy loop pays a fixed ~0.2 ms of call overhead per
step whatever the batch; here a step of a 4-state circuit is a few microseconds per run.

A model takes this path when it has a compiled drift-and-Jacobian kernel (``kernel()``, the
one the integrator uses) and an affine output (``affine_output()``); otherwise, for the
``radau`` discretisation, and for a filter that overrides ``cycle`` (the UKF, a plugin), the
numpy loop runs. ``tests/test_compiled_filters.py`` checks that both agree to rounding.
"""

from __future__ import annotations

import numpy as np

from estim.estimators import breaks
from estim.estimators.compiled_steps import (
    METHODS,
    history,
    joseph_update,
    keep,
    predict,
    predict_scratch,
    update_scratch,
)
from estim.numerics import kernels
from estim.numerics.kernels import jit, plain
from estim.numerics.small_matrices import copy_matrix, copy_vector, matmul, matmul_t

AVAILABLE = kernels.AVAILABLE


def _runs(kind, Pk, x0, P0, z, u, dt, Q, R, H, c, method, substeps, bound):
    runs, steps, m = z.shape
    n = x0.shape[1]
    out = history(runs, steps, n, m)
    scratch = update_scratch(n, m)
    S, FP = scratch[0], scratch[7]
    x = np.empty(n)
    xp = np.empty(n)
    P = np.empty((n, n))
    nu = np.empty(m)
    steps_scratch = predict_scratch(n)
    F = steps_scratch[0]
    for r in range(runs):
        copy_vector(x0[r], x)
        copy_matrix(P0, P)
        for k in range(steps):
            predict(kind, Pk, x, u[r, k], dt, method, substeps, steps_scratch)
            copy_vector(x, xp)
            matmul(F, P, FP)                          # P = F P F^T + Q
            matmul_t(FP, F, P)
            for a in range(n):
                for b in range(n):
                    P[a, b] += Q[a, b]
            for i in range(m):                        # innovation z - (H x + c)
                acc = c[i]
                for a in range(n):
                    acc += H[i, a] * x[a]
                nu[i] = z[r, k, i] - acc
            ok = joseph_update(x, P, nu, H, R, scratch)
            if not keep(r, k, ok, x, xp, bound, P, S, nu, out):
                break
    return out


runs_compiled = jit(_runs)


def usable(model, discretization: str) -> tuple | None:
    """``(kind, P, H, c)`` where the compiled loop can run ``model`` (module docstring),
    else ``None``."""
    if not AVAILABLE or discretization not in METHODS:
        return None
    make = getattr(model, "kernel", None)
    affine = getattr(model, "affine_output", None)
    kernel = make() if make is not None else None
    output = affine() if affine is not None else None
    if kernel is None or output is None:
        return None
    return kernel[0], kernel[1], output[0], output[1]


def run(plan: tuple, x0: np.ndarray, P0: np.ndarray, z: np.ndarray, u: np.ndarray, dt: float,
        Q: np.ndarray, R: np.ndarray, discretization: str, substeps: int,
        bound: float, why: dict | None = None) -> tuple[np.ndarray, ...]:
    """:func:`estim.estimators.base.run_batch` of the EKF's cycle for ``plan`` (from
    :func:`usable`): ``x_hat``, ``P``, ``S``, the innovations and the runs alive at the end;
    ``why`` is filled as ``run_batch`` fills it."""
    kind, Pk, H, c = plan
    runs, _, n = z.shape[0], z.shape[1], np.shape(x0)[-1]
    X0 = np.broadcast_to(np.asarray(x0, float), (runs, n))
    out = runs_compiled(int(kind), plain(Pk), plain(X0), plain(P0), plain(z), plain(u),
                        float(dt), plain(Q), plain(R), plain(H), plain(c),
                        METHODS[discretization], int(substeps), float(bound))
    if why is not None:
        why.update(breaks.reasons(out[5], out[6], out[7]))
    return out[:5]
