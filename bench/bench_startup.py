"""Wall time of the small commands (validate, list, table), each a fresh process, beside a
bare ``python -c "import numpy, scipy.linalg, yaml"``.

    python bench/bench_startup.py                     # this checkout
    python bench/bench_startup.py --baseline HEAD~3   # beside a baseline, in the same run

Each command runs once to warm the caches (Python's bytecode, numba's, estim's DC points:
``estim.util.disk_cache``), then three times; the fastest of the three is printed.
``PYTHONDONTWRITEBYTECODE`` is removed from the commands' environment: with it set, as on
some development machines, no bytecode is written and every run compiles estim's modules
again (0.1-0.15 s), which an installed package (``pip install`` writes the bytecode) never
does (start-up is a floor, and the fastest run is the one least disturbed by other work on
the machine). The baseline runs from a package view of its checkout
(:func:`bench_reproduce.package_view`).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_reproduce import ROOT, checkouts, package_view  # noqa: E402

COMMANDS = (("validate", "configs/mosfet_saturation.yaml"),
            ("validate", "configs/dipole_field.yaml"),
            ("validate", "configs/diffamp_distortion.yaml"),
            ("list",),
            ("table", "distortion", "diffamp_distortion"),
            ("table", "rmse", "mosfet_saturation"),
            ("table", "distortion"),
            ("table", "rmse"))


ENTRY = "from estim.cli.launch import main; main()"
"""What the console script ``estim`` runs (``[project.scripts]``): its command group loads
only the command it is given."""

REFERENCE = "import numpy, scipy.linalg, yaml"
"""Issue 46's yardstick: a bare import of what every estim command needs at least."""


def fastest(command: tuple[str, ...], env: dict, repeats: int = 3,
            code: str = ENTRY) -> float:
    """The fastest wall time of ``repeats`` runs of ``estim COMMAND`` (of ``python -c CODE``
    with ``code``) after one warm-up."""
    times = []
    for k in range(repeats + 1):
        start = time.perf_counter()
        out = subprocess.run([sys.executable, "-c", code, *command], env=env, cwd=ROOT,
                             capture_output=True, text=True)
        if out.returncode:
            raise SystemExit(f"estim {' '.join(command)}: exit {out.returncode}\n{out.stderr}")
        if k:
            times.append(time.perf_counter() - start)
    return min(times)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="a commit or a checkout's folder")
    args = parser.parse_args(argv)
    with checkouts(args.baseline, "estim-startup-") as (scratch, sides):
        base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        envs = {side: {**base, "PYTHONPATH": str(package_view(c, scratch / side))}
                for side, c in sides.items()}
        print(f"{'command':<48}" + "".join(f"{side + ' s':>12}" for side in sides)
              + f"{'this / bare':>12}")
        bare = fastest((), base, code=REFERENCE)
        rows = [{"command": f'python -c "{REFERENCE}"', **{f"{side} s": bare for side in sides},
                 "this / bare import": 1.0}]
        for command in COMMANDS:
            seconds = {side: fastest(command, envs[side]) for side in sides}
            cells = "".join(f"{s:>12.2f}" for s in seconds.values())
            ratio = seconds["this"] / bare
            print(f"{'estim ' + ' '.join(command):<48}{cells}{ratio:>12.2f}", flush=True)
            rows.append({"command": "estim " + " ".join(command),
                         **{f"{side} s": s for side, s in seconds.items()},
                         "this / bare import": ratio})
    record.save("startup", rows, __doc__)


if __name__ == "__main__":
    main()
