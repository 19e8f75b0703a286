"""First-order perturbation (Volterra-like) analysis of a nonlinear circuit (thesis Chapter 2).

About a DC operating point ``(x*, u*)`` write the circuit as its linear part plus
``epsilon`` times its quadratic part (eqs 2.8-2.10, 2.52-2.55, 2.94-2.97, 2.143),

    dx/dt = A dx + B du + epsilon q(dx, du),     q(z) = 1/2 H[z, z],  z = [dx, du],

with ``A = df/dx``, ``B = df/du`` and ``H`` the second derivatives of ``f`` at the operating
point (``Model.hessian``). Expanding ``dx = x0 + epsilon x1`` and equating powers of
``epsilon`` gives the two linear systems the thesis solves by Laplace transform and
cofactors (eqs 2.27, 2.34-2.41, 2.68-2.85, 2.116-2.136, 2.156-2.174):

    x0' = A x0 + B du(t)                 (zeroth order, driven by the input)
    x1' = A x1 + q(x0, du(t))            (first order, driven by the quadratic terms on x0)

Here both are integrated together in the time domain, for any model, with the same stiff
integrator and the same piecewise-constant input as the full nonlinear circuit; nothing is
transcribed from the thesis' coefficient expressions. The outputs are ``y0 = C x0`` and
``y1 = C x1`` with ``C = dh/dx`` (models here have linear outputs).

For a periodic input the analysis is done on the periodic steady state of all three
systems (x0, x1 and the full circuit), found by shooting over one period: for the linear
systems exactly, ``x(0) = (I - e^{AT})^-1 x_T`` with ``x_T`` the state reached from rest;
for the full circuit by quasi-Newton iterations with the same matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estim.errors import SimulationError
from estim.numerics.simulate import SOLVERS
from estim.util import lazy

linalg = lazy.load("scipy.linalg")
kernels = lazy.load("estim.numerics.kernels")


@dataclass(frozen=True)
class Expansion:
    """Linear and quadratic parts of a model about its operating point."""

    x_op: np.ndarray
    u_op: np.ndarray
    A: np.ndarray
    B: np.ndarray
    H: np.ndarray
    C: np.ndarray

    @property
    def spectral_abscissa(self) -> float:
        """Largest real part of the eigenvalues of ``A``: negative for a stable point."""
        return float(np.max(np.linalg.eigvals(self.A).real))


def check_expansion(e: Expansion, name: str) -> None:
    """Raise :class:`SimulationError` unless the linear and quadratic parts are finite and
    the operating point is stable (about an unstable point the series diverges)."""
    if not all(np.all(np.isfinite(m)) for m in (e.A, e.B, e.H)):
        raise SimulationError(f"{name}: the circuit's linearisation at its operating point "
                              "is not finite (a parameter out of range?)")
    if e.spectral_abscissa >= 0:
        raise SimulationError(
            f"{name}: the operating point is unstable (an eigenvalue of the linearisation "
            f"has real part {e.spectral_abscissa:.3g} 1/s >= 0): the circuit oscillates and "
            "a perturbation series about the point diverges")


def expand(model, x_op: np.ndarray, u_op: np.ndarray) -> Expansion:
    """The linear + quadratic split of ``model`` about ``(x_op, u_op)``."""
    x_op, u_op = np.asarray(x_op, float), np.asarray(u_op, float)
    H = model.hessian(x_op, u_op)
    return Expansion(x_op=x_op, u_op=u_op, A=model.jacobian(x_op, u_op),
                     B=model.input_jacobian(x_op, u_op), H=0.5 * (H + np.swapaxes(H, 1, 2)),
                     C=model.h_jacobian(x_op))


EXACT_STIFFNESS_LIMIT = 1e6
"""Largest ``max |eig(A)| dt`` for which the exact propagation is used. Its matrix
exponential rounds to about ``eps max|eig(A)| dt`` of the output: 2e-10 at the limit, below
the integrator's ``rtol``; beyond it (the printed-bias amplifiers, up to 5e8) the stacked
system is integrated instead (measured: 6e-9 of a 9 V output per period, which the periodic
solve amplifies 26-fold, against 1e-11 for the integrator)."""


def propagate_expanded(e: Expansion, du: np.ndarray, dt: float,
                       start: np.ndarray) -> np.ndarray:
    """Exact zeroth- and first-order trajectories ``[x0, x1]`` at the sample times.

    On each interval the input deviation ``du`` is constant, so ``z = [x0, du]`` obeys
    ``z' = M z`` with ``M = [[A, B], [0, 0]]``, the products ``z (x) z`` obey
    ``(z (x) z)' = (M (+) M)(z (x) z)`` (Kronecker sum), and the first order is
    ``x1' = A x1 + 1/2 H (z (x) z)``: a linear system with one constant matrix, advanced
    over an interval by one matrix exponential computed once. No integrator, no step
    control; the only error is the exponential's rounding.

    ``du`` has shape ``(runs, steps, p)``, ``start`` ``(runs, 2n)``; returns
    ``(runs, steps + 1, 2n)``.
    """
    n, p = e.B.shape
    m = n + p
    M = np.zeros((m, m))
    M[:n, :n], M[:n, n:] = e.A, e.B
    eye = np.eye(m)
    size = m + m * m + n
    G = np.zeros((size, size))
    G[:m, :m] = M
    G[m:m + m * m, m:m + m * m] = np.kron(M, eye) + np.kron(eye, M)
    G[m + m * m:, m:m + m * m] = 0.5 * e.H.reshape(n, m * m)
    G[m + m * m:, m + m * m:] = e.A
    Phi = linalg.expm(G * dt)
    # only x0 (rows :n) and x1 (last n rows) are read after each interval
    rows = np.concatenate([np.arange(n), np.arange(m + m * m, size)])
    Phi_out = Phi[rows].T
    runs, steps = du.shape[0], du.shape[1]
    out = np.empty((runs, steps + 1, 2 * n))
    out[:, 0] = start
    x = np.asarray(start, float).copy()
    w = np.empty((runs, size))
    for k in range(steps):
        z = np.concatenate([x[:, :n], du[:, k]], axis=1)
        w[:, :m] = z
        w[:, m:m + m * m] = (z[:, :, None] * z[:, None, :]).reshape(runs, m * m)
        w[:, m + m * m:] = x[:, n:]
        x = w @ Phi_out
        out[:, k + 1] = x
    return out




class ExpandedSystem:
    """The zeroth- and first-order systems stacked, ``[x0, x1]``, as a model for the
    integrator: input ``du``, drift ``[A x0 + B du, A x1 + q(x0, du)]``."""

    def __init__(self, expansion: Expansion, name: str) -> None:
        self.expansion = expansion
        self.name = f"{name} (perturbation)"
        self.n = expansion.A.shape[0]
        self.n_states = 2 * self.n

    def f_and_jacobian(self, state: np.ndarray, du: np.ndarray,
                       t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        e, n = self.expansion, self.n
        x0, x1 = state[..., :n], state[..., n:]
        du = np.broadcast_to(du, state.shape[:-1] + du.shape[-1:])
        z = np.concatenate([x0, du], axis=-1)
        f = np.concatenate([x0 @ e.A.T + du @ e.B.T,
                            x1 @ e.A.T + 0.5 * np.einsum("ijk,...j,...k->...i", e.H, z, z)],
                           axis=-1)
        J = np.zeros(state.shape + (2 * n,))
        J[..., :n, :n] = e.A
        J[..., n:, n:] = e.A
        J[..., n:, :n] = np.einsum("ijk,...k->...ij", e.H[:, :n, :], z)
        return f, J

    def kernel(self):
        """The compiled drift for :mod:`estim.numerics.radau_compiled`:
        ``P = [n, p, A (n*n), B (n*p), H (n*m*m)]``, ``m = n + p``."""
        e = self.expansion
        n, p = e.B.shape
        P = np.concatenate([[n, p], e.A.ravel(), e.B.ravel(), e.H.ravel()])
        return kernels.EXPANDED, P

    def f(self, state: np.ndarray, du: np.ndarray, t: float = 0.0) -> np.ndarray:
        return self.f_and_jacobian(state, du, t)[0]

    def jacobian(self, state: np.ndarray, du: np.ndarray, t: float = 0.0) -> np.ndarray:
        return self.f_and_jacobian(state, du, t)[1]


@dataclass(frozen=True)
class Response:
    """Output deviations from the operating point at the sample times, ``(runs, steps + 1)``:
    zeroth order ``y0``, first order ``y1`` and the full nonlinear circuit ``y_full``."""

    t: np.ndarray
    y0: np.ndarray
    y1: np.ndarray
    y_full: np.ndarray
    shooting_iterations: int


def _with_start(start: np.ndarray, traj: np.ndarray) -> np.ndarray:
    return np.concatenate([start[:, None, :], traj], axis=1)


def respond(model, source: np.ndarray, bias: np.ndarray, dt: float, periodic: bool,
            solver: str = "batched_radau", rtol: float = 1e-8, atol: float = 1e-10,
            shooting_tol: float = 1e-7, max_shooting: int = 20) -> Response:
    """Zeroth-order, first-order and full responses of ``model`` to sampled sources.

    ``source`` has shape ``(runs, steps + 1, p)`` (samples at ``t_0 .. t_steps``); the model
    maps it to its input on each interval (``source_to_input``). The operating point is the
    DC point with the sources held at ``bias`` ``(p,)``. With
    ``periodic`` the source must span exactly one period and every response is its periodic
    steady state; otherwise all three start at rest at the operating point.
    ``shooting_tol`` bounds the full circuit's distance from its periodic orbit at the
    output (the last quasi-Newton correction ``(I - e^{AT})^-1 (x(T) - x(0))``), relative to
    the zeroth-order output swing.
    """
    integrate = SOLVERS[solver]
    source = np.asarray(source, float)
    runs, steps = source.shape[0], source.shape[1] - 1
    u_in = model.source_to_input(source, dt)
    held = np.broadcast_to(np.asarray(bias, float), (2, source.shape[-1]))
    u_op = model.source_to_input(held, dt)[0]
    x_op = model.operating_point(u=u_op)
    expansion = expand(model, x_op, u_op)
    check_expansion(expansion, model.name)
    du = np.broadcast_to(u_in - u_op, u_in.shape)
    n = model.n_states
    stiffness = float(np.max(np.abs(np.linalg.eigvals(expansion.A)))) * dt
    system = ExpandedSystem(expansion, model.name)

    def run_expanded(start):
        if stiffness <= EXACT_STIFFNESS_LIMIT:
            return propagate_expanded(expansion, du, dt, start)
        return _with_start(start, integrate(system, start, du, dt, rtol=rtol, atol=atol))

    zero = np.zeros((runs, 2 * n))
    iterations = 0
    if periodic:
        M = np.eye(n) - linalg.expm(expansion.A * dt * steps)
        lu = linalg.lu_factor(M)
        start = zero.copy()
        start[:, :n] = linalg.lu_solve(lu, run_expanded(zero)[:, -1, :n].T).T
        start[:, n:] = linalg.lu_solve(lu, run_expanded(start)[:, -1, n:].T).T
        traj = run_expanded(start)
        x_start = x_op + start[:, :n] + start[:, n:]
        swing = np.max(np.abs(traj[..., :n] @ expansion.C.T), axis=(1, 2))
        if not np.all(swing > 0):
            raise SimulationError(f"{model.name}: the input does not reach the output in the "
                                  "linearised circuit (zero-order output is zero)")
        while True:
            full = _with_start(x_start, integrate(model, x_start, u_in, dt, rtol=rtol,
                                                  atol=atol))
            step = linalg.lu_solve(lu, (full[:, -1] - x_start).T).T
            if np.all(np.abs(step @ expansion.C.T).max(axis=-1) <= shooting_tol * swing):
                break
            iterations += 1
            if iterations > max_shooting:
                raise SimulationError(f"{model.name}: periodic steady state not found in "
                                      f"{max_shooting} shooting iterations")
            x_start = x_start + step
    else:
        traj = run_expanded(zero)
        x_start = np.broadcast_to(x_op, (runs, n))
        full = _with_start(x_start, integrate(model, x_start, u_in, dt, rtol=rtol, atol=atol))
    y_op = model.h(x_op)
    return Response(
        t=dt * np.arange(steps + 1),
        y0=(traj[..., :n] @ expansion.C.T)[..., 0],
        y1=(traj[..., n:] @ expansion.C.T)[..., 0],
        y_full=(model.h(full) - y_op)[..., 0],
        shooting_iterations=iterations,
    )

