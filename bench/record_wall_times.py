"""Record the stored results' wall times for checkouts that have none of their own.

    python bench/record_wall_times.py        # after `estim reproduce --all` into results/
    python bench/record_wall_times.py NAME   # after a new config's first run: its row only

Each result folder's ``run.json`` (untracked: git ignores it) gives the wall time of the run
that made it on this machine. This writes them, with the command, the host and the commit,
to ``results/wall_times.csv`` (tracked), which ``estim reproduce``, ``run`` and ``check``
read for a config with no run record of its own (a fresh clone): the order that starts the
longest configs first, and the weights of the progress bar's time left
(:func:`estim.engine.runner.recorded_seconds`). A missing run record is an error: the file
describes one reproduction, not a mixture, except for the rows of the configs named on the
command line, which are added or replaced from their own run records (a config added since
the last reproduction; its row says the command that made it).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def row(folder: Path) -> dict | None:
    """The wall-time row of one result folder, from its run record (``None``: none)."""
    record = folder / "run.json"
    if not record.is_file():
        return None
    run = json.loads(record.read_text())
    host = run.get("host") or {}
    return {"name": folder.name, "wall_time_s": run["wall_time_s"],
            "command": run.get("command", ""),
            "host": f"{host.get('machine', '')} {host.get('cpus', '')} cpus",
            "git_commit": run.get("git_commit") or ""}


def main(names: list[str]) -> int:
    results = ROOT / "results"
    if names:
        table = pd.read_csv(results / "wall_times.csv")
        for name in names:
            new = row(results / name)
            if new is None or not (results / name / "manifest.json").is_file():
                print(f"no stored results with a run record in results/{name}",
                      file=sys.stderr)
                return 1
            table = pd.concat([table[table["name"] != name], pd.DataFrame([new])])
        table.sort_values("name").to_csv(results / "wall_times.csv", index=False,
                                         lineterminator="\n")
        print(f"results/wall_times.csv: {', '.join(names)} added")
        return 0
    rows, missing = [], []
    for manifest in sorted(results.glob("*/manifest.json")):
        found = row(manifest.parent)
        if found is None:
            missing.append(manifest.parent.name)
            continue
        rows.append(found)
    if missing:
        print(f"no run.json in {', '.join(missing)}: run estim reproduce --all first",
              file=sys.stderr)
        return 1
    pd.DataFrame(rows).to_csv(results / "wall_times.csv", index=False, lineterminator="\n")
    print(f"results/wall_times.csv: {len(rows)} configs")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
