"""The potentials of a dipole on a 3-D grid (thesis eqs 5.48-5.49, the chapter's Remark):

    A_z'' = c^2 lap A_z + c^2 mu0 J_z,      Phi'' = c^2 lap Phi + c^2 rho / eps0,

with the Remark's consistent source: ``J_z = I0 cos(omega t) j(x)`` on a short segment and
``rho = (I0 / omega) sin(omega t) r(x)`` with ``r = -d/dz j`` (the discrete divergence of the
profile), so ``d rho/dt + div J = 0`` holds on the grid and the Lorenz gauge is kept.
``j`` is a smooth delta in x and y (a Gaussian of width ``width`` cells) times a smoothed
segment of length ``dl`` in z, scaled so its integral is ``dl``.

Time stepping is the three-level leapfrog ``u+ = 2u - u- + T^2 (c^2 L u + s)`` (the same
scheme as :func:`estim.fields.wave.step`'s kick-drift-kick, stable up to ``c T / Delta =
0.577``), with Mur's first-order absorbing boundary on the six faces: a face value is
advanced as a wave leaving the box, ``u0+ = u1 + (cT - Delta)/(cT + Delta) (u1+ - u0)``.
A Dirichlet box instead reflects every outgoing wave back in (docs/deviations.md).

Fields: ``E = -grad Phi - dA/dt`` (eq 5.25), ``H = curl A / mu0`` (eq 5.27) with the centred
operators of :mod:`estim.fields.operators`; ``dA/dt`` by the centred difference of the
leapfrog levels. Everything works on a leading batch axis (ensemble members).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erf

from estim.fields import operators as ops
from estim.fields.dipole import Dipole
from estim.fields.grid import Grid
from estim.numerics.kernels import jit


@jit
def _leapfrog(prev, now, new, indptr, indices, data, n, scale):  # pragma: no cover - compiled
    """``new = scale L now + 2 now - prev`` for every member and field ``(m, fields, n^3)``,
    ``L`` the 7-point Laplacian in CSR form. Rows on the faces follow the CSR rows; interior
    rows use the same seven coefficients at fixed offsets (a loop along z that vectorises),
    summed in the CSR's index order, so every value is rounded as scipy's product rounds
    it."""
    members, fields, points = now.shape
    nn = n * n
    mid = nn * (n // 2) + n * (n // 2) + n // 2
    lo = indptr[mid]
    cx0, cy0, cz0, cd = data[lo], data[lo + 1], data[lo + 2], data[lo + 3]
    cz1, cy1, cx1 = data[lo + 4], data[lo + 5], data[lo + 6]
    for k in range(members):
        for f in range(fields):
            u = now[k, f]
            v = prev[k, f]
            w = new[k, f]
            for x in range(n):
                for y in range(n):
                    base = x * nn + y * n
                    if 0 < x < n - 1 and 0 < y < n - 1:
                        for z in range(1, n - 1):
                            i = base + z
                            s = (cx0 * u[i - nn] + cy0 * u[i - n] + cz0 * u[i - 1] + cd * u[i]
                                 + cz1 * u[i + 1] + cy1 * u[i + n] + cx1 * u[i + nn])
                            w[i] = s * scale + 2 * u[i] - v[i]
                        edges = (0, n - 1)
                    else:
                        edges = (0, -1)
                    if edges[1] == -1:
                        for z in range(n):
                            i = base + z
                            s = 0.0
                            for jj in range(indptr[i], indptr[i + 1]):
                                s += data[jj] * u[indices[jj]]
                            w[i] = s * scale + 2 * u[i] - v[i]
                    else:
                        for z in edges:
                            i = base + z
                            s = 0.0
                            for jj in range(indptr[i], indptr[i + 1]):
                                s += data[jj] * u[indices[jj]]
                            w[i] = s * scale + 2 * u[i] - v[i]


@jit
def _mur(now, new, faces, inner, mur):  # pragma: no cover - compiled
    """Mur's face update ``new[face] = now[inner] + mur (new[inner] - now[face])``, the faces
    taken in order (a later face overwrites the edges it shares with an earlier one)."""
    members, fields = now.shape[0], now.shape[1]
    for k in range(members):
        for f in range(fields):
            for a in range(faces.shape[0]):
                for b in range(faces.shape[1]):
                    p, q = faces[a, b], inner[a, b]
                    new[k, f, p] = now[k, f, q] + mur * (new[k, f, q] - now[k, f, p])


def source_profiles(grid: Grid, dl: float, width: float) -> tuple[np.ndarray, np.ndarray]:
    """``j`` (current density per unit current, along z) and ``r = -d/dz j`` (charge
    density per unit ``I0 / omega``) on the grid."""
    s = width * grid.spacing
    x, y, z = grid.xyz.T
    across = np.exp(-(x**2 + y**2) / (2 * s**2)) / (2 * np.pi * s**2)
    along = 0.5 * (erf((z + dl / 2) / (np.sqrt(2) * s)) - erf((z - dl / 2) / (np.sqrt(2) * s)))
    j = across * along
    j *= dl / (j.sum() * grid.spacing**3)
    _, _, dz = ops.partials(grid.n, grid.spacing)
    return j, -(dz @ j)


@dataclass
class Simulation:
    """Leapfrog for ``[A_z, Phi]`` with Mur boundaries; ``state`` has shape
    ``(members, 2, 2, n^3)``: (previous, current) x (A_z, Phi)."""

    grid: Grid
    dipole: Dipole
    dt: float
    dl: float
    width: float = 1.0
    boundary: str = "mur"

    def __post_init__(self) -> None:
        if self.boundary not in ("mur", "dirichlet"):
            raise ValueError(f"boundary {self.boundary!r}; expected 'mur' or 'dirichlet'")
        self.j, self.rho = source_profiles(self.grid, self.dl, self.width)
        c, h = self.dipole.c, self.grid.spacing
        self.mur = (c * self.dt - h) / (c * self.dt + h)
        # the profiles are Gaussian-smoothed: below 1e-14 of their peak they are dropped,
        # which keeps each step's source to the few hundred points it really touches
        self._faces = np.stack(self.grid.faces)
        self._inner = np.stack(self.grid.inner)
        self._support = np.flatnonzero((np.abs(self.j) > 1e-14 * np.abs(self.j).max())
                                       | (np.abs(self.rho) > 1e-14 * np.abs(self.rho).max()))

    def source(self, t: float, amplitude: np.ndarray) -> np.ndarray:
        """``c^2 [mu0 J_z, rho / eps0]`` at time ``t`` for complex amplitudes ``I0`` per
        member, on the source's support: ``(members, 2, support)``. The current is
        ``Re{I0 e^{j omega t}}``, the charge its integral ``Re{I0 e^{j omega t} / (j omega)}``."""
        d = self.dipole
        a = np.asarray(amplitude, complex).reshape(-1)
        phase = np.exp(1j * d.omega * t)
        cur = (a * phase).real
        charge = (a * phase / (1j * d.omega)).real
        j, rho = self.j[self._support], self.rho[self._support]
        return d.c**2 * np.stack([d.mu0 * cur[:, None] * j,
                                  charge[:, None] * rho / d.eps0], axis=1)

    def step(self, state: np.ndarray, t: float, amplitude: np.ndarray) -> np.ndarray:
        """Advance from ``t`` to ``t + dt``: ``state (members, 2, 2, n^3)`` holds the levels
        (t - dt, t); the result holds (t, t + dt)."""
        prev, now = state[:, 0], state[:, 1]
        out = np.empty_like(state)
        out[:, 0] = now
        new = out[:, 1]
        L = self.grid.laplacian
        _leapfrog(prev, now, new, L.indptr, L.indices, L.data, self.grid.n,
                  (self.dipole.c * self.dt) ** 2)
        new[..., self._support] += self.dt**2 * self.source(t, amplitude)
        if self.boundary == "mur":
            _mur(now, new, self._faces, self._inner, self.mur)
        else:
            for face in self.grid.faces:
                new[..., face] = 0.0
        return out


def fields_from(grid: Grid, A: np.ndarray, Phi: np.ndarray, dA_dt: np.ndarray,
                mu0: float) -> dict[str, np.ndarray]:
    """Cartesian E and H (``(..., 3, n^3)``) from ``A_z``, ``Phi`` and ``dA_z/dt``
    (``(..., n^3)``)."""
    lead = A.shape[:-1]
    A3 = np.zeros(lead + (3, grid.size))
    A3[..., 2, :] = A
    flatA = A3.reshape(-1, 3 * grid.size)
    H = (grid.curl @ flatA.T).T.reshape(lead + (3, grid.size)) / mu0
    gradPhi = (grid.grad @ Phi.reshape(-1, grid.size).T).T.reshape(lead + (3, grid.size))
    E = -gradPhi
    E[..., 2, :] -= dA_dt
    return {"E": E, "H": H}


def spherical(grid: Grid, F: np.ndarray, where: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Cartesian ``(..., 3, points)`` -> r, theta, phi components, at the grid points
    ``where`` (default: all of them)."""
    sel = slice(None) if where is None else where
    th, ph = grid.theta[sel], grid.phi[sel]
    st, ct, sp_, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    fx, fy, fz = F[..., 0, :], F[..., 1, :], F[..., 2, :]
    return {"r": st * cp * fx + st * sp_ * fy + ct * fz,
            "theta": ct * cp * fx + ct * sp_ * fy - st * fz,
            "phi": -sp_ * fx + cp * fy}
