"""One self-contained HTML page of stored results (``estim report``), the page a reader opens
first. At the top, a summary: per experiment its claims' verdicts (holds / fails /
undecided, from claims.csv), how many of its cells sit beside a printed value and the range
of their ratios, and its health flags (runs that diverged, filters outside the NEES band),
each linking to the experiment's section. Per experiment: its tables (ours beside the printed
values and their ratio; rows where a claim fails in red; a table with no value at all is
named, not drawn), its figures (shrunk, captioned in words, a twin's look-alike named
instead of drawn again: :mod:`estim.report.figures`; tables cut to :data:`ROWS_MAX` rows; unless
``full``: the page of the shipped results stays under 3 MB), the deviations its config cites
rendered from their markdown, and the seeds and versions of its manifest. A table of
contents stays in view. :func:`sections` reads a results folder; :func:`page` writes no file.
"""

from __future__ import annotations

import base64
import html
import re

from estim import reference
from estim.errors import UsageError
from estim.report import figures, fragility, overview, tables
from estim.report.section import Section
from estim.util import lazy

pd = lazy.load("pandas")

STYLE = """
body { font-family: sans-serif; margin: 0; color: #222; display: flex; }
nav#toc { position: sticky; top: 0; align-self: flex-start; height: 100vh; overflow-y: auto;
  min-width: 15em; max-width: 17em; padding: 1em; background: #f7f7f7;
  border-right: 1px solid #ddd; font-size: 0.85em; box-sizing: border-box; }
nav#toc a { display: block; margin: 0.15em 0; text-decoration: none; color: #134; }
main { padding: 1em 2em; max-width: 110em; min-width: 0; }
h1 { font-size: 1.6em; } h2 { margin-top: 2.2em; border-bottom: 1px solid #bbb; }
table.summary td.bad { background: #f8d0d0; } table.summary td.good { background: #d8efd8; }
.deviation { border-left: 3px solid #bbb; padding-left: 0.8em; font-size: 0.9em; }
table { border-collapse: collapse; font-size: 0.8em; margin: 0.6em 0 1.2em; }
th, td { border: 1px solid #ccc; padding: 0.15em 0.45em; text-align: right; }
th { background: #f0f0f0; } td.t, td.text { text-align: left; }
tr.fail td { background: #f8d0d0; } .meta { color: #555; font-size: 0.85em; }
figure { display: block; margin: 1em 0; } figure img { max-width: min(100%, 45em); }
figcaption { font-size: 0.9em; color: #333; max-width: 45em; }
figcaption code { color: #777; font-size: 0.85em; }
table.summary tr.group th, table.summary thead th:first-child { text-align: left; }
table.summary tr.group th { background: #e4e8ee; }
table.summary span.what { color: #555; font-size: 0.9em; }
dl.legend { font-size: 0.85em; color: #333; max-width: 62em; }
dl.legend dt { font-weight: bold; margin-top: 0.4em; } dl.legend dd { margin-left: 1.5em; }
input.filter { font-size: 0.85em; margin: 0.3em 0; width: 20em; }
table.sortable thead th { cursor: pointer; } pre { white-space: pre-wrap; font-size: 0.85em; }
div.scroll { overflow: auto; max-width: 100%; max-height: 36em; margin: 0.6em 0 1.2em; }
div.scroll table { margin: 0; }
table.data thead th { position: sticky; top: 0; z-index: 1; }
table.data td:first-child, table.data th:first-child { position: sticky; left: 0;
  background: #fafafa; }
table.data thead th:first-child { z-index: 2; background: #f0f0f0; }
table.headline td.bad { background: #f8d0d0; } table.headline td.good { background: #d8efd8; }
"""

ROWS_MAX = 30
"""Rows of a table drawn unless ``full``: the CSV holds them all."""


MEDIA = {"png": "image/png", "svg": "image/svg+xml"}

SCRIPT = """
for (const box of document.querySelectorAll('input.filter')) {
  const table = box.nextElementSibling.querySelector('table');
  box.addEventListener('input', () => {
    const words = box.value.toLowerCase();
    for (const row of table.tBodies[0].rows)
      row.hidden = words !== '' && !row.textContent.toLowerCase().includes(words);
  });
}
for (const table of document.querySelectorAll('table.sortable')) {
  table.tHead.rows[0].querySelectorAll('th').forEach((th, col) => {
    th.title = 'sort by this column';
    th.addEventListener('click', () => {
      const up = th.dataset.order !== 'up';
      th.dataset.order = up ? 'up' : 'down';
      const key = row => {
        const text = row.cells[col] ? row.cells[col].textContent.trim() : '';
        const number = parseFloat(text);
        return isNaN(number) ? text.toLowerCase() : number;
      };
      for (const body of table.tBodies) {
        const rows = [...body.rows].filter(r => !r.classList.contains('group'));
        rows.sort((a, b) => {
          const x = key(a), y = key(b);
          const order = typeof x === typeof y ? (x < y ? -1 : x > y ? 1 : 0)
                                              : (typeof x === 'number' ? -1 : 1);
          return up ? order : -order;
        });
        for (const row of rows) body.appendChild(row);
      }
    });
  });
}
"""
"""The page's one script, offline: a filter box above each data table (rows containing
the words typed stay), and a click on a column heading sorts the rows by it (numbers as
numbers; the summary within each chapter)."""


def deviation_entries(markdown: str) -> dict[str, str]:
    """``{"D12": text}`` from the pages of docs/deviations/: each entry runs from its bold
    ``**D12.`` to the next entry or heading (the anchor line before each entry left out)."""
    out: dict[str, str] = {}
    current, lines = None, []
    for line in markdown.splitlines():
        if re.fullmatch(r'<a id="d\d+"></a>', line):       # the docs site's anchor
            continue
        match = re.match(r"\*\*(D\d+)\.", line)
        if match or line.startswith("#"):
            if current:
                out[current] = "\n".join(lines).strip()
            current, lines = (match.group(1), [line]) if match else (None, [])
        elif current:
            lines.append(line)
    if current:
        out[current] = "\n".join(lines).strip()
    return out


def cited(text_: str) -> list[str]:
    """The deviation numbers a config's text cites (``D12``, ``D44-D47``), in order."""
    found: list[str] = []
    for a, b in re.findall(r"\bD(\d+)(?:\s*[-\u2013]\s*D?(\d+))?\b", text_):
        for n in range(int(a), int(b or a) + 1):
            if f"D{n}" not in found:
                found.append(f"D{n}")
    return found


def _table(caption: str, df: pd.DataFrame, source: str = "", rows_max: int | None = None) -> str:
    """A table as HTML; with ``rows_max``, at most that many rows (for claims, chosen from
    the rows that do not hold first; shown in the table's order) and a line naming the CSV
    that holds them all."""
    failing = (df["verdict"].astype(str) == "fails") if "verdict" in df else None
    note = ""
    if rows_max is not None and len(df) > rows_max:
        order = (df.index[df["verdict"].astype(str) != "holds"].tolist()
                 + df.index[df["verdict"].astype(str) == "holds"].tolist()
                 if "verdict" in df else df.index.tolist())
        shown = sorted(order[:rows_max])
        note = (f'<p class="meta">{rows_max} of {len(df)} rows shown'
                + (" (chosen from the claims that do not hold first)" if "verdict" in df else "")
                + f"; all of them in {html.escape(source)} and in "
                "<code>estim report --full</code>.</p>")
        df, failing = df.loc[shown], failing.loc[shown] if failing is not None else None
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    rows = []
    for i, row in enumerate(df.itertuples(index=False)):
        cells = "".join(("<td class=t>" if isinstance(v, str) else "<td>")
                        + html.escape(tables.number(v)) + "</td>" for v in row)
        cls = ' class="fail"' if failing is not None and bool(failing.iloc[i]) else ""
        rows.append(f"<tr{cls}>{cells}</tr>")
    return (f'<h3>{html.escape(caption)}</h3><input class="filter" type="search" '
            'placeholder="show rows containing ..." aria-label="filter rows">'
            '<div class="scroll"><table class="data sortable"><thead>'
            f"<tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table></div>{note}")


def _meta(manifest: dict) -> str:
    """Seed, runs, wall time, command, commit, overrides and versions; what the manifest
    does not hold (an analysis without Monte Carlo has no seed) is left out."""
    versions = manifest.get("versions") or {}
    parts = [f"{label} {html.escape(str(manifest[key]))}{unit}"
             for key, label, unit in (("seed", "seed", ""), ("runs", "runs", ""),
                                      ("wall_time_s", "wall time", " s"))
             if manifest.get(key) is not None]
    if manifest.get("command"):
        parts.append(f"command <code>{html.escape(str(manifest['command']))}</code>")
    if manifest.get("git_commit"):
        parts.append(f"commit {html.escape(str(manifest['git_commit']))}")
    if manifest.get("overrides"):
        parts.append(f"overrides {html.escape(str(manifest['overrides']))}")
    if versions:
        parts.append("versions " + html.escape(", ".join(f"{k} {v}" for k, v in
                                                          sorted(versions.items()))))
    return '<p class="meta">' + "; ".join(parts) + "</p>"


def _inline(text_: str) -> str:
    """The inline markdown docs/deviations.md uses: ``**bold**``, ``*emphasis*``,
    `` `code` `` and ``[text](#anchor)`` (a link elsewhere is shown as its text)."""
    out = html.escape(text_, quote=False)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", out)
    out = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", out)
    return re.sub(r"\[([^\]]+)\]\((#[^)\s]*)\)", r'<a href="\2">\1</a>',
                  re.sub(r"\[([^\]]+)\]\((?!#)[^)]*\)", r"\1", out))


def markdown(text_: str) -> str:
    """A deviation's markdown as HTML: paragraphs, ``-`` lists (an indented line continues
    its item) and the inline forms of :func:`_inline`."""
    blocks, para, items = [], [], []

    def close() -> None:
        if para:
            blocks.append(f"<p>{_inline(' '.join(para))}</p>")
            para.clear()
        if items:
            blocks.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in items) + "</ul>")
            items.clear()

    for line in text_.splitlines():
        stripped = line.strip()
        if not stripped:
            close()
        elif re.match(r"^\s*[-*] ", line):
            if para:
                close()
            items.append(stripped[2:])
        elif items and line.startswith((" ", "\t")):
            items[-1] += " " + stripped
        else:
            if items:
                close()
            para.append(stripped)
    close()
    return "\n".join(blocks)


def _has_values(df: pd.DataFrame) -> bool:
    """Whether a table holds any value (a cell that is neither missing, empty nor ``--``)."""
    return any(pd.notna(v) and str(v).strip() not in ("", "--")
               for column in df.columns for v in df[column])


def page(title: str, sections: list[Section], full: bool = False) -> str:
    """The whole page as one string (UTF-8 HTML5, no external resources); with ``full``
    every PNG as stored, else shrunk (:func:`estim.report.figures.shrink_png`)."""
    headline = overview.headline(sections)
    toc = ['<nav id="toc"><strong>Contents</strong>'
           + ('<a href="#headline">What holds</a>' if headline else "")
           + '<a href="#summary">Summary</a>']
    toc += [f'<a href="#{html.escape(s.name)}">{html.escape(s.name)}</a>' for s in sections]
    toc.append("</nav>")
    body = [headline, overview.summary_table(sections)]
    shown_as = {} if full else figures.alike([(s.name, s.figures) for s in sections])
    for s in sections:
        part = [f'<h2 id="{html.escape(s.name)}">{html.escape(s.name)}: '
                f"{html.escape(s.title)}</h2>", _meta(s.manifest)]
        empty = s.empty + [caption for _, caption, df in s.tables if not _has_values(df)]
        part += [_table(caption, df, f"results/{s.name}/{metric}.csv",
                        None if full else ROWS_MAX)
                 for metric, caption, df in s.tables if _has_values(df)]
        if empty:
            part.append('<p class="meta">Left out, no values in any cell: '
                        + html.escape("; ".join(empty)) + "</p>")
        skipped, alike = [], []
        for name, data in s.figures:
            kind = MEDIA.get(name.rpartition(".")[2])
            if kind is None:
                skipped.append(name)
                continue
            if (s.name, name) in shown_as:
                alike.append(f"{name} (as {shown_as[s.name, name]}'s)")
                continue
            caption = figures.caption(data) if kind == "image/png" else ""
            if kind == "image/png" and not full:
                try:
                    kind, data = figures.shrink_png(data)
                except (OSError, ValueError, SyntaxError):     # PIL's errors for junk
                    raise UsageError(f"{s.name}/figures/{name} (under the results folder): "
                                     "not a readable PNG image") from None
            encoded = base64.b64encode(data).decode("ascii")
            part.append(f'<figure><img alt="{html.escape(caption or name)}" '
                        f'data-file="{html.escape(name)}" '
                        f'src="data:{kind};base64,{encoded}"><figcaption>'
                        f"{html.escape(caption)} <code>{html.escape(name)}</code>"
                        "</figcaption></figure>")
        if alike:
            part.append('<p class="meta">Not drawn again, the same to the eye as the figure '
                        "of the same name shown in another section (their images differ by "
                        f"under {figures.ALIKE:.1%} on average; every figure is drawn with "
                        "--full): " + html.escape(", ".join(alike)) + "</p>")
        if skipped:
            part.append('<p class="meta">Not shown (a browser page cannot embed PDF as an '
                        "image; re-run with --figure-format png or svg): "
                        + html.escape(", ".join(skipped)) + "</p>")
        if s.deviations:
            part.append("<h3>Deviations this config cites (docs/deviations/)</h3>")
            part += [f'<div class="deviation" id="{html.escape(s.name)}-{number}">'
                     f"{markdown(text_)}</div>" for number, text_ in s.deviations]
        body.append("\n".join(part))
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
            + "".join(toc) + f"<main><h1>{html.escape(title)}</h1>\n" + "\n".join(body)
            + f"\n</main><script>{SCRIPT}</script></body></html>\n")


def sections(results, deviations_text: str, config_dir, analyses: dict) -> list[Section]:
    """One :class:`Section` per experiment stored under ``results``: its tables (joined to
    the printed values where there are any), figures, and the deviations (from the text of
    docs/deviations.md) its config in ``config_dir`` cites. A manifest that cannot be read
    is a ``UsageError`` naming it."""
    from pathlib import Path

    from estim.errors import ReferenceJoinError
    from estim.store import MAX_FIGURE_BYTES, read_run_record, stored_folders

    entries = deviation_entries(deviations_text) if deviations_text else {}
    fragile = fragility.read(Path(results))
    out = []
    for stored in stored_folders(Path(results), analyses):
        folder, config, manifest = stored.folder, stored.config, stored.manifest
        section = Section(folder.name, str(config.get("title") or ""),
                          {**manifest, **read_run_record(folder)},
                          fragile=sum(map(len, fragility.cells(fragile, folder.name).values())),
                          fragile_cells=fragile)
        for metric, spec in stored.analysis.TABLES.items():
            df = stored.table(spec)
            if df is None:
                continue
            df = reference.view(df, spec)
            caption = f"{metric}: {spec.title}"
            values = df.drop(columns=[*spec.keys, *reference.sweep_columns(df)], errors="ignore")
            if values.isna().all().all():             # ours are empty, printed ones or not
                section.empty.append(caption)
                continue
            if spec.join and "table_id" in df and df["table_id"].astype(str).str.len().any():
                try:
                    df = reference.with_reference(df, spec, allow_unmatched=True)
                except ReferenceJoinError:
                    pass
            section.tables.append((metric, caption, df))
        for figure in stored.figures():
            section.figures.append((figure.name,
                                    stored.read(figure, MAX_FIGURE_BYTES, "figure")))
        source = Path(config_dir) / f"{folder.name}.yaml" if config_dir else None
        text_ = source.read_text() if source is not None and source.is_file() else ""
        section.deviations = [(d, entries[d]) for d in cited(text_) if d in entries]
        out.append(section)
    return out
