"""Time steppers for the wave equation ``u'' = c^2 L u + s`` (thesis eqs 5.20, 5.48-5.49),
state ``(u, v = u')``, any linear operator ``L`` (a sparse Laplacian here).

``leapfrog``  kick-drift-kick (velocity Verlet): half kick ``v += T/2 (c^2 L u + s)``, drift
              ``u += T v``, half kick with the new ``u``. Second order, time-reversible; a
              mode of ``L`` with eigenvalue ``-k^2`` neither grows nor decays while
              ``c T k <= 2``. For the 7-point Laplacian ``k^2 < 12 / Delta^2``, so every
              mode is stable up to ``c T / Delta = 1/sqrt(3) = 0.577``.
``euler``     forward Euler on ``(u, v)`` (the thesis' ``F ~ I + T F`` for eq 5.20's system,
              unnumbered, §5.2): every mode grows by ``sqrt(1 + (c T k)^2)`` per step, at
              any ``T`` (the row "plain simulation (Euler, eq 5.20)" of ``dipole_field``,
              kept to show it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

STEPPERS = ("leapfrog", "euler")

COURANT_LIMIT = 1 / np.sqrt(3)
"""Largest ``c T / Delta`` at which leapfrog is stable for the 3-D 7-point Laplacian."""


def step(u: np.ndarray, v: np.ndarray, apply_L: Callable[[np.ndarray], np.ndarray], c: float,
         dt: float, s_now: np.ndarray | float = 0.0, s_next: np.ndarray | float = 0.0,
         method: str = "leapfrog") -> tuple[np.ndarray, np.ndarray]:
    """One step of length ``dt`` from ``(u, v)``; ``s_now``, ``s_next`` the source at the
    step's start and end. ``apply_L`` maps ``u`` (any trailing batch axes) to ``L u``."""
    if method == "leapfrog":
        v_half = v + 0.5 * dt * (c**2 * apply_L(u) + s_now)
        u_new = u + dt * v_half
        return u_new, v_half + 0.5 * dt * (c**2 * apply_L(u_new) + s_next)
    if method == "euler":
        return u + dt * v, v + dt * (c**2 * apply_L(u) + s_now)
    raise ValueError(f"stepper {method!r}; expected one of {list(STEPPERS)}")
