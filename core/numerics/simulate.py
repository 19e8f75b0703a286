"""The "actual" signal: the nonlinear circuit integrated with a stiff solver (PSPICE's role).

The input is piecewise constant on each sample interval (``model.source_to_input``), so the
trajectory is integrated interval by interval. scipy's ``solve_ivp`` cannot advance a batch
of independent Monte Carlo runs at once, and on these circuits it needs hundreds of
function evaluations per interval; so the runs are advanced together with the 3-stage
Radau IIA collocation method (order 5, L-stable, the method behind ``solve_ivp``'s
``Radau``) solving the stage equations with full Newton iterations. Each run's step size is
controlled on its own by the method's embedded error estimate, while all runs advance
together in one vectorised loop. ``tests/test_mosfet.py`` checks the result against
``solve_ivp`` at tight tolerance.
"""

from __future__ import annotations

import numpy as np

from estim.errors import SimulationError
from estim.numerics import linalg, radau
from estim.util import lazy

integrate = lazy.load("scipy.integrate")
compiled = lazy.load("estim.numerics.radau_compiled")

RADAU_A, _MU, _E = radau.A, radau.MU, radau.E


def _radau_step(model, x: np.ndarray, u: np.ndarray, h: np.ndarray, newton_tol: float,
                max_newton: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One Radau IIA step of per-run size ``h (runs,)``.

    Returns the new states, a per-run success flag and the embedded error estimate.
    """
    runs, n = x.shape
    Z = np.zeros((runs, 3, n))
    eye = np.eye(3 * n)
    ha = h[:, None, None] * RADAU_A
    uu = u[:, None, :]
    f0, J0 = model.f_and_jacobian(x, u)
    done = np.zeros(runs, bool)
    active = np.ones(runs, bool)
    for _ in range(max_newton):
        idx = np.flatnonzero(active)
        X = x[idx, None, :] + Z[idx]
        with np.errstate(all="ignore"):
            F, J = model.f_and_jacobian(X, uu[idx])
            G = Z[idx] - np.einsum("rij,rjn->rin", ha[idx], F)
            M = eye - np.einsum("rij,rjab->riajb", ha[idx], J).reshape(idx.size, 3 * n, 3 * n)
            finite = np.all(np.isfinite(M), axis=(1, 2)) & np.all(np.isfinite(G), axis=(1, 2))
            dZ = np.full((idx.size, 3, n), np.nan)
            if finite.any():
                dZ[finite] = linalg.solve(
                    M[finite], -G[finite].reshape(-1, 3 * n, 1)).reshape(-1, 3, n)
        finite &= np.all(np.isfinite(dZ), axis=(1, 2))
        Z[idx[finite]] += dZ[finite]
        size = np.max(np.abs(dZ), axis=(1, 2))
        scale = 1.0 + np.max(np.abs(Z[idx]), axis=(1, 2))
        ok = finite & (size <= newton_tol * scale)
        done[idx[ok]] = True
        active[idx[ok | ~finite]] = False
        if not active.any():
            break
    with np.errstate(all="ignore"):
        ZE = np.einsum("j,rjn->rn", _E, Z) / h[:, None]
        L = (_MU / h)[:, None, None] * np.eye(n) - J0
        error = linalg.solve(L, (f0 + ZE)[..., None])[..., 0]
    return x + Z[:, 2, :], done & np.all(np.isfinite(error), axis=1), error


def simulate(model, x0: np.ndarray, u: np.ndarray, dt: float, rtol: float = 1e-6,
             atol: float = 1e-7, newton_tol: float = 1e-12, max_newton: int = 20,
             max_iterations: int = 1_000_000, on_failure: str = "raise",
             engine: str = "auto") -> np.ndarray:
    """Integrate ``model`` from ``x0`` over ``steps`` intervals of length ``dt``.

    Each run has its own step size: a step is accepted when the RMS over states of the
    embedded error estimate, scaled by ``atol + rtol |x|``, is at most one, and the next
    step follows the usual ``err^(-1/4)`` rule. Step sizes carry over between intervals (a
    step shortened to land on a sample time does not shrink the next one).

    Parameters
    ----------
    x0 : ``(n,)`` or ``(runs, n)`` initial state at ``t_0``.
    u : ``(runs, steps, p)`` input, constant on each interval ``[t_k, t_{k+1})``.
    on_failure : ``"raise"`` a :class:`SimulationError` when a run's step size underflows,
        or ``"nan"``: that run's states become NaN from there on and the others go on.
    engine : ``"compiled"`` (:mod:`estim.numerics.radau_compiled`, the same algorithm compiled with
    numba;
        needs numba and a model with a ``kernel``), ``"numpy"``, or ``"auto"``: compiled
        where it can be.

    Returns
    -------
    ``(runs, steps, n)`` states at ``t_1 .. t_steps``.
    """
    if on_failure not in ("raise", "nan"):
        raise ValueError(f"on_failure {on_failure!r}; expected 'raise' or 'nan'")
    u = np.asarray(u, float)
    runs, steps, _ = u.shape
    x = np.broadcast_to(np.asarray(x0, float), (runs, model.n_states)).copy()
    make = getattr(model, "kernel", None)
    kernel = make() if make is not None and engine != "numpy" and compiled.AVAILABLE else None
    if engine == "compiled" and kernel is None:
        raise ValueError(f"{model.name}: no compiled kernel (or numba is not installed)")
    if kernel is not None:
        out, status, r, k = compiled.integrate(kernel[0], kernel[1], x, u, dt, rtol, atol,
                                               newton_tol, max_newton, max_iterations,
                                               on_failure == "nan")
        if status == compiled.STEP_UNDERFLOW:
            raise SimulationError(f"{model.name}: step size underflow on interval {k} "
                                  f"(run {r})")
        if status == compiled.TOO_MANY_STEPS:
            raise SimulationError(f"{model.name}: more than {max_iterations} steps (run {r})")
        return out
    out = np.empty((runs, steps, model.n_states))
    h = np.full(runs, dt / 4)
    iterations = 0
    for k in range(steps):
        uk = u[:, k, :]
        t = np.where(np.all(np.isfinite(x), axis=1), 0.0, dt)
        while True:
            idx = np.flatnonzero(t < dt * (1 - 1e-12))
            if idx.size == 0:
                break
            iterations += 1
            if iterations > max_iterations:
                raise SimulationError(f"{model.name}: more than {max_iterations} steps")
            hh = np.minimum(h[idx], dt - t[idx])
            xi = x[idx]
            new, ok, error = _radau_step(model, xi, uk[idx], hh, newton_tol, max_newton)
            with np.errstate(all="ignore"):
                scale = atol + rtol * np.maximum(np.abs(xi), np.abs(new))
                err = np.sqrt(np.mean((error / scale) ** 2, axis=1))
            ok &= np.isfinite(err)
            accept = ok & (err <= 1.0)
            x[idx[accept]] = new[accept]
            t[idx[accept]] += hh[accept]
            with np.errstate(divide="ignore"):
                factor = np.where(ok, np.clip(0.9 * np.maximum(err, 1e-10) ** (-0.25), 0.2, 10.0),
                                  0.5)
            proposal = hh * factor
            clipped = accept & (hh < h[idx])
            h[idx] = np.minimum(np.where(clipped, np.maximum(proposal, h[idx]), proposal), dt)
            failed = idx[~(h[idx] >= dt * 1e-14)]
            if failed.size:
                if on_failure == "raise":
                    raise SimulationError(f"{model.name}: step size underflow on interval {k}")
                x[failed], t[failed], h[failed] = np.nan, dt, dt / 4
        out[:, k, :] = x
    return out


def simulate_scipy(model, x0: np.ndarray, u: np.ndarray, dt: float, rtol: float = 1e-6,
                   atol: float = 1e-7, method: str = "Radau") -> np.ndarray:
    """The same integration with scipy's ``solve_ivp``, one run and one interval at a time.

    Slow (a Python loop over runs, hundreds of function evaluations per interval on the
    circuits here), but independent of :func:`simulate`: the reference it is tested against,
    and the config's ``simulation.solver: scipy``.
    """
    u = np.asarray(u, float)
    runs, steps, _ = u.shape
    x0 = np.broadcast_to(np.asarray(x0, float), (runs, model.n_states))
    out = np.empty((runs, steps, model.n_states))
    for r in range(runs):
        y = x0[r]
        for k in range(steps):
            uk = u[r, k]
            sol = integrate.solve_ivp(lambda _t, x, uk=uk: model.f(x, uk), (0.0, dt), y,
                                      method=method, rtol=rtol, atol=atol,
                                      jac=lambda _t, x, uk=uk: model.jacobian(x, uk))
            if not sol.success:
                raise SimulationError(f"{model.name}: solve_ivp failed on run {r}, interval "
                                      f"{k}: {sol.message}")
            y = sol.y[:, -1]
            out[r, k] = y
    return out


SOLVERS = {"batched_radau": simulate, "scipy": simulate_scipy}
