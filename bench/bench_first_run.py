"""The first run's compile: every default config's quick profile with no compiled kernel
cached, then again with the kernels the first pass cached, on this checkout and a baseline.

    python bench/bench_first_run.py [--baseline COMMIT_OR_FOLDER] [--jobs 2]

``estim run configs/*.yaml --quick --jobs J`` runs each analysis' quick profile (seconds of
work: the first cell of a sweep, short records, one to five runs), so nearly all of a cold
pass is numba compiling the kernels the configs use, as on a fresh install, and the
difference of the two passes is what a first ``estim reproduce`` pays on top of a warm one.
Each side gets an empty ``NUMBA_CACHE_DIR`` of its own; the baseline runs from a package view
of its checkout (bench_reproduce.py). CPU-seconds are the child's user + system time.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402
from bench_reproduce import ROOT, checkouts, cpu_run, package_view  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="a commit (a git worktree) or a checkout's folder")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    configs = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "configs").glob("*.yaml"))
    rows = []
    with checkouts(args.baseline, "estim-first-") as (scratch, sides):
        for side, checkout in sides.items():
            view = package_view(checkout, scratch / f"view-{side}")
            cache = scratch / f"numba-{side}"
            cache.mkdir()
            env = {**os.environ, "PYTHONPATH": str(view), "NUMBA_CACHE_DIR": str(cache),
                   "ESTIM_CACHE_DIR": str(scratch / f"dc-{side}")}
            passes = {}
            for kind in ("cold", "warm"):
                out = scratch / f"out-{side}-{kind}"
                cpu, wall, rc = cpu_run(["run", *configs, "--quick", "--jobs", str(args.jobs),
                                         "--out", str(out)], env, checkout)
                if rc:
                    raise SystemExit(f"{side} {kind}: exit {rc}")
                passes[kind] = (cpu, wall)
            label = "this" if side == "this" else f"baseline {args.baseline}"
            row = {"checkout": label, "cold wall s": passes["cold"][1],
                   "warm wall s": passes["warm"][1],
                   "first run's extra wall s": passes["cold"][1] - passes["warm"][1],
                   "cold CPU-s": passes["cold"][0], "warm CPU-s": passes["warm"][0],
                   "compile CPU-s": passes["cold"][0] - passes["warm"][0]}
            rows.append(row)
            print("  ".join(f"{k}: {v:.1f}" if isinstance(v, float) else f"{k}: {v}"
                            for k, v in row.items()), flush=True)
    record.save("first_run", rows, __doc__)


if __name__ == "__main__":
    main()
