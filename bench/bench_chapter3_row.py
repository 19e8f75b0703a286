"""One Chapter 3 row as a process, this checkout against an old version, alternated.

    python bench/bench_chapter3_row.py [--baseline a291372] [--runs 3]

The row is ``mosfet_saturation`` at 1 kHz, its first noise level and reading, 30 runs, every
figure drawn: the config is cut from each version's own ``configs/mosfet_saturation.yaml``
and run as ``estim run ROW --jobs 1 --quiet`` into a fresh folder. Wall seconds of each
process, bytecode written (``PYTHONDONTWRITEBYTECODE`` removed), after one warm-up run per
side that fills the caches; the sides alternate run by run, so the machine's drift hits both.

A baseline laid out as the ``estim`` package runs through a package view (as in
``bench_reproduce.py``); an older one whose CLI is the top-level ``cli`` package (a291372,
before the package was named) runs from its checkout on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_reproduce import LAUNCH, checkouts, package_view  # noqa: E402

OLD_LAUNCH = "from cli.main import main; main()"


def row_config(checkout: Path, into: Path) -> Path:
    """The one-row config cut from ``checkout``'s own ``mosfet_saturation.yaml``."""
    spec = yaml.safe_load((checkout / "configs" / "mosfet_saturation.yaml").read_text())
    level = spec["noise"]["input_levels"][0]
    spec["name"] = "row"
    spec["input"]["frequencies_hz"] = [1000]
    spec["noise"]["input_levels"] = [level]
    spec["noise"]["readings"] = spec["noise"]["readings"][:1]
    spec["monte_carlo"]["runs"] = 30
    if isinstance(spec.get("figures"), dict) and "noise_level" in spec["figures"]:
        spec["figures"]["noise_level"] = level
    into.write_text(yaml.safe_dump(spec))
    return into


def side(checkout: Path, scratch: Path, name: str) -> tuple[list[str], dict]:
    """The command and environment that run the row on ``checkout``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if "from estim" in (checkout / "cli" / "main.py").read_text():
        env["PYTHONPATH"] = str(package_view(checkout, scratch / f"view-{name}"))
        launch = LAUNCH
    else:
        env["PYTHONPATH"] = str(checkout)
        launch = OLD_LAUNCH
    config = row_config(checkout, scratch / f"row-{name}.yaml")
    return [sys.executable, "-c", launch, "run", str(config), "--jobs", "1", "--quiet"], env


def wall(command: list[str], env: dict, out: Path, cwd: Path) -> float:
    """Wall seconds of one run of the row into the empty folder ``out``."""
    shutil.rmtree(out, ignore_errors=True)
    start = time.perf_counter()
    done = subprocess.run([*command, "--out", str(out)], env=env, cwd=cwd,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{command[2][:40]}...: exit {done.returncode}: "
                         f"{done.stderr.strip().splitlines()[-1:]}")
    return seconds


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default="a291372", help="commit or checkout folder")
    parser.add_argument("--runs", type=int, default=3, help="timed runs per side")
    args = parser.parse_args(argv)
    with checkouts(args.baseline, "estim-row-") as (scratch, trees):
        sides = {name: side(tree, scratch, name) for name, tree in trees.items()}
        for name, (command, env) in sides.items():
            wall(command, env, scratch / f"out-{name}", scratch)          # warm-up
        times: dict[str, list[float]] = {name: [] for name in sides}
        for _ in range(args.runs):
            for name, (command, env) in sides.items():
                times[name].append(wall(command, env, scratch / f"out-{name}", scratch))
    base, this = times["baseline"], times["this"]
    print(f"one Chapter 3 row, {args.runs} runs per side, alternated (wall seconds)")
    print(f"baseline {args.baseline}: " + ", ".join(f"{t:.2f}" for t in base))
    print("this checkout: " + ", ".join(f"{t:.2f}" for t in this))
    ratios = [b / t for b, t in zip(base, this, strict=True)]
    print(f"speed-up run by run: {min(ratios):.1f}-{max(ratios):.1f}x")
    record.save("chapter3_row", [{"run": i + 1, f"baseline {args.baseline} s": b,
                                  "this checkout s": t, "speed-up": b / t}
                                 for i, (b, t) in enumerate(zip(base, this, strict=True))],
                __doc__)


if __name__ == "__main__":
    main()
