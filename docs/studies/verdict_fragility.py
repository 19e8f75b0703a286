"""Which claim verdicts another machine's arithmetic moves (docs/claims.md, "Fragile verdicts").

Run from the project folder: ``python docs/studies/verdict_fragility.py [CONFIGS]`` (default:
every config of ``configs/``, ``configs/netlist/`` and ``configs/studies/`` whose claims are
judged over Monte Carlo runs). It runs the configs under each arithmetic variant of
``arithmetic_spread.py`` (OpenBLAS's Zen kernels; its Haswell kernels with numpy's AVX-512
loops left out: what another x86-64 machine with the same package versions changes) and
compares every cell's ``verdict`` and ``verdict_family`` in ``claims.csv`` with
``results/``.

It writes ``results/fragile_verdicts.csv``: one row per (config, claim, cell) whose verdict
or family verdict moved under some variant, with the stored and the moved verdicts and the
variant. ``estim summary``, the README's generated blocks and the report count these cells
as fragile beside the claim's verdicts. An empty table (the header alone) means no verdict
moved. The file records the variants run and the commit in its first lines' comments.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from arithmetic_spread import VARIANTS  # noqa: E402

from estim import api  # noqa: E402
from estim.report.fragility import COLUMNS, FILE  # noqa: E402

KEYS = ["claim", "cell"]


def random_claims(config: str) -> bool:
    """Whether some stored claim of the config is judged over 6 or more Monte Carlo runs
    (fewer decide nothing, so no verdict of theirs can move)."""
    exp = api.experiment(config)
    path = Path("results") / exp.name / "claims.csv"
    if not path.is_file():
        return False
    df = pd.read_csv(path)
    return bool(((df["method"] == "sign") & (df["runs"] >= 6)).any())


def moved(configs: list[str], variant: str, env: dict[str, str], jobs: int) -> list[dict]:
    """The verdicts of ``configs`` that differ from results/ when run under ``env``."""
    rows = []
    with tempfile.TemporaryDirectory() as out:
        subprocess.run(["estim", "run", *configs, "--out", out, "--jobs", str(jobs),
                        "--quiet"], env={**os.environ, **env}, check=True,
                       stdout=subprocess.DEVNULL)
        for config in configs:
            name = api.experiment(config).name
            stored = pd.read_csv(Path("results") / name / "claims.csv")
            new = pd.read_csv(Path(out) / name / "claims.csv")
            both = stored.merge(new, on=KEYS, suffixes=("", "_moved"), validate="1:1")
            changed = both[(both["verdict"] != both["verdict_moved"])
                           | (both["verdict_family"] != both["verdict_family_moved"])]
            for _, row in changed.iterrows():
                rows.append({"config": name, "claim": row["claim"], "cell": row["cell"],
                             "verdict": row["verdict"], "verdict_moved": row["verdict_moved"],
                             "verdict_family": row["verdict_family"],
                             "verdict_family_moved": row["verdict_family_moved"],
                             "variant": variant})
    return rows


def main(argv: list[str]) -> None:
    configs = argv or sorted(str(p) for folder in ("configs", "configs/netlist",
                                                   "configs/studies")
                             for p in Path(folder).glob("*.yaml"))
    configs = [c for c in configs if random_claims(c)]
    jobs = len(os.sched_getaffinity(0))
    rows = []
    for variant, env in VARIANTS.items():
        found = moved(configs, variant, env, jobs)
        print(f"{variant}: {len(found)} verdicts moved over {len(configs)} configs")
        rows += found
    table = pd.DataFrame(rows, columns=COLUMNS)
    table = table.groupby(["config", "claim", "cell"], sort=False, as_index=False).agg(
        {c: "first" for c in COLUMNS if c not in ("config", "claim", "cell", "variant")}
        | {"variant": lambda v: " + ".join(sorted(set(v)))})[COLUMNS]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, check=False).stdout.strip()
    at = f" at {commit}" if commit else ""
    header = (f"# written by docs/studies/verdict_fragility.py{at} over {len(configs)} "
              f"configs; variants: {'; '.join(VARIANTS)}\n")
    Path("results", FILE).write_text(header + table.to_csv(index=False,
                                                            lineterminator="\n"))
    print(table.to_markdown(index=False) if len(table) else "no verdict moved")


if __name__ == "__main__":
    main(sys.argv[1:])
