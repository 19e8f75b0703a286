"""Which claim verdicts another machine's arithmetic moves (docs/claims.md, "Fragile verdicts").

Run from the project folder: ``python docs/studies/verdict_fragility.py [--runs N] [CONFIGS]``
(default: every config of ``configs/``, ``configs/netlist/`` and ``configs/studies/`` whose
claims are judged over Monte Carlo runs). It runs the configs under each arithmetic variant of
``arithmetic_spread.py`` (OpenBLAS's Zen kernels; its Haswell kernels with numpy's AVX-512
loops left out: what another x86-64 machine with the same package versions changes) and
compares every cell's ``verdict`` and ``verdict_family`` in ``claims.csv`` with
``results/``.

It writes ``results/fragile_verdicts.csv``: one row per (config, claim, cell) whose verdict
or family verdict moved under some variant, with the stored and the moved verdicts and the
variant. ``estim summary``, the README's generated blocks and the report count these cells
as fragile beside the claim's verdicts. An empty table (the header alone) means no verdict
moved. The file records the variants run and the commit in its first lines' comments.

With ``--runs N`` it asks whether more runs settle the verdicts instead: the configs run at
``monte_carlo.runs=N`` under this machine's arithmetic and each variant, and the moved cells
go to ``docs/studies/verdict_fragility_runs<N>.csv`` (``results/`` is not touched).
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


def run_claims(configs: list[str], env: dict[str, str], jobs: int, out: str,
               overrides: list[str]) -> None:
    """``estim run`` of ``configs`` into ``out`` under the arithmetic ``env``."""
    subprocess.run(["estim", "run", *configs, *overrides, "--out", out, "--jobs", str(jobs),
                    "--quiet"], env={**os.environ, **env}, check=True,
                   stdout=subprocess.DEVNULL)


def compare(configs: list[str], base: Path, out: Path, variant: str) -> list[dict]:
    """The cells of ``configs`` whose verdict or family verdict differs between the claims
    under ``base`` and under ``out``."""
    rows = []
    for config in configs:
        name = api.experiment(config).name
        stored = pd.read_csv(base / name / "claims.csv")
        new = pd.read_csv(out / name / "claims.csv")
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


def moved(configs: list[str], variant: str, env: dict[str, str], jobs: int,
          base: Path | None = None, overrides: tuple[str, ...] = ()) -> list[dict]:
    """The verdicts of ``configs`` that differ from ``base`` (``results/``) when run under
    ``env`` (with ``overrides``)."""
    with tempfile.TemporaryDirectory() as out:
        run_claims(configs, env, jobs, out, list(overrides))
        return compare(configs, base or Path("results"), Path(out), variant)


def grouped(rows: list[dict]) -> pd.DataFrame:
    """One row per (config, claim, cell), the variants that moved it joined by ' + '."""
    table = pd.DataFrame(rows, columns=COLUMNS)
    return table.groupby(["config", "claim", "cell"], sort=False, as_index=False).agg(
        {c: "first" for c in COLUMNS if c not in ("config", "claim", "cell", "variant")}
        | {"variant": lambda v: " + ".join(sorted(set(v)))})[COLUMNS]


def commit_note() -> str:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, check=False).stdout.strip()
    return f" at {commit}" if commit else ""


def at_runs(configs: list[str], runs: int, jobs: int) -> None:
    """Whether more runs settle the fragile verdicts: ``configs`` run with
    ``monte_carlo.runs=runs`` under this machine's arithmetic and under each variant, the
    variants compared with the first. Writes ``docs/studies/verdict_fragility_runs<N>.csv``
    (the columns of ``results/fragile_verdicts.csv``); ``results/`` is not touched."""
    overrides = (f"monte_carlo.runs={runs}",)
    rows = []
    with tempfile.TemporaryDirectory() as base:
        run_claims(configs, {}, jobs, base, list(overrides))
        for variant, env in VARIANTS.items():
            found = moved(configs, variant, env, jobs, Path(base), overrides)
            print(f"{variant}: {len(found)} verdicts moved over {len(configs)} configs "
                  f"at {runs} runs")
            rows += found
    table = grouped(rows)
    path = Path(__file__).with_name(f"verdict_fragility_runs{runs}.csv")
    header = (f"# written by docs/studies/verdict_fragility.py --runs {runs}{commit_note()}: "
              f"{' '.join(configs)} at monte_carlo.runs={runs}, each variant against this "
              f"machine's own arithmetic; variants: {'; '.join(VARIANTS)}\n")
    path.write_text(header + table.to_csv(index=False, lineterminator="\n"))
    print(table.to_markdown(index=False) if len(table) else "no verdict moved")


def main(argv: list[str]) -> None:
    runs = None
    if argv[:1] == ["--runs"]:
        runs, argv = int(argv[1]), argv[2:]
    configs = argv or sorted(str(p) for folder in ("configs", "configs/netlist",
                                                   "configs/studies")
                             for p in Path(folder).glob("*.yaml"))
    configs = [c for c in configs if random_claims(c)]
    jobs = len(os.sched_getaffinity(0))
    if runs is not None:
        at_runs(configs, runs, jobs)
        return
    rows = []
    for variant, env in VARIANTS.items():
        found = moved(configs, variant, env, jobs)
        print(f"{variant}: {len(found)} verdicts moved over {len(configs)} configs")
        rows += found
    table = grouped(rows)
    header = (f"# written by docs/studies/verdict_fragility.py{commit_note()} over "
              f"{len(configs)} configs; variants: {'; '.join(VARIANTS)}\n")
    Path("results", FILE).write_text(header + table.to_csv(index=False,
                                                            lineterminator="\n"))
    print(table.to_markdown(index=False) if len(table) else "no verdict moved")


if __name__ == "__main__":
    main(sys.argv[1:])
