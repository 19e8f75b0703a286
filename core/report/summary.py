"""Results prose generated from the stored tables (``estim summary``).

For every stored experiment: each claim's verdict counts (holds / fails / undecided out of
the cells it was judged in, :mod:`estim.experiments.shared.claims`) with the range of the ratio of
the losses, and the ranges of the quantities its analysis quotes (:class:`Quote`, declared in the
analysis module as ``QUOTES``). docs/results.md's results sections embed these blocks between
markers (:func:`refresh`), and a test fails when one of them no longer matches the stored
tables.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from estim.config.registry import ANALYSES
from estim.experiments.base import Quote
from estim.experiments.shared import claims
from estim.report import fragility
from estim.store import Stored, open_stored, stored_folders
from estim.util import lazy

pd = lazy.load("pandas")


LIST_AT_MOST = 3
"""A claim's cells are listed by verdict when at most this many have it (and not all)."""


def number(value: float) -> str:
    """Three significant digits; ``inf`` and ``nan`` spelled out."""
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return "nan"
    if np.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.3g}"


def span(values) -> str:
    """``"a–b"`` over the finite values (with ``inf`` when any is infinite), or ``"a"``."""
    v = np.asarray(pd.to_numeric(pd.Series(values), errors="coerce"), float)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return "none"
    lo, hi = float(v.min()), float(v.max())
    return number(lo) if number(lo) == number(hi) else f"{number(lo)}–{number(hi)}"


def claim_lines(df: pd.DataFrame, fragile: dict[str, set[str]] | None = None) -> list[str]:
    """One line per claim of a claims table, in the order they first appear; ``fragile``
    (``{claim: {cell, ...}}``, :mod:`estim.report.fragility`) counts the cells whose verdict
    another machine's arithmetic moves."""
    fragile = fragile or {}
    lines = []
    family = "verdict_family" in df
    for claim, part in df.groupby("claim", sort=False):
        v = part["verdict_family" if family else "verdict"].astype(str)
        n = {k: int((v == k).sum()) for k in claims.VERDICTS}
        line = (f"- `{claim}`: holds {n['holds']}, fails {n['fails']}, undecided "
                f"{n['undecided']} of {len(part)} cells")
        own = part["verdict"].astype(str)
        if family and not (own == v).all():
            line += (f" after Holm's correction (each cell alone: holds "
                     f"{int((own == claims.HOLDS).sum())}, fails "
                     f"{int((own == claims.FAILS).sum())})")
        moved = fragile.get(str(claim), set()) & set(part["cell"].astype(str))
        if moved:
            line += (f"; fragile in {len(moved)} (a verdict another machine's arithmetic "
                     "moves)")
        line += f"; ratio {span(part['ratio'])}"
        keys = [claims.cell_keys(str(c)) for c in part["cell"]]
        varying = [k for k in keys[0] if len({row.get(k) for row in keys}) > 1]
        for verdict in claims.VERDICTS:
            if 0 < n[verdict] <= LIST_AT_MOST and n[verdict] < len(part):
                shown = [", ".join(f"{k}={row[k]}" for k in varying if k in row)
                         for row, hit in zip(keys, v == verdict, strict=True) if hit]
                line += f"; {verdict} at " + " | ".join(f"({c})" for c in shown)
        lines.append(line)
    return lines


def quote_line(quote: Quote, df: pd.DataFrame) -> str | None:
    """The line of one quote, or ``None`` when the table has no value for it."""
    if quote.where:
        df = df.query(quote.where)
    values = df.eval(quote.column) if quote.column not in df else df[quote.column]
    frame = pd.DataFrame({"value": pd.to_numeric(values, errors="coerce")})
    if frame["value"].isna().all():
        return None
    if quote.total:
        frame["of"] = pd.to_numeric(df.eval(quote.total) if quote.total not in df
                                    else df[quote.total], errors="coerce")
    if quote.by:
        frame["by"] = df[quote.by].astype(str).to_numpy()
        groups = list(frame.groupby("by", sort=False))
    else:
        groups = [(None, frame)]
    parts = []
    for key, part in groups:
        if quote.total:
            shown = f"{int(part['value'].sum())} of {int(part['of'].sum())}"
        else:
            shown = span(part["value"])
        parts.append(shown if key is None else f"{key} {shown}")
    return f"- {quote.label}: " + "; ".join(parts)


def experiment(folder: Path, analyses: dict) -> list[str]:
    """The summary lines of the experiment stored in ``folder`` (empty when there is no such
    folder; a damaged one is a ``UsageError``, as everywhere: :func:`estim.store.open_stored`)."""
    if not (Path(folder) / "manifest.json").exists() and not \
            (Path(folder) / "manifest.json").is_symlink():
        return []
    return lines_of(open_stored(folder, analyses))


def lines_of(stored: Stored) -> list[str]:
    """The summary lines of one stored experiment; the fragile verdicts are read from the
    folder's parent (``results/``)."""
    config, folder, module = stored.config, stored.folder, stored.analysis
    title = str(config.get("title") or "")
    runs = (config.get("monte_carlo") or {}).get("runs")
    head = f"**{folder.name}**" + (f": {title}" if title else "")
    verdicts = stored.table(claims.TABLE)
    notes = [f"{runs} runs per cell"] if runs and runs > 1 else []
    if verdicts is not None:      # the margin of practical significance (docs/claims.md)
        notes.append(f"claim margin {number(float(config.get('claim_margin') or 0.0))}")
    if notes:
        head += f" ({'; '.join(notes)})"
    lines = [head]
    if verdicts is not None:
        lines += claim_lines(verdicts,
                             fragility.cells(fragility.read(folder.parent), folder.name))
    loaded: dict[str, pd.DataFrame] = {}
    for quote in getattr(module, "QUOTES", ()):
        if quote.metric not in loaded:
            table = stored.table(module.TABLES[quote.metric])
            if table is None:
                continue
            loaded[quote.metric] = table
        line = quote_line(quote, loaded[quote.metric])
        if line is not None:
            lines.append(line)
    return lines


def everything(results: Path, analyses: dict) -> dict[str, list[str]]:
    """The summary lines of every stored experiment under ``results``, by name (a damaged
    folder is a ``UsageError`` naming the file, as ``estim table`` and ``estim report``
    have it: :func:`estim.store.stored_folders`)."""
    out = {}
    for stored in stored_folders(results, analyses):
        lines = lines_of(stored)
        if lines:
            out[stored.name] = lines
    return out


def _finite_or_text(value: float) -> float | str:
    """A number for JSON: itself when finite, else ``"inf"``, ``"-inf"`` or ``"nan"``."""
    value = float(value)
    return value if np.isfinite(value) else number(value)


def as_data(results: Path, analyses: dict) -> list[dict]:
    """What ``estim summary --json`` prints: per stored experiment its name, title, runs,
    claim margin and, per claim, the family verdict counts (``holds``, ``fails``,
    ``undecided``, ``cells``), the cells' own (``cell_holds``, ``cell_fails``), the fragile
    cells and the ratio's range (``"inf"`` where a filter broke); then the quoted ranges as
    the lines the text gives."""
    out = []
    fragile = fragility.read(results)
    for stored in stored_folders(results, analyses):
        lines = lines_of(stored)
        name, config = stored.name, stored.config
        entry = {"name": name, "title": str(config.get("title") or ""),
                 "runs": (config.get("monte_carlo") or {}).get("runs"),
                 "claim_margin": float(config.get("claim_margin") or 0.0), "claims": [],
                 "quotes": [line[2:] for line in lines if line.startswith("- ")
                            and not line.startswith("- `")]}
        df = stored.table(claims.TABLE)
        if df is not None:
            moved = fragility.cells(fragile, name)
            family, own = claims.counts(df), claims.counts(df, "verdict")
            for (_, f), (_, o) in zip(family.iterrows(), own.iterrows(), strict=True):
                part = df[df["claim"] == f["claim"]]
                ratio = pd.to_numeric(part["ratio"], errors="coerce")
                entry["claims"].append({
                    "claim": f["claim"], "holds": int(f[claims.HOLDS]),
                    "fails": int(f[claims.FAILS]), "undecided": int(f[claims.UNDECIDED]),
                    "cells": int(f["cells"]), "cell_holds": int(o[claims.HOLDS]),
                    "cell_fails": int(o[claims.FAILS]),
                    "fragile": len(moved.get(f["claim"], set())),
                    "ratio_min": _finite_or_text(ratio.min()),
                    "ratio_max": _finite_or_text(ratio.max())})
        out.append(entry)
    return out


HEADLINE = (
    ("2.1", "cco_distortion", None), ("2.2", "diffamp_distortion", None),
    ("2.3", "diffamp_em_distortion", None), ("2.4", "mosfet_distortion", None),
    ("3.1, 3.3", "mosfet_conduction", None), ("3.2, 3.4", "mosfet_saturation", None),
    ("3.5", "diffamp_ekf", None), ("4.1", "kronecker_table_4_1", None),
    ("4.2", "kronecker_table_4_2", None), ("4.3, 4.4", "kronecker_burden", None),
    ("5.1-5.12", "dipole_literal", None), ("5.1-5.12 (on the field)", "dipole_field",
                                           "KF RMSE < RLS RMSE"),
    ("FIR paper, Table II", "fir_differentiator", None),
    ("Kalman differentiator paper", "kalman_differentiator", None),
    ("passive-network paper", "passive_network", None),
    ("image papers", "image_kalman", "NSHP Kalman, adaptive MSE < NSHP Kalman MSE"),
)
"""The headline table's rows: the thesis or paper table, the experiment, and the claim that
is its headline (``None``: the experiment's first claim)."""


def headline_counts(df: pd.DataFrame, claim: str | None) -> tuple[pd.Series, int]:
    """Of a claims table: the family verdict counts of ``claim`` (``None``: the first
    claim), as :func:`estim.experiments.shared.claims.counts` gives them, and how many other
    claims it holds."""
    found = claims.counts(df)
    row = found.iloc[0] if claim is None else found[found["claim"] == claim].iloc[0]
    return row, len(found) - 1


def headline(results: Path) -> list[str]:
    """The headline table (Markdown): per row of :data:`HEADLINE`, the claim and its
    family-corrected verdict counts from the stored claims table, with the fragile cells
    and how many other claims the experiment judges."""
    lines = ["| thesis | experiment | headline claim | holds | fails | undecided | of cells "
             "| fragile | other claims |", "|---|---|---|---|---|---|---|---|---|"]
    fragile = fragility.read(results)
    for table, name, claim in HEADLINE:
        df = None
        if (results / name / "manifest.json").exists():
            df = open_stored(results / name, ANALYSES).table(claims.TABLE)
        if df is None:
            lines.append(f"| {table} | {name} | (no stored results) | | | | | | |")
            continue
        row, others = headline_counts(df, claim)
        moved = len(fragility.cells(fragile, name).get(row["claim"], set()))
        said = str(row["claim"]).replace("|", "\\|")
        lines.append(f"| {table} | `{name}` | {said} | {row[claims.HOLDS]} | "
                     f"{row[claims.FAILS]} | {row[claims.UNDECIDED]} | {row['cells']} | "
                     f"{moved} | {others} |")
    return lines


HEADLINE_BLOCK = re.compile(r"(<!-- headline -->\n)(?P<body>.*?)(<!-- /headline -->)", re.S)
"""The headline table's generated block in a Markdown file."""


BLOCK = re.compile(r"(<!-- summary: (?P<name>[A-Za-z0-9_.-]+) -->\n)(?P<body>.*?)"
                   r"(<!-- /summary -->)", re.S)
"""A generated block in a Markdown file: ``<!-- summary: NAME -->`` ... ``<!-- /summary -->``."""


def refresh(text: str, results: Path, analyses: dict) -> tuple[str, list[str]]:
    """``text`` with every summary block re-generated from ``results``, and the names of
    the blocks whose content changed (a stale file names them)."""
    stale = []
    made: dict[str, list[str]] = {}       # a name's lines once, however many blocks cite it

    def fill(match: re.Match) -> str:
        name = match.group("name")
        if name not in made:
            made[name] = experiment(results / name, analyses)
        lines = made[name]
        body = ("\n".join(lines) if lines else f"(no stored results for {name})") + "\n"
        if body != match.group("body"):
            stale.append(name)
        return match.group(1) + body + match.group(4)

    def fill_headline(match: re.Match) -> str:
        body = "\n".join(headline(results)) + "\n"
        if body != match.group("body"):
            stale.append("headline")
        return match.group(1) + body + match.group(3)

    text = HEADLINE_BLOCK.sub(fill_headline, text)
    return BLOCK.sub(fill, text), stale
