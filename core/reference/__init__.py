"""The thesis tables as printed (CSV data, read with importlib.resources), and the join of
our tables to them: each analysis declares its tables as :class:`TableSpec`, and this module
joins whatever it is given.
"""

from __future__ import annotations

import math
from importlib import resources

from estim.errors import ReferenceJoinError
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.columns import NAN, Table, is_missing

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


def reference_columns(table_id: str) -> Table:
    """:func:`reference_table` as plain columns, read without pandas (the same types and
    values; ``tests/test_tables.py``)."""
    text_ = resources.files("estim.reference").joinpath(_reference_name(table_id)).read_text()
    table = Table.from_csv(text_, text_columns=("table_id",))
    if "noise_param_value" in table:
        table = table.as_float("noise_param_value")
    return table


SWEEP_PREFIX = "sweep:"


def sweep_columns(names) -> list[str]:
    """The ``sweep:<key>`` columns of a swept run's table (its column names, or a table)."""
    names = names.names if isinstance(names, Table) else getattr(names, "columns", names)
    return [c for c in names if str(c).startswith(SWEEP_PREFIX)]


def view(df, spec: TableSpec):
    """The columns of ``spec`` in a stored table (several metrics may share a file), after
    the leading ``sweep:<key>`` columns of a swept run; a DataFrame or a :class:`Table`."""
    if isinstance(df, Table):
        return df.select(sweep_columns(df) + [c for c in spec.columns if c in df])
    return df[sweep_columns(df) + [c for c in spec.columns if c in df.columns]]


def _describe(names: list[str], values: tuple) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in zip(names, values, strict=True))


def _key(values: tuple) -> tuple:
    """A join key whose missing cells match each other (as pandas' merge matches NaN)."""
    return tuple(None if is_missing(v) else v for v in values)


def with_reference(df: pd.DataFrame, spec: TableSpec,
                   allow_unmatched: bool = False) -> pd.DataFrame:
    """:func:`join_reference` of a DataFrame: a DataFrame with ``df``'s index."""
    out = join_reference(Table.from_frame(df), spec, allow_unmatched).to_frame()
    out.index = df.index
    return out


def join_reference(table: Table, spec: TableSpec, allow_unmatched: bool = False) -> Table:
    """Add ``thesis_<value>`` and ``ratio_<value>`` (ours / reference) beside each value.

    Rows are joined on ``spec.join`` within each ``table_id`` and keep their order. Raises
    :class:`ReferenceJoinError` naming the table and the row when the reference repeats a key
    (one of our rows would match twice) or when a reference row matches none of ours (unless
    ``allow_unmatched``: a run of part of a table).
    """
    named = {value: f"thesis_{value}" for value in spec.reference}
    table = view(table, spec)
    groups: dict = {}
    for i, table_id in enumerate(table["table_id"]):
        groups.setdefault(_key((table_id,)), []).append(i)
    parts, order = [], []
    for (table_id,), rows in groups.items():
        part = table.take(rows)
        if isinstance(table_id, str) and table_id:
            if not has_reference_table(table_id):
                raise ReferenceJoinError(f"table_id {table_id[:20]!r}: no printed table of "
                                         "that number is shipped with estim")
            part = _join_one(part, table_id, spec, named, allow_unmatched)
        for column in named.values():
            if column not in part:
                part = part.with_column(column, [NAN] * len(part), "f")
        parts.append(part)
        order += rows
    out = Table.concat(parts).take(sorted(range(len(order)), key=order.__getitem__))
    for value, column in named.items():
        ratios = [_ratio(a, b) for a, b in zip(out[value], out[column], strict=True)]
        out = out.with_column(f"ratio_{value}", ratios, "f")
    return out


def _ratio(ours, printed) -> float:
    """``ours / printed`` as pandas divides floats: NaN for a missing value, an infinity or
    NaN for a printed zero."""
    if is_missing(ours) or is_missing(printed):
        return NAN
    if printed == 0:
        return NAN if ours == 0 or ours != ours else math.copysign(math.inf, ours) * \
            math.copysign(1.0, printed)
    return float(ours) / float(printed)


def _join_one(part: Table, table_id: str, spec: TableSpec, named: dict[str, str],
              allow_unmatched: bool) -> Table:
    ref = reference_columns(table_id)
    on = []
    for ours, accepted in spec.join:
        theirs = next((c for c in accepted if c in ref), None)
        if theirs is None and ours in spec.optional_join:
            continue
        if theirs is None:
            raise ReferenceJoinError(f"Table {table_id}: no column {' or '.join(accepted)} "
                                     f"to join our {ours!r} on")
        ref = ref.renamed({theirs: ours})
        on.append(ours)
    values = [c for c in named if c in ref]
    ref = ref.select(on + values).renamed(named)
    keys = [_key(row) for row in ref.rows(on)] if on else [()] * len(ref)
    counts: dict = {}
    for key in keys:
        counts[key] = counts.get(key, 0) + 1
    repeated = next((i for i, key in enumerate(keys) if counts[key] > 1), None)
    if repeated is not None:
        raise ReferenceJoinError(f"Table {table_id}: key {on} repeats in row "
                                 f"{repeated + 1} ({_describe(on, ref.rows(on)[repeated])})")
    for column in on:
        if ref.kinds[column] in "ifb":
            ref, part = ref.as_float(column), part.as_float(column)
        else:
            ref, part = ref.as_text(column), part.as_text(column)
    ref_rows = {_key(row): i for i, row in enumerate(ref.rows(on))} if on else {(): 0}
    ours = [_key(row) for row in part.rows(on)] if on else [()] * len(part)
    present = set(ours)
    missing = [i for i, row in enumerate(ref.rows(on) if on else [()] * len(ref))
               if _key(row) not in present]
    if missing and not allow_unmatched:
        i = missing[0]
        raise ReferenceJoinError(f"Table {table_id}: row {i + 1} "
                                 f"({_describe(on, ref.rows(on)[i])}) matches none of ours")
    matches = [ref_rows.get(key) for key in ours]
    for value in values:
        column, kind = named[value], ref.kinds[named[value]]
        cells = [NAN if j is None else ref[column][j] for j in matches]
        if None in matches and kind in "ib":
            kind = "f" if kind == "i" else "O"
            cells = [float(v) if kind == "f" and not is_missing(v) else v for v in cells]
        part = part.with_column(column, cells, kind)
    return part
