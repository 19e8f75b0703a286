"""Chapter 5: how wrong is one leapfrog step? The source of the field filter's default model
error (``filter.field_error``, docs/deviations.md D61).

Run on demand:  python bench/field_truncation.py [N]     (default N = 32)

The analytic potentials of the dipole, ``A_z = mu0 I0 dl e^{-j beta r} / (4 pi r)`` and the
analytic ``Phi``, are put into the leapfrog at eight instants of a period. What the scheme
leaves over, the truncation error

    tau = (u(t + dt) - 2 u(t) + u(t - dt)) / dt^2 - c^2 L u(t) - s(t),

is the error one step adds to a field that was exact; ``dt^2 tau`` is that error in the
units of ``u``. Printed per radial shell (inside the faces, r from 0.25 wavelengths): the
RMS of ``dt^2 tau`` relative to the RMS of ``u`` (the per-step relative error) and the RMS
of ``tau`` relative to that of ``u''``.
"""

from __future__ import annotations

import sys

import numpy as np

from estim.fields.dipole import Dipole
from estim.fields.fdtd import Grid, Simulation

SHELLS = ((0.25, 0.45), (0.45, 0.8), (0.8, 1.2), (1.2, 1.9))


def truncation(n: int = 32, length: float = 4.0, courant: float = 0.5) -> list[dict]:
    grid = Grid(n, length / n)
    d = Dipole(dl=grid.spacing)
    per = int(round(1 / (courant * grid.spacing)))
    dt = 1 / per
    sim = Simulation(grid, d, dt, dl=grid.spacing, width=0.7)
    A = d.mu0 * d.I0 * d.dl * np.exp(-1j * d.beta * grid.r) / (4 * np.pi * grid.r)
    Phi = d.phasors(grid.r, grid.theta)["Phi"]
    inside = np.ones(grid.size, bool)
    for face in grid.faces:
        inside[face] = False
    rows = []
    for name, F, k in (("A_z", A, 0), ("Phi", Phi, 1)):
        taus, us, accs = [], [], []
        for t in np.linspace(0, 1, 8, endpoint=False):
            u0, um, up = ((F * np.exp(1j * d.omega * s)).real for s in (t, t - dt, t + dt))
            src = np.zeros(grid.size)
            src[sim._support] = sim.source(t, np.array([1.0]))[0, k]
            acc = (up - 2 * u0 + um) / dt**2
            taus.append(acc - d.c**2 * (grid.laplacian @ u0) - src)
            us.append(u0)
            accs.append(acc)
        taus, us, accs = map(np.array, (taus, us, accs))
        for lo, hi in SHELLS:
            m = inside & (grid.r >= lo) & (grid.r < hi)
            rms = {key: float(np.sqrt(np.mean(v[:, m] ** 2)))
                   for key, v in (("tau", taus), ("u", us), ("acc", accs))}
            rows.append({"potential": name, "r": f"{lo}-{hi}",
                         "per_step": dt**2 * rms["tau"] / rms["u"],
                         "of_acceleration": rms["tau"] / rms["acc"]})
    return rows


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 32
    print(f"N = {n}: RMS of dt^2 tau / RMS of u (per step), RMS tau / RMS u''")
    for row in truncation(n):
        print(f"{row['potential']:4s} r {row['r']:9s} {row['per_step']:9.2e} "
              f"{row['of_acceleration']:9.2e}")


if __name__ == "__main__":
    main()
