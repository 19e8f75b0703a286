"""estim's LETKF analysis beside DAPPER's ``local_analyses`` at dipole_field's size: the
config's grid (32^3 points, 512 cubes of 4^3), its 50 members, its sensors (655, six readings
each) and its Gaspari-Cohn localisation, on one random forecast ensemble (the cost does not
depend on the values). estim: ``letkf.transforms`` and ``letkf.analyse``; DAPPER: its
``local_analyses`` with one state batch per cube and its own Gaspari-Cohn taper, as
``crosscheck_dapper.dapper_local`` calls it (that script checks the two agree to 1e-10 on a
spun-up field; here the largest difference of the analysed anomalies is printed too).

DAPPER cannot share estim's environment (crosscheck_dapper.py says why), so its side runs in
DAPPER's own interpreter (``--dapper-python``, as CI makes it: ``.venv-dapper/bin/python``)
on the same arrays, passed through a temporary file; each round times one analysis of each,
alternated, inside the process that runs it (DAPPER's start-up is not counted).

    python bench/peers.py --letkf --dapper-python .venv-dapper/bin/python
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import record
import yaml

ROOT = Path(__file__).resolve().parents[1]

DAPPER_ROUND = """
import json, sys, time
from types import SimpleNamespace
import numpy as np
sys.path.insert(0, sys.argv[3])
from crosscheck_dapper import dapper_local
d = np.load(sys.argv[1])
local = SimpleNamespace(points=list(d["points"]), distances=d["distances"])
start = time.perf_counter()
E = dapper_local(d["X"], d["Y"], d["y"], d["R"], local, float(d["half_width"]))
seconds = time.perf_counter() - start
np.save(sys.argv[2], E)
print(json.dumps(seconds))
"""


def problem(seed: int = 5):
    """dipole_field's localisation and a random forecast ensemble of its size."""
    from estim.config.loading import parse_data
    from estim.experiments import dipole_field

    spec = yaml.safe_load((ROOT / "configs" / "dipole_field.yaml").read_text())
    exp = parse_data(spec, "dipole_field.yaml", "dipole_field")
    su = dipole_field.setup(exp.config, exp.plan, dipole_field.layout(exp.config, exp.plan, 0))
    m, points = exp.spec["filter"]["members"], exp.plan.grid.size
    sensors = su.local.taper.shape[1]
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((m, 5, points))
    Y = rng.standard_normal((m, sensors, 6))
    y = Y.mean(axis=0) + 0.3 * rng.standard_normal((sensors, 6))
    R = rng.uniform(0.5, 2.0, (sensors, 6))
    return su, X, Y, y, R


def measure(dapper_python: str, rounds: int = 3) -> list[dict]:
    from estim.fields import letkf

    su, X, Y, y, R = problem()
    local = su.local

    def ours():
        W = letkf.transforms(Y - Y.mean(axis=0), y - Y.mean(axis=0), R, local.taper)
        return letkf.analyse(X, local, W)

    times = {"estim": [], "DAPPER": []}
    with tempfile.TemporaryDirectory() as tmp:
        data, out = Path(tmp) / "problem.npz", Path(tmp) / "dapper.npy"
        np.savez(data, X=X, Y=Y, y=y, R=R, points=np.asarray(local.points),
                 distances=np.asarray(local.distances), half_width=su.local_half_width)
        for _ in range(rounds):
            start = time.perf_counter()
            mine = ours()
            times["estim"].append(time.perf_counter() - start)
            done = subprocess.run([dapper_python, "-c", DAPPER_ROUND, str(data), str(out),
                                   str(ROOT / "bench")], capture_output=True, text=True)
            if done.returncode:
                raise SystemExit(f"DAPPER's side failed:\n{done.stderr[-2000:]}")
            times["DAPPER"].append(json.loads(done.stdout.strip().splitlines()[-1]))
        theirs = np.load(out)
    anomalies = (mine - X, theirs - X)
    gap = float(np.max(np.abs(anomalies[0] - anomalies[1])) / np.max(np.abs(anomalies[1])))
    base = float(np.median(times["estim"]))
    rows = []
    for name, seconds in times.items():
        s = float(np.median(seconds))
        rows.append({"library": name, "seconds per analysis": s, "this / estim": s / base,
                     "largest difference of analysed anomalies (relative)":
                         0.0 if name == "estim" else gap})
        print(f"LETKF {name:7s} {s:8.3f} s per analysis   {s / base:6.2f}x estim's time")
    print(f"analysed anomalies differ by {gap:.1e} of the largest")
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--dapper-python", default=str(ROOT / ".venv-dapper/bin/python"))
    args = parser.parse_args(argv)
    record.save("peers_letkf", measure(args.dapper_python, args.rounds), __doc__)


if __name__ == "__main__":
    sys.exit(main())
