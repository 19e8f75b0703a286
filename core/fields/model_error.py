"""Model error of the leapfrog grid in the field filter's ensemble (D60).

What the grid gets wrong is, locally, the amplitude and the phase of a wave of the known
frequency: numerical dispersion delays it (0.195 rad at r = 1.5 on the axes at 8 points per
wavelength), the smooth source and the Mur faces change its size. So each member's forecast
is perturbed as a local phasor. The two leapfrog levels ``u(t)``, ``u(t + dt)`` of a
harmonic of angular frequency ``omega`` are ``Re Z`` and ``Re(Z e^{j omega dt})``, which
gives the local complex amplitude ``Z`` point by point:

    Re Z = u(t),     Im Z = (cos(omega dt) u(t) - u(t + dt)) / sin(omega dt),

and the member continues from ``Z (1 + a + j p)``, with ``a`` and ``p`` independent smooth
random fields (white noise smoothed by a Gaussian of ``length`` cells along each axis,
scaled to standard deviation ``size`` at every point): a relative amplitude error and a
phase error in radians per step, the same for ``A_z`` and ``Phi`` at a point.

``size`` is stated per step; its default (docs/deviations.md D60) comes from the truncation
error of the analytic potentials in the leapfrog: about 0.3 % of the local amplitude per
step beyond r = 0.45 wavelengths.
"""

from __future__ import annotations

import numpy as np

from estim.numerics.kernels import jit


def gaussian_smoother(n: int, length: float) -> np.ndarray:
    """``(n, n)`` rows of a Gaussian of ``length`` points, each row of unit Euclidean norm, so
    that white noise smoothed along one axis keeps unit variance at every point."""
    i = np.arange(n)
    K = np.exp(-0.5 * ((i[:, None] - i[None, :]) / length) ** 2)
    return K / np.linalg.norm(K, axis=1, keepdims=True)


def smooth_noise(rng: np.random.Generator, count: int, n: int, K: np.ndarray) -> np.ndarray:
    """``count`` fields ``(count, n^3)`` of unit-variance noise smoothed by ``K`` along x, y
    and z."""
    z = rng.standard_normal((count, n, n, n)) @ K.T          # along z
    z = K @ z                                                # along y
    z = K @ z.reshape(count, n, n * n)                       # along x
    return z.reshape(count, n**3)


@jit
def _perturb(levels, c, s, a, p, scale):  # pragma: no cover - compiled
    members, _, fields, points = levels.shape
    for k in range(members):
        for f in range(fields):
            for i in range(points):
                zr = levels[k, 0, f, i]
                zi = (c * zr - levels[k, 1, f, i]) / s
                ak, pk = a[k, i] * scale[f, i], p[k, i] * scale[f, i]
                zr2 = zr + ak * zr - pk * zi
                zi2 = zi + ak * zi + pk * zr
                levels[k, 0, f, i] = zr2
                levels[k, 1, f, i] = c * zr2 - s * zi2


def perturb(levels: np.ndarray, omega_dt: float, a: np.ndarray, p: np.ndarray,
            scale: np.ndarray | None = None) -> np.ndarray:
    """Members' levels ``(m, 2, fields, points)`` (``u(t)``, ``u(t + dt)``) continued from
    the local phasor ``Z (1 + s a + j s p)``; ``a``, ``p`` ``(m, points)``, ``s`` the
    ``scale`` of each field at each point ``(fields, points)`` (default 1). In place;
    returns ``levels``."""
    if scale is None:
        scale = np.ones(levels.shape[2:])
    _perturb(levels, np.cos(omega_dt), np.sin(omega_dt), np.ascontiguousarray(a, float),
             np.ascontiguousarray(p, float), np.ascontiguousarray(scale, float))
    return levels


def truncation_profile(sim, potentials: tuple[np.ndarray, np.ndarray], bins: np.ndarray,
                       instants: int = 8) -> np.ndarray:
    """The leapfrog's relative error per step for each potential ``(2, points)``: the
    truncation error ``tau = (u(t+dt) - 2u(t) + u(t-dt))/dt^2 - c^2 L u - s`` of the
    analytic phasors ``potentials`` (``A_z``, ``Phi``) at ``instants`` times of a period,
    ``RMS(dt^2 tau) / RMS(u)`` over each radial shell of ``bins`` (so a node of a potential
    does not divide by zero), given to every point of the shell. Faces are left out of the
    RMS (Mur sets them, not the Laplacian); points beyond the last bin take its value."""
    grid, d, dt = sim.grid, sim.dipole, sim.dt
    inside = np.ones(grid.size, bool)
    for face in grid.faces:
        inside[face] = False
    shell = np.clip(np.digitize(grid.r, bins) - 1, 0, len(bins) - 2)
    out = np.zeros((2, grid.size))
    for k, F in enumerate(potentials):
        tau2 = np.zeros(grid.size)
        u2 = np.zeros(grid.size)
        for t in np.arange(instants) / (instants * d.omega / (2 * np.pi)):
            u0, um, up = ((F * np.exp(1j * d.omega * s)).real for s in (t, t - dt, t + dt))
            src = np.zeros(grid.size)
            src[sim._support] = sim.source(t, np.array([1.0]))[0, k]
            tau = (up - 2 * u0 + um) / dt**2 - d.c**2 * (grid.laplacian @ u0) - src
            tau2 += tau**2
            u2 += u0**2
        num = np.bincount(shell[inside], (dt**4 * tau2)[inside], minlength=len(bins) - 1)
        den = np.bincount(shell[inside], u2[inside], minlength=len(bins) - 1)
        ratio = np.sqrt(num / np.where(den > 0, den, np.inf))
        out[k] = ratio[shell]
    return out
