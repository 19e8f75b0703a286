"""Rendering result tables for the terminal, Markdown, CSV and LaTeX, with the thesis' rows
beside ours (:mod:`estim.reference` joins them).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from estim.errors import ReferenceJoinError
from estim.reference import sweep_columns, view, with_reference
from estim.util import lazy

pd = lazy.load("pandas")

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
    if value is None or value is pd.NA:
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


def render(df: pd.DataFrame, fmt: str) -> str:
    """Text (wrapped at :data:`TEXT_WIDTH`), CSV, Markdown or LaTeX (booktabs, escaped)
    rendering of a table."""
    if fmt == "csv":
        return df.to_csv(index=False)
    if fmt == "text" and len(df) and len(df.columns):
        return text_blocks([[str(name), *map(number, df[name].tolist())] for name in df.columns])
    cells = df.astype(object).map(number) if len(df) else df.astype(object)
    if fmt == "markdown":
        align = ["right" if df[c].dtype.kind in "iuf" else "left" for c in df.columns]
        return cells.to_markdown(index=False, disable_numparse=True, colalign=align)
    if fmt == "latex":
        head = " & ".join(latex_escape(c) for c in df.columns)
        body = [" & ".join(latex_escape(v) for v in row) + r" \\" for row in cells.to_numpy()]
        align = "".join("r" if df[c].dtype.kind in "iuf" else "l" for c in df.columns)
        return "\n".join(["% needs \\usepackage{booktabs}", f"\\begin{{tabular}}{{{align}}}",
                          r"\toprule", head + r" \\", r"\midrule", *body, r"\bottomrule",
                          r"\end{tabular}"]) + "\n"
    return cells.to_string(index=False, line_width=TEXT_WIDTH)


def stored(results, metric: str, fmt: str, thesis: bool, partial: bool,
           analyses: dict, only: tuple[str, ...] = ()) -> str:
    """What ``estim table`` prints: the ``metric`` tables of every experiment stored under
    ``results`` in ``fmt`` (text, csv, markdown, latex), with the printed values and the
    ratios beside ours when ``thesis``. csv is one table over all experiments (an
    ``experiment`` column first); the others one table per experiment under its title.
    ``only``: just these experiments (folder names). With ``thesis``, the experiments with
    no printed table are left out and named in one closing line (the only line when no
    experiment has one). A thesis join that fails, an experiment of ``only`` that holds no
    such table, or no values at all, is a ``UsageError``."""
    from estim.config.settings import did_you_mean
    from estim.errors import UsageError
    from estim.store import read_table, stored_tables

    found = list(stored_tables(results, metric, analyses))
    names = [folder.name for folder, _, _ in found]
    for name in only:
        if name not in names:
            raise UsageError(f"{name}: no stored {metric} table under {results}/"
                             f"{did_you_mean(name, names)}; experiments with one: "
                             f"{', '.join(sorted(names)) or 'none'}")
    parts, frames, unprinted = [], [], []
    for folder, spec, path in found:
        if only and folder.name not in only:
            continue
        df = view(read_table(path, spec), spec)
        values = df.drop(columns=[*spec.keys, *sweep_columns(df)], errors="ignore")
        if values.isna().all().all():
            continue
        printed = spec.join and "table_id" in df and df["table_id"].astype(str).str.len().any()
        if thesis and not printed:
            unprinted.append(folder.name)
            continue
        if thesis and spec.join and "table_id" in df:
            try:
                df = with_reference(df, spec, allow_unmatched=partial)
            except ReferenceJoinError as exc:
                raise UsageError(f"{path}: {exc}") from None
        if fmt == "csv":
            frames.append(df.assign(experiment=folder.name)[["experiment", *df.columns]])
            continue
        ids = ", ".join(sorted({str(t) for t in df.get("table_id", []) if t}))
        note = f" (thesis Table {ids})" if ids else ""
        title = f"{folder.name}: {spec.title}" if spec.title else folder.name
        head = {"text": f"== {title}{note}", "markdown": f"### {title}{note}\n"}.get(
            fmt, f"% {latex_escape(title + note)}")
        parts.append(f"{head}\n{render(df, fmt)}")
    if frames:
        parts.append(render(pd.concat(frames, ignore_index=True), "csv").rstrip("\n"))
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
