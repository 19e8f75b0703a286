"""The README's quick start as a newcomer runs it, timed: bench/quickstart.csv.

    python bench/bench_quickstart.py        # from the project folder, on a quiet machine

It clones this checkout's HEAD into a temporary folder, makes a fresh virtual environment
there (as .ci/run does) and runs the README's two commands one after the other under
GNU time (``/usr/bin/time -v``): ``pip install . && estim reproduce``, then
``pip install '.[test]' && pytest``. It records each one's wall time and peak memory (the
largest resident set of any one process GNU time waited for), whether ``git status
--short`` is empty after the first, the machine and the commit, in
``bench/quickstart.csv``, which the README's quick-start table quotes (tested).
"""

from __future__ import annotations

import csv
import os
import platform
import re
import subprocess
import sys
import tempfile
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = ("pip install . && estim reproduce", "pip install '.[test]' && pytest")
OUT = ROOT / "bench" / "quickstart.csv"


def timed(command: str, cwd: Path, env: dict) -> tuple[float, float, int]:
    """Wall seconds, peak resident megabytes and exit status of ``command`` (bash) under
    GNU time (a failing command is reported, its output's end printed, and recorded: the
    tests' run needs this file, which the README's table is checked against)."""
    done = subprocess.run(["/usr/bin/time", "-v", "bash", "-c", command], cwd=cwd, env=env,
                          capture_output=True, text=True)
    if done.returncode != 0:
        print(f"{command}: exit {done.returncode}\n{done.stdout[-3000:]}", file=sys.stderr)
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", done.stderr)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", done.stderr)
    parts = [float(p) for p in wall.group(1).split(":")]
    seconds = sum(p * 60 ** i for i, p in enumerate(reversed(parts)))
    return seconds, int(rss.group(1)) / 1024, done.returncode


def machine() -> str:
    model = ""
    try:
        model = next(line.split(":", 1)[1].strip() for line in
                     Path("/proc/cpuinfo").read_text().splitlines()
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{model or platform.processor()}, {len(os.sched_getaffinity(0))} cores"


def main() -> int:
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True, check=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        clone = Path(tmp) / "estim"
        subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
        subprocess.run([sys.executable, "-m", "venv", str(clone / ".venv")], check=True)
        env = {**os.environ, "PATH": f"{clone / '.venv' / 'bin'}:{os.environ['PATH']}",
               "VIRTUAL_ENV": str(clone / ".venv")}
        env.pop("PYTHONPATH", None)
        for i, command in enumerate(COMMANDS):
            seconds, mb, status_code = timed(command, clone, env)
            clean = ""
            if i == 0:
                status = subprocess.run(["git", "status", "--short"], cwd=clone,
                                        capture_output=True, text=True, check=True).stdout
                clean = "yes" if not status.strip() else "no: " + " ".join(status.split())
            rows.append({"command": command, "exit": status_code, "wall_s": round(seconds, 1),
                         "peak_mb": round(mb), "git_status_clean": clean,
                         "machine": machine(), "commit": commit,
                         "date": date.today().isoformat()})
            print(f"{command}: {seconds:.0f} s, {mb:.0f} MB {clean}", flush=True)
    with OUT.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
