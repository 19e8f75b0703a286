"""Record the stored results' wall times for checkouts that have none of their own.

    python bench/record_wall_times.py        # after `estim reproduce --all` into results/

Each result folder's ``run.json`` (untracked: git ignores it) gives the wall time of the run
that made it on this machine. This writes them, with the command, the host and the commit,
to ``results/wall_times.csv`` (tracked), which ``estim reproduce``, ``run`` and ``check``
read for a config with no run record of its own (a fresh clone): the order that starts the
longest configs first, and the weights of the progress bar's time left
(:func:`estim.engine.runner.recorded_seconds`). A missing run record is an error: the file
describes one reproduction, not a mixture.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    results = ROOT / "results"
    rows, missing = [], []
    for manifest in sorted(results.glob("*/manifest.json")):
        record = manifest.parent / "run.json"
        if not record.is_file():
            missing.append(manifest.parent.name)
            continue
        run = json.loads(record.read_text())
        host = run.get("host") or {}
        rows.append({"name": manifest.parent.name, "wall_time_s": run["wall_time_s"],
                     "command": run.get("command", ""),
                     "host": f"{host.get('machine', '')} {host.get('cpus', '')} cpus",
                     "git_commit": run.get("git_commit") or ""})
    if missing:
        print(f"no run.json in {', '.join(missing)}: run estim reproduce --all first",
              file=sys.stderr)
        return 1
    pd.DataFrame(rows).to_csv(results / "wall_times.csv", index=False, lineterminator="\n")
    print(f"results/wall_times.csv: {len(rows)} configs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
