"""Generic table code: the reference tables, joining ours to them, rendering.

Nothing here knows an analysis: each declares its tables as :class:`TableSpec` and this
module joins and renders whatever it is given.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np

from estim import lazy
from estim.analyses.base import TableSpec
from estim.errors import ReferenceJoinError

pd = lazy.load("pandas")

OWN_TABLE = "ours"
"""``tables.<metric>: ours`` in a config writes the table without naming a thesis table (a
study that extends one); its ``table_id`` column is left empty."""


def _reference_name(table_id: str) -> str:
    return "table_" + table_id.replace(".", "_") + ".csv"


def has_reference_table(table_id: str) -> bool:
    return resources.files("estim.reference").joinpath(_reference_name(table_id)).is_file()


def reference_table(table_id: str) -> pd.DataFrame:
    """A reference (thesis) table as printed, shipped in :mod:`estim.reference`."""
    with resources.files("estim.reference").joinpath(_reference_name(table_id)).open("r") as fh:
        return pd.read_csv(fh, dtype={"noise_param_value": float, "table_id": str})


SWEEP_PREFIX = "sweep:"


def sweep_columns(df: pd.DataFrame) -> list[str]:
    """The ``sweep:<key>`` columns of a swept run's table."""
    return [c for c in df.columns if str(c).startswith(SWEEP_PREFIX)]


def view(df: pd.DataFrame, spec: TableSpec) -> pd.DataFrame:
    """The columns of ``spec`` in a stored table (several metrics may share a file), after
    the leading ``sweep:<key>`` columns of a swept run."""
    return df[sweep_columns(df) + [c for c in spec.columns if c in df.columns]]


def _describe(row: pd.Series) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items())


def with_reference(df: pd.DataFrame, spec: TableSpec,
                   allow_unmatched: bool = False) -> pd.DataFrame:
    """Add ``thesis_<value>`` and ``ratio_<value>`` (ours / reference) beside each value.

    Rows are joined on ``spec.join`` within each ``table_id``. Raises
    :class:`ReferenceJoinError` naming the table and the row when the reference repeats a key
    (one of our rows would match twice) or when a reference row matches none of ours (unless
    ``allow_unmatched``: a run of part of a table).
    """
    named = {value: f"thesis_{value}" for value in spec.reference}
    parts = []
    for table_id, part in view(df, spec).groupby("table_id", sort=False, dropna=False):
        part = part.copy()
        if isinstance(table_id, str) and table_id:
            if not has_reference_table(table_id):
                raise ReferenceJoinError(f"table_id {table_id[:20]!r}: no printed table of "
                                         "that number is shipped with estim")
            part = _join_one(part, str(table_id), spec, named, allow_unmatched)
        for column in named.values():
            if column not in part:
                part[column] = float("nan")
        parts.append(part)
    out = pd.concat(parts).sort_index()
    for value, column in named.items():
        out[f"ratio_{value}"] = out[value] / out[column]
    return out


def _join_one(part: pd.DataFrame, table_id: str, spec: TableSpec, named: dict[str, str],
              allow_unmatched: bool) -> pd.DataFrame:
    ref = reference_table(table_id)
    on = []
    for ours, accepted in spec.join:
        theirs = next((c for c in accepted if c in ref.columns), None)
        if theirs is None and ours in spec.optional_join:
            continue
        if theirs is None:
            raise ReferenceJoinError(f"Table {table_id}: no column {' or '.join(accepted)} "
                                     f"to join our {ours!r} on")
        ref = ref.rename(columns={theirs: ours})
        on.append(ours)
    values = [c for c in named if c in ref.columns]
    ref = ref[on + values].rename(columns=named)
    repeated = ref[ref.duplicated(on, keep=False)]
    if len(repeated):
        raise ReferenceJoinError(f"Table {table_id}: key {on} repeats in row "
                                 f"{repeated.index[0] + 1} ({_describe(repeated.iloc[0][on])})")
    for column in on:
        if pd.api.types.is_numeric_dtype(ref[column]):
            ref[column] = ref[column].astype(float)
            part[column] = pd.to_numeric(part[column], errors="coerce").astype(float)
        else:
            ref[column] = ref[column].astype(str)
            part[column] = part[column].astype(str)
    matched = ref.merge(part[on].drop_duplicates(), on=on, how="left", indicator=True)
    missing = matched[matched["_merge"] == "left_only"]
    if len(missing) and not allow_unmatched:
        raise ReferenceJoinError(f"Table {table_id}: row {missing.index[0] + 1} "
                                 f"({_describe(missing.iloc[0][on])}) matches none of ours")
    joined = part.merge(ref, on=on, how="left", validate="many_to_one")
    return joined.set_index(part.index)


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
           analyses: dict) -> str:
    """What ``estim table`` prints: the ``metric`` tables of every experiment stored under
    ``results`` in ``fmt`` (text, csv, markdown, latex), with the printed values and the
    ratios beside ours when ``thesis``. csv is one table over all experiments (an
    ``experiment`` column first); the others one table per experiment under its title. A
    thesis join that fails, or no values at all, is a ``UsageError``."""
    from estim.errors import UsageError
    from estim.io import read_table, stored_tables

    parts, frames = [], []
    for folder, spec, path in stored_tables(results, metric, analyses):
        df = view(read_table(path, spec), spec)
        values = df.drop(columns=[*spec.keys, *sweep_columns(df)], errors="ignore")
        if values.isna().all().all():
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
        note = f" (thesis Table {ids})" if ids else (
            " (no printed table to compare with)" if thesis else "")
        title = f"{folder.name}: {spec.title}" if spec.title else folder.name
        head = {"text": f"== {title}{note}", "markdown": f"### {title}{note}\n"}.get(
            fmt, f"% {latex_escape(title + note)}")
        parts.append(f"{head}\n{render(df, fmt)}")
    if frames:
        parts.append(render(pd.concat(frames, ignore_index=True), "csv").rstrip("\n"))
    if not parts:
        if (Path(results) / "manifest.json").exists():
            raise UsageError(f"{results} is one experiment's folder; give the folder that "
                             "holds it (--results PARENT)")
        raise UsageError(f"no {metric} values under {results}/ (run 'estim reproduce')")
    return "\n".join(parts)
