"""Write docs/speed.md from the benchmarks' output files in bench/results/ (and the quick
start's bench/quickstart.csv): one section per benchmark, with what it measures, the
command that made it, the machine and the commit, and its table.

    python bench/speed_page.py

tests/test_docs_blocks.py fails when the page is stale.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import record  # noqa: E402

ROOT = record.ROOT
PAGE = ROOT / "docs" / "speed.md"
SECTIONS = (
    ("reproduce", "The whole reproduction, config by config"),
    ("quickstart", "The README's quick start"),
    ("startup", "Start-up of the small commands"),
    ("first_run", "The first run's numba compile"),
    ("peers", "The KF, EKF and UKF beside filterpy and dynamax (JAX)"),
    ("peers_integrator_matched", "The stiff integrator beside scipy and ngspice, at matched "
                                 "accuracy"),
    ("peers_integrator", "The stiff integrator beside scipy and ngspice, every setting"),
    ("peers_letkf", "The LETKF beside DAPPER"),
    ("filters", "Batched filters against filterpy"),
    ("ekf_steps", "Where an EKF step's time goes"),
    ("simulate", "The actual signal: integrators"),
    ("newton", "The integrator's Newton iteration: full against simplified"),
    ("rtol", "What the integrator's tolerance is worth"),
    ("letkf_sqrt", "The LETKF's symmetric inverse square root"),
    ("expansion", "Chapter 2: exact propagation of the expansion"),
    ("field", "Chapter 5: the field simulation and filter against the grid"),
    ("image", "The image filters"),
    ("chapter3_row", "One Chapter 3 row against an old version"),
)
"""Each benchmark's output file (bench/results/NAME.csv) and its section's title, in the
page's order."""

INTRO = """\
# Speed

Every table below is a benchmark's output file in `bench/results/`, written by the command
shown above it on the machine it names; `python bench/speed_page.py` makes this page from
those files, and a test fails when the page and the files differ. The ratios (speed-ups,
"x" columns) are measured in one process or in alternated runs, so they carry to other
machines better than the seconds do. `pip install '.[bench]'` adds the peer libraries the
benchmarks run beside estim; `python bench/all.py` runs the eight in-process benchmarks in one
go.
"""


def quickstart() -> tuple[dict[str, str], list[dict[str, str]]]:
    """bench/quickstart.csv (one row per quick-start command, the machine in its columns)
    as :func:`record.read` gives the other files."""
    with open(ROOT / "bench" / "quickstart.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    first = rows[0]
    meta = {"about": "The README's two commands in a fresh clone and a fresh virtual "
                     "environment, under GNU time: wall time, peak memory of any one process, "
                     "and whether git status is empty after the first.",
            "command": "python bench/bench_quickstart.py", "machine": first["machine"],
            "commit": first["commit"], "date": first["date"]}
    keep = ("command", "exit", "wall_s", "peak_mb", "git_status_clean")
    return meta, [{k: row[k] for k in keep} for row in rows]


def table(rows: list[dict[str, str]]) -> str:
    """Rows as a Markdown table."""
    head = list(rows[0])

    def cells(values) -> str:
        return "| " + " | ".join(str(v).replace("|", "\\|") for v in values) + " |"

    return "\n".join([cells(head), "|" + "---|" * len(head),
                      *(cells(row[k] for k in head) for row in rows)])


def page() -> str:
    """The whole text of docs/speed.md."""
    parts = [INTRO]
    for name, title in SECTIONS:
        if name == "quickstart":
            meta, rows = quickstart()
        else:
            path = record.RESULTS / f"{name}.csv"
            if not path.is_file():
                continue
            meta, rows = record.read(path)
        parts.append(f"## {title}\n\n{meta['about']}\n\n"
                     f"- command: `{meta['command']}`\n- machine: {meta['machine']}\n"
                     f"- commit {meta['commit']}, {meta['date']}\n\n{table(rows)}\n")
    return "\n".join(parts)


if __name__ == "__main__":
    PAGE.write_text(page())
    print(f"-> {PAGE.relative_to(ROOT)}")
