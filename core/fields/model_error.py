"""Model error of the leapfrog grid in the field filter's ensemble (D61).

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

``size`` is stated per step; its default (docs/deviations.md D61) comes from the truncation
error of the analytic potentials in the leapfrog: about 0.3 % of the local amplitude per
step beyond r = 0.45 wavelengths.
"""

from __future__ import annotations

import numpy as np

from estim.kernels import jit


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
def _perturb(levels, c, s, a, p):  # pragma: no cover - compiled
    members, _, fields, points = levels.shape
    for k in range(members):
        for f in range(fields):
            for i in range(points):
                zr = levels[k, 0, f, i]
                zi = (c * zr - levels[k, 1, f, i]) / s
                zr2 = zr + a[k, i] * zr - p[k, i] * zi
                zi2 = zi + a[k, i] * zi + p[k, i] * zr
                levels[k, 0, f, i] = zr2
                levels[k, 1, f, i] = c * zr2 - s * zi2


def perturb(levels: np.ndarray, omega_dt: float, a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Members' levels ``(m, 2, fields, points)`` (``u(t)``, ``u(t + dt)``) continued from
    the local phasor ``Z (1 + a + j p)``; ``a``, ``p`` ``(m, points)``. In place; returns
    ``levels``."""
    _perturb(levels, np.cos(omega_dt), np.sin(omega_dt), np.ascontiguousarray(a, float),
             np.ascontiguousarray(p, float))
    return levels
