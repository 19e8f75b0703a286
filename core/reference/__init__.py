"""The thesis tables as printed (CSV data, read with importlib.resources), and the join of
our tables to them: each analysis declares its tables as :class:`TableSpec`, and this module
joins whatever it is given.
"""

from __future__ import annotations

from importlib import resources

from estim.errors import ReferenceJoinError
from estim.reference.tablespec import TableSpec
from estim.util import lazy

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
