"""Where a benchmark's table goes: ``bench/results/NAME.csv``, headed by what it measures,
the command that made it, the machine, the commit and the date. docs/speed.md is made from
these files by ``python bench/speed_page.py`` (tested: the page cannot drift from them)."""

from __future__ import annotations

import csv
import io
import os
import platform
import subprocess
import sys
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
META = ("about", "command", "machine", "commit", "date")


def machine() -> str:
    """The CPU model, its usable cores, the system, Python's and numpy's versions."""
    import numpy as np

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (f"{cpu}, {cores} cores, {platform.system()} {platform.release()}, Python "
            f"{platform.python_version()}, numpy {np.__version__}")


def commit() -> str:
    """This checkout's short commit, with ``+changes`` when its code differs from it."""
    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
        return done.stdout.strip() if done.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD") or "unknown"
    changed = git("status", "--porcelain", "--untracked-files=no", "--", "core", "cli", "bench",
                  "configs")
    return head + ("+changes" if changed else "")


def about(doc: str) -> str:
    """The first paragraph of a benchmark's docstring, on one line."""
    return " ".join(doc.strip().split("\n\n")[0].split())


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def save(name: str, rows: list[dict], doc: str, command: str | None = None) -> Path:
    """Write ``rows`` (one dict per row, the same keys) to ``bench/results/NAME.csv`` under
    the header lines of :data:`META`; ``doc`` is the benchmark's docstring, ``command`` by
    default the one that runs this process."""
    if command is None:
        script = Path(sys.argv[0]).resolve()
        shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else script.name
        command = " ".join(["python", str(shown), *sys.argv[1:]])
    meta = {"about": about(doc), "command": command, "machine": machine(),
            "commit": commit(), "date": date.today().isoformat()}
    buf = io.StringIO()
    for key in META:
        buf.write(f"# {key}: {meta[key]}\n")
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: _cell(v) for k, v in row.items()} for row in rows)
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.csv"
    path.write_text(buf.getvalue())
    print(f"-> {path.relative_to(ROOT)}")
    return path


def read(path: Path) -> tuple[dict[str, str], list[dict[str, str]]]:
    """The header lines and the rows of a file :func:`save` wrote."""
    lines = path.read_text().splitlines()
    meta = {}
    while lines and lines[0].startswith("# "):
        key, _, value = lines.pop(0)[2:].partition(": ")
        meta[key] = value
    return meta, list(csv.DictReader(lines))
