"""The top of the report page: the headline table, the summary of every experiment grouped
by chapter, and the legend that says what their columns mean. A failing claim is told apart
by what the thesis printed for the same cell (:func:`fail_kinds`): one the printed values
say holds is a disagreement to read; the others are findings."""

from __future__ import annotations

import html
import math
from typing import TYPE_CHECKING

from estim.report import fragility, tables
from estim.util import lazy

if TYPE_CHECKING:
    from estim.report.section import Section

pd = lazy.load("pandas")

AGAINST = "against_printed"
"""Failing cells whose printed values (both estimators') say the claim holds."""
AS_PRINTED = "as_printed"
"""Failing cells whose printed values fail the claim too."""
NOT_PRINTED = "not_printed"
"""Failing cells with no printed value for one side (the raw measurement, an estimator the
thesis does not run): findings of estim's own comparisons."""


def _cell(text_: str) -> dict[str, str]:
    """A claim's cell (``s_no=1; frequency_hz=100``) as ``{key: value}``."""
    out = {}
    for part in str(text_).split("; "):
        key, _, value = part.partition("=")
        out[key] = value
    return out


def _same(a, b) -> bool:
    try:
        return math.isclose(float(a), float(b), rel_tol=1e-9)
    except (TypeError, ValueError):
        return str(a) == str(b)


def printed_pair(frames: dict, cell: str, better: str, worse: str) -> tuple[float, float] | None:
    """The printed values of ``better`` and ``worse`` in a claim's cell: from the first
    table with an ``estimator`` column and one ``thesis_`` column whose rows of that cell
    (every cell key the table has, matched) hold one printed value for each; None where no
    table does."""
    keys = _cell(cell)
    for metric, df in frames.items():
        printed = [c for c in df.columns if c.startswith("thesis_")]
        if metric == "claims" or "estimator" not in df or len(printed) != 1:
            continue
        rows = df
        for key, value in keys.items():
            if key in rows:
                rows = rows[[_same(v, value) for v in rows[key]]]
        pair = [pd.to_numeric(rows[rows["estimator"] == side][printed[0]],
                              errors="coerce").dropna() for side in (better, worse)]
        if all(len(p) == 1 for p in pair):
            return float(pair[0].iloc[0]), float(pair[1].iloc[0])
    return None


def fail_kinds(section: Section, claim: str | None = None) -> dict[str, int]:
    """The failing claim cells (after Holm's correction) of an experiment (of one ``claim``
    where given), counted by what the thesis printed for the same cell: :data:`AGAINST`,
    :data:`AS_PRINTED`, :data:`NOT_PRINTED`."""
    frames = {metric: df for metric, _, df in section.tables}
    out = {AGAINST: 0, AS_PRINTED: 0, NOT_PRINTED: 0}
    claims = frames.get("claims")
    if claims is None or "verdict" not in claims:
        return out
    column = "verdict_family" if "verdict_family" in claims else "verdict"
    failing = claims[column].astype(str) == "fails"
    if claim is not None:
        failing &= claims["claim"].astype(str) == claim
    for row in claims[failing].itertuples(index=False):
        pair = printed_pair(frames, row.cell, row.better, row.worse)
        kind = NOT_PRINTED if pair is None else AGAINST if pair[0] < pair[1] else AS_PRINTED
        out[kind] += 1
    return out


def chapter(section: Section) -> str:
    """The group an experiment's summary row sits in: the thesis chapter of the tables it
    reproduces (their ``table_id``), the sister papers, or none printed."""
    ids = set()
    for _, _, df in section.tables:
        if "table_id" in df:
            ids |= {str(v) for v in df["table_id"].dropna() if str(v).strip()}
    chapters = sorted({i.split(".")[0] for i in ids if i[:1].isdigit()})
    if chapters:
        return "Chapter " + ", ".join(chapters)
    return "The sister papers" if ids else "No printed table"


def summary(section: Section) -> dict:
    """What the page's summary says of one experiment: its claims' verdict counts (the
    failing ones split by :func:`fail_kinds`), the number of cells beside a printed value
    and the range of ratio ours/printed, and its health flags (runs that diverged or broke;
    filter rows inconsistent in NEES)."""
    frames = {metric: df for metric, _, df in section.tables}
    out = {"holds": 0, "fails": 0, "undecided": 0, "printed": 0, "ratio": None, "flags": [],
           **fail_kinds(section)}
    claims = frames.get("claims")
    if claims is not None and "verdict" in claims:
        column = "verdict_family" if "verdict_family" in claims else "verdict"
        counts = claims[column].astype(str).value_counts()
        out.update({k: int(counts.get(k, 0)) for k in ("holds", "fails", "undecided")})
    ratios = []
    for df in frames.values():
        for column in (c for c in df.columns if c.startswith("thesis_")):
            value = column[len("thesis_"):]
            printed = pd.to_numeric(df[column], errors="coerce").notna()
            out["printed"] += int(printed.sum())
            if f"ratio_{value}" in df:
                r = pd.to_numeric(df[f"ratio_{value}"], errors="coerce")[printed]
                ratios += [float(x) for x in r if pd.notna(x) and abs(x) != float("inf")]
    if ratios:
        out["ratio"] = (min(ratios), max(ratios))
    if section.fragile:
        out["flags"].append(f"{section.fragile} fragile claim verdicts (moved by another "
                            "machine's arithmetic)")
    health = frames.get("health")
    if health is not None:
        for column, words in (("diverged", "diverged"), ("broken", "broke")):
            if column in health:
                n = int(pd.to_numeric(health[column], errors="coerce").fillna(0).sum())
                if n:
                    out["flags"].append(f"{n} runs {words} (summed over cells and filters)")
        if "nees_in_band" in health:
            band = pd.to_numeric(health["nees_in_band"], errors="coerce")
            low = int((band < 0.5).sum())
            if low:
                out["flags"].append(f"{low} of {int(band.notna().sum())} filter rows with "
                                    "NEES in its band in under half the runs")
    return out


def headline(sections: list[Section]) -> str:
    """The headline table, first on the page: per row of :data:`estim.report.summary.HEADLINE`
    (a thesis or paper table) its headline claim and that claim's verdicts after Holm's
    correction, as the README's generated table gives them."""
    from estim.report.summary import HEADLINE, headline_counts

    by_name = {s.name: s for s in sections}
    rows = []
    for table, name, claim in HEADLINE:
        s = by_name.get(name)
        df = next((d for m, _, d in s.tables if m == "claims"), None) if s else None
        if df is None or "verdict_family" not in df:
            continue
        row, _ = headline_counts(df, claim)
        moved = fragility.cells(s.fragile_cells, name).get(row["claim"], set()) \
            if s.fragile_cells is not None else set()
        kinds = fail_kinds(s, str(row["claim"]))
        link = f'<a href="#{html.escape(name)}">{html.escape(name)}</a>'
        rows.append(f'<tr><td class="text">{html.escape(table)}</td><td class="text">{link}'
                    f'</td><td class="text">{html.escape(str(row["claim"]))}</td>'
                    f'<td class="{"good" if row["holds"] else "num"}">{row["holds"]}</td>'
                    f'<td class="{"bad" if kinds[AGAINST] else "num"}">{row["fails"]}</td>'
                    f'<td class="num">{row["undecided"]}</td><td class="num">{row["cells"]}'
                    f'</td><td class="num">{len(moved)}</td>'
                    f'<td class="text">{html.escape(reading(row, kinds))}</td></tr>')
    if not rows:
        return ""
    head = ("<tr><th>thesis</th><th>experiment</th><th>headline claim</th><th>holds</th>"
            "<th>fails</th><th>undecided</th><th>of cells</th><th>fragile</th>"
            "<th>reading</th></tr>")
    return ('<h2 id="headline">What holds</h2><p class="meta">The headline claim of each '
            "thesis and paper table, judged over its cells (a condition of the printed table) by "
            "the paired runs of both estimators, at 95 % with Holm's correction within the "
            "claim; a fragile cell's verdict moves under another x86-64 machine's rounding. "
            "A fails count is red only where the printed values of both estimators say the "
            "claim holds in a failing cell. The summary below gives every experiment; each "
            "section every claim.</p>"
            f'<table class="headline"><thead>{head}</thead><tbody>{"".join(rows)}</tbody>'
            "</table>")


def reading(row, kinds: dict[str, int]) -> str:
    """A headline row in words: where its claim holds, fails (and whether the printed values
    say otherwise) and is undecided."""
    holds, fails, undecided, cells = (int(row[k]) for k in ("holds", "fails", "undecided",
                                                              "cells"))
    if holds == cells:
        return f"holds in every cell ({cells})"
    parts = [f"holds in {holds} of {cells} cells"]
    if fails:
        against = kinds[AGAINST]
        parts.append(f"fails in {fails}, " + (
            "where the printed values say it holds" if against == fails else
            f"{against} of them where the printed values say it holds" if against else
            "where no value is printed for one side, or the printed values fail too"))
    if undecided:
        parts.append(f"{undecided} undecided")
    return "; ".join(parts)


LEGEND = (
    ("holds / fails / undecided", "claim cells (a condition of the printed table) by their "
     "verdict after Holm's correction within each claim: the paired runs of both estimators "
     "on the same noise draws, at 95 % (docs/claims.md)."),
    ("against the printed", "failing cells where the printed values of both estimators say "
     "the claim holds: a disagreement with the thesis, the ones to read first (red)."),
    ("findings", "the other failing cells: the thesis prints no value for one side (the raw "
     "measurement, the UKF, a fitted Q: estim's own comparisons), or its printed values fail "
     "the claim too. A filter worse than the raw measurement at a noise level is such a "
     "finding: often the point of the table, not a fault."),
    ("cells beside a printed value", "table cells that have a printed value next to ours."),
    ("ratio ours/printed", "our value over the printed one, lowest to highest over those "
     "cells: 1 is agreement; a range reaching far from 1 means some cell differs by that "
     "factor. Each experiment's tables show the ratio per cell, and the deviations it cites "
     "say why (a printed value that cannot be reproduced, a filter that diverged)."),
    ("health", "runs that diverged (counted, never dropped) and filter rows whose NEES sits "
     "in its consistency band in under half of the runs."),
)
"""The summary's columns, in words, as the page's legend gives them."""


def legend() -> str:
    return ('<dl class="legend">' + "".join(
        f"<dt>{html.escape(term)}</dt><dd>{html.escape(words)}</dd>" for term, words in LEGEND)
        + "</dl>")


def summary_table(sections: list[Section]) -> str:
    """Every experiment, grouped by :func:`chapter`: its title, claim verdicts (the failing
    ones split by :func:`fail_kinds`), printed cells, ratio range and health, then the
    legend."""
    head = ("<tr><th>experiment</th><th>holds</th><th>fails</th><th>undecided</th>"
            "<th>against the printed</th><th>findings</th><th>cells beside a printed value"
            "</th><th>ratio ours/printed</th><th>health</th></tr>")
    groups: dict[str, list[str]] = {}
    for s in sections:
        v = summary(s)
        ratio = (f"{tables.number(v['ratio'][0])} to {tables.number(v['ratio'][1])}"
                 if v["ratio"] else "--")
        link = (f'<a href="#{html.escape(s.name)}">{html.escape(s.name)}</a>'
                f'<br><span class="what">{html.escape(s.title)}</span>')
        findings = v[AS_PRINTED] + v[NOT_PRINTED]
        groups.setdefault(chapter(s), []).append(
            f'<tr data-name="{html.escape(s.name)}"><td class="text">{link}</td>'
            f'<td class="{"good" if v["holds"] else "num"}">{v["holds"]}</td>'
            f'<td class="num">{v["fails"]}</td><td class="num">{v["undecided"]}</td>'
            f'<td class="{"bad" if v[AGAINST] else "num"}">{v[AGAINST]}</td>'
            f'<td class="num">{findings}</td><td class="num">{v["printed"]}</td>'
            f'<td class="num">{ratio}</td>'
            f'<td class="text">{html.escape("; ".join(v["flags"]) or "--")}</td></tr>')
    order = sorted(groups, key=lambda g: (not g.startswith("Chapter"), g))
    bodies = "".join(f'<tbody><tr class="group"><th colspan="9">{html.escape(g)}</th></tr>'
                     + "".join(groups[g]) + "</tbody>" for g in order)
    return ('<h2 id="summary">Summary</h2><p class="meta">Every experiment by the chapter '
            "of the tables it reproduces; the legend below the table says what each column "
            "counts.</p>"
            f'<table class="summary sortable"><thead>{head}</thead>{bodies}</table>'
            + legend())
