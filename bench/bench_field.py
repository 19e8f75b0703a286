"""Chapter 5: seconds per step of the field simulation and of the ensemble filter against
the grid size N (16, 24, 32, 48), as ratios to N = 16 run in the same process.

Run on demand (not part of the tests):  python bench/bench_field.py

Per N: one leapfrog/Mur step of the plain simulation (1 member), one step of a 50-member
ensemble, one global ETKF analysis of that ensemble (the source-only filter) and one LETKF
analysis (the field filter: cubes of 4 points, Gaspari-Cohn half-width one wavelength,
transforms and their application), 2 % of the points as sensors, six field components each.
The work per step grows as N^3 (the LETKF's as cubes x sensors within reach); the printed
ratios say how close the code comes to that (8x from 16 to 32, 27x to 48).
"""

from __future__ import annotations

import time

import numpy as np
import record

from estim.experiments.dipole_field.filtering import observe, sensor_operators
from estim.fields import etkf, letkf
from estim.fields.dipole import Dipole
from estim.fields.fdtd import Grid, Simulation


def timed(fn, repeats: int = 5) -> float:
    best = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best.append(time.perf_counter() - t0)
    return float(np.median(best))


def case(n: int, members: int = 50) -> dict:
    grid = Grid(n, 4.0 / n)
    d = Dipole(dl=grid.spacing)
    dt = 0.5 * grid.spacing
    sim = Simulation(grid, d, dt, dl=grid.spacing, width=0.7)
    one = np.zeros((1, 2, 2, grid.size))
    ens = np.random.default_rng(0).standard_normal((members, 2, 2, grid.size)) * 1e-3
    amps = np.ones(members, complex)
    rng = np.random.default_rng(1)
    sensors = np.sort(rng.choice(grid.size, max(1, grid.size // 50), replace=False))
    ops = sensor_operators(grid, sensors)
    nxt = sim.step(ens, 0.0, amps)
    Y = np.concatenate([v for v in observe(grid, ens, nxt, dt, 1.0, ops).values()], axis=1)
    Y = Y.reshape(members, -1)
    X = nxt.reshape(members, -1)
    y = Y.mean(axis=0)
    R = np.full(Y.shape[1], 1e-4)
    local = letkf.localisation(n, grid.xyz, grid.xyz[sensors], 4, 1.0)
    Ys = Y.reshape(members, 6, -1).transpose(0, 2, 1)
    Xs = nxt.reshape(members, 4, -1)
    dy = 0.01 * rng.standard_normal(Ys.shape[1:])

    def local_analysis():
        W = letkf.transforms(Ys - Ys.mean(axis=0), dy, R.reshape(-1, 6), local.taper)
        return letkf.analyse(Xs, local, W)

    return {"N": n, "states": 4 * grid.size,
            "plain_s": timed(lambda: sim.step(one, 0.0, np.ones(1))),
            "ensemble_s": timed(lambda: sim.step(ens, 0.0, amps)),
            "etkf_s": timed(lambda: etkf.analysis(X, Y, y, R)),
            "letkf_s": timed(local_analysis)}


def main() -> None:
    rows = [case(n) for n in (16, 24, 32, 48)]
    base = rows[0]
    print(f"{'N':>4s} {'states':>9s} {'plain s/step':>13s} {'x N=16':>7s} "
          f"{'50 members s/step':>18s} {'x N=16':>7s} {'ETKF s':>9s} {'x N=16':>7s} "
          f"{'LETKF s':>9s} {'x N=16':>7s}")
    for r in rows:
        print(f"{r['N']:4d} {r['states']:9d} {r['plain_s']:13.2e} "
              f"{r['plain_s'] / base['plain_s']:7.1f} {r['ensemble_s']:18.2e} "
              f"{r['ensemble_s'] / base['ensemble_s']:7.1f} {r['etkf_s']:9.2e} "
              f"{r['etkf_s'] / base['etkf_s']:7.1f} {r['letkf_s']:9.2e} "
              f"{r['letkf_s'] / base['letkf_s']:7.1f}")
    record.save("field", [{"N": r["N"], "states": r["states"],
                           "plain s/step": r["plain_s"],
                           "x N=16": r["plain_s"] / base["plain_s"],
                           "50 members s/step": r["ensemble_s"],
                           "x N=16 ": r["ensemble_s"] / base["ensemble_s"],
                           "ETKF s": r["etkf_s"], "x N=16  ": r["etkf_s"] / base["etkf_s"],
                           "LETKF s": r["letkf_s"],
                           "x N=16   ": r["letkf_s"] / base["letkf_s"]} for r in rows],
                __doc__)


if __name__ == "__main__":
    main()
