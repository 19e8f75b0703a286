"""What the integrator's tolerance is worth: each default config whose actual signal comes
from the stiff integrator, at its own ``simulation.rtol`` and loosened to 1e-4 and 1e-3.

    python bench/bench_rtol.py [CONFIGS]

Each run is a fresh process, ``estim run CONFIG simulation.rtol=R --jobs 1`` (an overridden
run writes into a scratch folder, never into ``results/``), the three tolerances of a config
one after the other so drift in the machine's load hits them alike. CPU-seconds are the
child's user + system time. "largest rmse move" is the largest relative difference of any
cell of ``rmse.csv``'s ``rmse`` column from the run at the config's own tolerance: what a
looser tolerance would move in the tables, not a bound on the trajectories' error. The
distortion configs are left out: their harmonics sit 100 dB or more below the fundamental,
which the integrator at 1e-8 resolves and at 1e-3 does not.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_reproduce import ROOT, cpu_run  # noqa: E402

CONFIGS = ("configs/diffamp_ekf.yaml", "configs/mosfet_conduction.yaml",
           "configs/mosfet_saturation.yaml", "configs/mosfet_input_derivative.yaml",
           "configs/kronecker_table_4_1.yaml", "configs/kronecker_table_4_2.yaml",
           "configs/kronecker_table_4_2_area.yaml")
LOOSER = (1e-4, 1e-3)


def own_rtol(config: str) -> float:
    """The config's ``simulation.rtol`` as validated (its default where it gives none)."""
    from estim import api

    return float(api.experiment(ROOT / config).config.simulation.rtol)


def rmse_cells(folder: Path) -> list[float]:
    """The ``rmse`` column of ``folder/rmse.csv``, in its row order."""
    with open(folder / "rmse.csv", newline="") as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        return [float(r["rmse"]) for r in rows]


def largest_move(cells: list[float], reference: list[float]) -> float:
    """The largest relative difference of ``cells`` from ``reference`` (finite cells)."""
    moves = [abs(a - b) / abs(b) for a, b in zip(cells, reference, strict=True)
             if b != 0 and abs(a) < float("inf") and abs(b) < float("inf")]
    return max(moves, default=0.0)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=list(CONFIGS))
    args = parser.parse_args(argv)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    rows = []
    with tempfile.TemporaryDirectory(prefix="estim-rtol-") as scratch:
        for config in args.configs:
            name = Path(config).stem
            own = own_rtol(config)
            cpu_run(["run", config, "--quick", "--jobs", "1", "--out", f"{scratch}/q"], env,
                    ROOT)
            times, cells = {}, {}
            for rtol in (own, *LOOSER):
                out = Path(scratch) / f"{name}-{rtol:g}"
                cpu, _, rc = cpu_run(["run", config, f"simulation.rtol={rtol!r}", "--jobs",
                                      "1", "--out", str(out)], env, ROOT)
                times[rtol] = cpu if rc == 0 else float("nan")
                cells[rtol] = rmse_cells(out / name) if rc == 0 else []
            for rtol in (own, *LOOSER):
                both = cells[rtol] and cells[own]
                move = largest_move(cells[rtol], cells[own]) if both else float("nan")
                row = {"config": name, "rtol": f"{rtol:g}", "own rtol": f"{own:g}",
                       "CPU-s": times[rtol], "speed vs own": times[own] / times[rtol],
                       "largest rmse move": move}
                rows.append(row)
                print(f"{name:<28}{rtol:>8g}{times[rtol]:>9.1f}"
                      f"{times[own] / times[rtol]:>7.2f}{move:>11.2e}", flush=True)
    record.save("rtol", rows, __doc__, command=" ".join(
        ["python bench/bench_rtol.py", *(argv if argv is not None else sys.argv[1:])]))


if __name__ == "__main__":
    main()
