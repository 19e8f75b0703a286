"""CPU-seconds of every default config, this checkout beside a baseline, in one run.

    python bench/all.py --reproduce --baseline HEAD~5        # a commit (a git worktree)
    python bench/all.py --reproduce --baseline ../old-clone  # or a checkout's folder

Each config runs as its own process (``estim run CONFIG --jobs 1 --out TMP``) first on the
baseline, then on this checkout, so drift in the machine's load hits both alike. A
``--quick`` run of each config comes first on each side and is not counted: it loads (or
compiles) numba's kernels into that checkout's cache. CPU-seconds are the child processes'
user + system time (``resource.RUSAGE_CHILDREN``). The last column says whether this
checkout's tables equal the stored ``results/`` byte for byte, or else within the config's
declared tolerances, as ``estim check`` judges (another machine's arithmetic moves the last
bits; a benchmark that changed a table beyond them has changed a result, not only a speed).

The baseline runs from a folder of symbolic links that lays its ``core/``, ``cli/``,
``configs/`` and ``circuits/`` out as the package ``estim`` (as pyproject.toml maps them),
first on ``PYTHONPATH``: no second install is needed.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = "from estim.cli.main import main; main()"


def package_view(checkout: Path, into: Path) -> Path:
    """A folder holding ``estim/`` laid out from ``checkout`` as the installed package."""
    pkg = into / "estim"
    pkg.mkdir(parents=True)
    for entry in (checkout / "core").iterdir():
        (pkg / entry.name).symlink_to(entry)
    cli = pkg / "cli"
    cli.mkdir()
    for entry in (checkout / "cli").iterdir():
        (cli / entry.name).symlink_to(entry)
    (cli / "configs").symlink_to(checkout / "configs")
    if (checkout / "circuits").is_dir():
        (pkg / "circuits").symlink_to(checkout / "circuits")
    return into


def checkout_of(baseline: str, scratch: Path) -> Path:
    """``baseline`` as a folder: itself if it is one, else a git worktree at that commit."""
    path = Path(baseline)
    if (path / "core").is_dir():
        return path.resolve()
    tree = scratch / "baseline"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), baseline],
                   check=True, capture_output=True)
    return tree


@contextlib.contextmanager
def checkouts(baseline: str | None, prefix: str) -> Iterator[tuple[Path, dict[str, Path]]]:
    """A scratch folder and the checkouts to run, ``{"baseline": ..., "this": ROOT}`` (only
    "this" without a baseline); the baseline's worktree and the folder are removed after."""
    scratch = Path(tempfile.mkdtemp(prefix=prefix))
    worktree = None
    try:
        sides = {"this": ROOT}
        if baseline:
            base = checkout_of(baseline, scratch)
            worktree = base if base.is_relative_to(scratch) else None
            sides = {"baseline": base, **sides}
        yield scratch, sides
    finally:
        if worktree is not None:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(worktree)], capture_output=True)
        shutil.rmtree(scratch, ignore_errors=True)


def cpu_run(args: list[str], env: dict, cwd: Path) -> tuple[float, float, int]:
    """CPU-seconds (user + system of the child) and wall seconds of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", LAUNCH, *args], env=env, cwd=cwd,
                         capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if out.returncode:
        print(f"   {' '.join(args[:2])}: exit {out.returncode}: "
              f"{out.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
    return cpu, wall, out.returncode


def tables_verdict(new: Path, stored: Path, config: str) -> str:
    """``identical``: every CSV of ``stored`` is in ``new`` with the same bytes (the
    wall-clock tables are under ``machine/``, not among them);
    ``within tolerances``: not, but every cell passes the config's ``check.tolerances`` (the
    rule of ``estim check``, which another machine's arithmetic needs); else ``DIFFER``."""
    csvs = list(stored.glob("*.csv"))
    if not csvs or not all((new / p.name).is_file() for p in csvs):
        return "DIFFER"
    if all((new / p.name).read_bytes() == p.read_bytes() for p in csvs):
        return "identical"
    from estim import api, store
    from estim.config.registry import ANALYSES
    from estim.engine import compare

    exp = api.experiment(ROOT / config)
    tol, specs = exp.spec["check"]["tolerances"], ANALYSES[exp.analysis].TABLES
    for p in csvs:
        stored = store.read_table(p, specs.get(p.stem))
        if compare.compare_tables(stored, store.read_table(new / p.name), tol):
            return "DIFFER"
    return "within tolerances"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True,
                        help="a commit (checked out as a git worktree) or a checkout's folder")
    parser.add_argument("configs", nargs="*",
                        help="configs to run [default: every configs/*.yaml]")
    args = parser.parse_args(argv)
    configs = args.configs or sorted(str(p.relative_to(ROOT))
                                     for p in (ROOT / "configs").glob("*.yaml"))
    with checkouts(args.baseline, "estim-bench-") as (scratch, sides):
        envs = {}
        for side, checkout in sides.items():
            view = package_view(checkout, scratch / f"view-{side}")
            envs[side] = {**os.environ, "PYTHONPATH": str(view), "OMP_NUM_THREADS": "1",
                          "NUMBA_NUM_THREADS": "1"}
        for config in configs:
            for side, checkout in sides.items():
                cpu_run(["run", config, "--quick", "--jobs", "1", "--out",
                         str(scratch / f"quick-{side}")], envs[side], checkout)
        print(f"{'config':<28}{'baseline s':>11}{'this s':>9}{'ratio':>8}{'wall s':>9}"
              "  tables (CPU-s, ratio this/baseline, this one's wall)")
        total = {"baseline": 0.0, "this": 0.0}
        rows = []
        for config in configs:
            cpu, wall = {}, {}
            for side, checkout in sides.items():
                out = scratch / f"out-{side}"
                c, w, rc = cpu_run(["run", config, "--jobs", "1", "--out", str(out)],
                                   envs[side], checkout)
                cpu[side] = c if rc == 0 else float("nan")
                total[side] += c
                wall[side] = w
            name = Path(config).stem
            verdict = tables_verdict(scratch / "out-this" / name, ROOT / "results" / name,
                                     config)
            print(f"{name:<28}{cpu['baseline']:>11.1f}{cpu['this']:>9.1f}"
                  f"{cpu['this'] / cpu['baseline']:>8.2f}{wall['this']:>9.1f}  {verdict}",
                  flush=True)
            rows.append({"config": name, f"baseline {args.baseline} CPU-s": cpu["baseline"],
                         "this CPU-s": cpu["this"], "ratio": cpu["this"] / cpu["baseline"],
                         "this wall s": wall["this"], "tables": verdict})
        print(f"{'total':<28}{total['baseline']:>11.1f}{total['this']:>9.1f}"
              f"{total['this'] / total['baseline']:>8.2f}")
        rows.append({"config": "total", f"baseline {args.baseline} CPU-s": total["baseline"],
                     "this CPU-s": total["this"], "ratio": total["this"] / total["baseline"],
                     "this wall s": "", "tables": ""})
    record.save("reproduce", rows, __doc__, command="python bench/all.py --reproduce "
                + " ".join(argv if argv is not None else sys.argv[1:]))


if __name__ == "__main__":
    main()
