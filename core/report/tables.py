"""Rendering result tables for the terminal, Markdown, CSV and LaTeX, with the thesis' rows
beside ours (:mod:`estim.reference` joins them). Tables are plain columns
(:class:`estim.util.columns.Table`), so ``estim table`` runs without pandas; a DataFrame given
to :func:`render` is read into one.
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

from estim.errors import ReferenceJoinError
from estim.reference import join_reference, sweep_columns, view
from estim.util.columns import Table, is_missing

TEXT_WIDTH = 100
"""``estim table``'s text output wraps its columns into blocks of at most this many
characters."""

_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                  "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
                  "^": r"\textasciicircum{}", "<": r"\textless{}", ">": r"\textgreater{}",
                  "|": r"\textbar{}"}


def latex_escape(text_: str) -> str:
    """``text_`` with LaTeX's special characters escaped."""
    return "".join(_LATEX_SPECIAL.get(c, c) for c in str(text_))


def number(value) -> str:
    """A cell: integers (a frequency, a count) in full, other numbers to 4 significant
    digits, missing values as ``--``."""
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return "--"
        if math.isfinite(v) and v == round(v) and abs(v) < 1e9:
            return str(int(round(v)))
        return f"{v:.4g}"
    if is_missing(value):
        return "--"
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return str(value)


def text_blocks(columns: list[list[str]], width: int = TEXT_WIDTH) -> str:
    """Columns of cell strings (each headed by its name) as text: right-justified, one space
    apart, wrapped into blocks of at most ``width`` characters, a block that continues ending
    its lines in `` \\``. The layout of pandas' ``to_string(index=False, line_width=width)``
    for string cells, without its cut of cells over 50 characters; written out because
    pandas' formatter took half of ``estim table rmse``'s time on 3,000 rows."""
    fixed = []
    for column in columns:
        w = max(map(len, column))
        fixed.append([cell.rjust(w) for cell in column])
    widths = [len(column[0]) for column in fixed]
    ends, used = [], 0
    for i, w in enumerate(widths):
        used += w + 1
        if i > 0 and used + (1 if i == len(widths) - 1 else 2) > width:
            ends.append(i)
            used = w + 1
    ends.append(len(widths))
    rows, blocks, start = len(fixed[0]), [], 0
    for k, end in enumerate(ends):
        block = fixed[start:end]
        if len(ends) > 1:
            block = [*block, [" \\"] + ["  "] * (rows - 1) if k < len(ends) - 1
                     else [" "] * rows]
        lines = [" ".join(cells[:-1]) + " " + cells[-1] if len(cells) > 1 else cells[0]
                 for cells in zip(*block, strict=True)]
        blocks.append("\n".join(lines))
        start = end
    return "\n\n".join(blocks)


def render(table, fmt: str) -> str:
    """Text (wrapped at :data:`TEXT_WIDTH`), CSV, Markdown or LaTeX (booktabs, escaped)
    rendering of a table (a :class:`Table` or a DataFrame)."""
    if not isinstance(table, Table):
        table = Table.from_frame(table)
    if fmt == "csv":
        return table.to_csv()
    if fmt == "text" and len(table) and table.names:
        return text_blocks([[str(name), *map(number, table[name])] for name in table.names])
    if fmt == "text":
        return table.to_frame().to_string(index=False, line_width=TEXT_WIDTH)
    rows = [[number(v) for v in row] for row in table.rows()] if table.names else []
    numeric = [table.kinds[c] in "if" for c in table.names]
    if fmt == "markdown":
        from tabulate import tabulate

        return tabulate(rows, headers=table.names, tablefmt="pipe", disable_numparse=True,
                        colalign=["right" if n else "left" for n in numeric],
                        showindex=False)
    head = " & ".join(latex_escape(c) for c in table.names)
    body = [" & ".join(latex_escape(v) for v in row) + r" \\" for row in rows]
    align = "".join("r" if n else "l" for n in numeric)
    return "\n".join(["% needs \\usepackage{booktabs}", f"\\begin{{tabular}}{{{align}}}",
                      r"\toprule", head + r" \\", r"\midrule", *body, r"\bottomrule",
                      r"\end{tabular}"]) + "\n"


def _distinct(values) -> int:
    """How many different values, a missing one counted once (``nunique(dropna=False)``)."""
    return len({None if is_missing(v) else v for v in values})


def fit(df: Table, spec, width: int) -> tuple[Table, list[str]]:
    """``df`` cut to ``width`` characters of text, and the notes saying how: a column with
    one value in every row is said once in a note, a key the other keys determine (a
    table id, a zone's βr) is left out; then the table's keys, each printed value with the
    thesis' value and the ratio beside it, the words (a verdict), and the other values in
    their order, as many as fit (a text cell as :func:`number` writes it, one space apart); the
    values left out are named in a note. The keys stay even where they alone are wider
    (:func:`text_blocks` then wraps). ``width`` 0: nothing is cut."""
    if width <= 0 or not len(df):
        return df, []
    notes = []
    same = [c for c in df.names if _distinct(df[c]) <= 1]
    if same and len(df) > 1:
        notes.append("in every row: " + ", ".join(f"{c} = {number(df[c][0])}" for c in same))
        df = df.drop(same)
    keys = [c for c in df.names if c in spec.keys or c.startswith(("sweep:",))]
    implied = []
    for k in list(keys):
        others = [c for c in keys if c != k and c not in implied]
        if others and _determined(df, others, k):
            implied.append(k)
    if implied:
        notes.append(f"{', '.join(implied)}: given by the other keys, left out")
        df = df.drop(implied)
        keys = [k for k in keys if k not in implied]
    df, shortened = _shorten_keys(df, keys, KEYS_SHARE * width)
    if shortened:
        notes.append(f"long cells of {', '.join(shortened)} shortened (…)")
    printed = [c for r in spec.reference for c in (r, f"thesis_{r}", f"ratio_{r}")
               if c in df]
    words = [c for c in spec.text if c in df]
    first = keys + printed + words
    order = first + [c for c in df.names if c not in first]

    def cost(c: str) -> int:
        return max(len(str(c)), *(len(number(v)) for v in df[c])) + 1
    used, shown, dropped = 0, [], []
    for c in order:
        if c in keys or used + cost(c) <= width:
            shown.append(c)
            used += cost(c)
        else:
            dropped.append(c)
    if dropped:
        notes.append(f"left out for a width of {width}: {', '.join(dropped)} "
                     "(--width 0 or --format csv shows every column)")
    return df.select(shown), [textwrap.fill(n, width - 2, break_on_hyphens=False)
                              for n in notes]


def _determined(df: Table, others: list[str], k: str) -> bool:
    """Whether the columns ``others`` determine ``k``: one value of ``k`` (a missing one
    counted as a value) in each group of rows alike in ``others``."""
    seen: dict = {}
    for row, value in zip(df.rows(others), df[k], strict=True):
        group = tuple(None if is_missing(v) else v for v in row)
        seen.setdefault(group, set()).add(None if is_missing(value) else value)
    return max(map(len, seen.values()), default=0) <= 1


KEYS_SHARE = 0.6
"""The share of the width the keys may take before their longest text cells are shortened."""

SHORTEST = 12
"""No text cell is shortened below this many characters."""


def _shorten_keys(df: Table, keys: list[str], room: float) -> tuple[Table, list]:
    """``df`` with the text cells of its widest key columns cut (ending in "…") until the
    keys take at most ``room`` characters or no column can be cut further (none is cut so
    far that two of its cells would read the same); the columns cut."""
    cut, whole = [], set()
    while True:
        cells = {k: max(len(number(v)) for v in df[k]) for k in keys}
        widths = {k: max(len(k), cells[k]) + 1 for k in keys}
        if sum(widths.values()) <= room:
            return df, cut
        floor = {k: max(len(k), SHORTEST) for k in keys}
        text_keys = [k for k in keys if df.kinds[k] not in "ifb"
                     and cells[k] > floor[k] and k not in whole]
        if not text_keys:
            return df, cut
        k = max(text_keys, key=cells.get)
        limit = max(floor[k], cells[k] - (sum(widths.values()) - int(room)))
        short = [v if len(str(v)) <= limit else str(v)[:limit - 1] + "…" for v in df[k]]
        if len(set(short)) < len({v for v in df[k] if not is_missing(v)}):
            whole.add(k)                              # two cells would read the same
            continue
        df = df.with_column(k, short, "O")
        if k not in cut:
            cut.append(k)


def stored(results, metric: str, fmt: str, thesis: bool, partial: bool,
           analyses: dict, only: tuple[str, ...] = (), width: int = 0) -> str:
    """What ``estim table`` prints: the ``metric`` tables of every experiment stored under
    ``results`` in ``fmt`` (text, csv, markdown, latex), with the printed values and the
    ratios beside ours when ``thesis``. csv is one table over all experiments (an
    ``experiment`` column first); the others one table per experiment under its title.
    ``only``: just these experiments (folder names; only their analyses are loaded);
    ``width``: text cut to it (:func:`fit`). With ``thesis``, the experiments with
    no printed table are left out and named in one closing line (the only line when no
    experiment has one). A thesis join that fails, an experiment of ``only`` that holds no
    such table, or no values at all, is a ``UsageError``."""
    from estim.config.settings import did_you_mean
    from estim.errors import UsageError
    from estim.store import stored_tables

    found = list(stored_tables(results, metric, analyses, only))
    names = [stored.name for stored, _ in found]
    for name in only:
        if name not in names:
            names = [stored.name for stored, _ in stored_tables(results, metric, analyses)]
            raise UsageError(f"{name}: no stored {metric} table under {results}/"
                             f"{did_you_mean(name, names)}; experiments with one: "
                             f"{', '.join(sorted(names)) or 'none'}")
    parts, frames, unprinted = [], [], []
    for stored, spec in found:
        folder, path = stored.folder, stored.table_path(spec)
        df = view(stored.columns(spec), spec)
        values = df.drop([*spec.keys, *sweep_columns(df)])
        if all(is_missing(v) for c in values.names for v in values[c]):
            continue
        printed = spec.join and "table_id" in df and any(len(str(t)) for t in df["table_id"])
        if thesis and not printed:
            unprinted.append(folder.name)
            continue
        if thesis and spec.join and "table_id" in df:
            try:
                df = join_reference(df, spec, allow_unmatched=partial)
            except ReferenceJoinError as exc:
                raise UsageError(f"{path}: {exc}") from None
        if fmt == "csv":
            frames.append(Table({"experiment": [folder.name] * len(df), **df.columns},
                                {"experiment": "O", **df.kinds}))
            continue
        ids = ", ".join(sorted({str(t) for t in (df["table_id"] if "table_id" in df else [])
                                if t},
                               key=lambda t: [int(x) if x.isdigit() else x
                                              for x in t.split(".")]))
        note = f" (thesis Table {ids})" if ids else ""
        title = f"{folder.name}: {spec.title}" if spec.title else folder.name
        head = {"text": f"== {title}{note}", "markdown": f"### {title}{note}\n"}.get(
            fmt, f"% {latex_escape(title + note)}")
        notes: list[str] = []
        if fmt == "text":
            df, notes = fit(df, spec, width)
            if width > 0:
                head = textwrap.fill(head, width, subsequent_indent="   ",
                                     break_on_hyphens=False)
        parts.append(f"{head}\n" + "".join(f"({n})\n" for n in notes) + render(df, fmt))
    if frames:
        parts.append(render(Table.concat(frames), "csv").rstrip("\n"))
    if unprinted and (parts or not frames) and fmt != "csv":
        parts.append(f"(--thesis: left out {len(unprinted)} experiment(s) with no printed "
                     f"{metric} table to compare with: {', '.join(unprinted)}; leave out "
                     "--thesis to see them)")
    if not parts:
        if (Path(results) / "manifest.json").exists():
            raise UsageError(f"{results} is one experiment's folder; give the folder that "
                             "holds it (--results PARENT)")
        raise UsageError(f"no {metric} values under {results}/ (run 'estim reproduce')")
    return "\n".join(parts)
