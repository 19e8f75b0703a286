"""Fragile verdicts: claim cells whose verdict another machine's arithmetic moves.

``docs/studies/verdict_fragility.py`` re-runs the configs whose claims are judged over Monte
Carlo runs under other x86-64 arithmetic (OpenBLAS's Zen and Haswell kernels, numpy without
AVX-512) and writes every (config, claim, cell) whose ``verdict`` or ``verdict_family``
moved to ``results/fragile_verdicts.csv``. Such a verdict is rounding, not a finding:
``estim summary``, the generated blocks of docs/results.md and the report count it as
fragile beside the claim (docs/claims.md).
"""

from __future__ import annotations

from pathlib import Path

from estim.util import lazy

pd = lazy.load("pandas")

FILE = "fragile_verdicts.csv"
"""The table's name in a results folder."""

COLUMNS = ["config", "claim", "cell", "verdict", "verdict_moved", "verdict_family",
           "verdict_family_moved", "variant"]


def read(results: Path) -> pd.DataFrame:
    """The fragile verdicts recorded under ``results`` (no rows when none are recorded)."""
    path = Path(results) / FILE
    if not path.is_file():
        return pd.DataFrame(columns=COLUMNS)
    return pd.read_csv(path, comment="#", dtype=str, keep_default_na=False)


def cells(table: pd.DataFrame, config: str) -> dict[str, set[str]]:
    """``{claim: {cell, ...}}`` of the fragile verdicts of ``config``."""
    out: dict[str, set[str]] = {}
    for _, row in table[table["config"] == config].iterrows():
        out.setdefault(row["claim"], set()).add(row["cell"])
    return out
