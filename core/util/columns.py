"""A table as plain Python columns, read from CSV the way ``pandas.read_csv`` reads estim's
stored tables (the same column types and values), for the commands that only print tables:
``estim table`` starts without importing pandas, whose import alone is half a second.

A column is a list of Python values with a kind, as a pandas column has a dtype: ``"i"``
integers, ``"f"`` floats (a missing cell is NaN), ``"b"`` booleans, ``"O"`` text (a missing
cell is NaN). :meth:`Table.from_frame` and :meth:`Table.to_frame` convert to and from a
DataFrame; ``tests/test_tables.py`` reads every stored table both ways.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass

MISSING = ("", "NaN", "nan", "<NA>")
"""The cells read as missing (estim's ``na_values``; pandas' other defaults are text)."""

_TRUE, _FALSE = ("True", "TRUE", "true"), ("False", "FALSE", "false")
NAN = float("nan")


def is_missing(value) -> bool:
    """Whether ``value`` is a missing cell: None, NaN or pandas' NA."""
    return value is None or (isinstance(value, float) and math.isnan(value)) \
        or type(value).__name__ == "NAType"


def _as_int(cell: str) -> int | None:
    try:
        return int(cell) if "_" not in cell else None
    except ValueError:
        return None


def _as_float(cell: str) -> float | None:
    try:
        return float(cell) if "_" not in cell else None
    except ValueError:
        return None


def infer(cells: list[str], text_only: bool = False) -> tuple[list, str]:
    """The values and kind of a column of CSV cells, as ``pandas.read_csv`` types it:
    integers if every cell is one (floats once one is missing), else floats if every
    present cell is a number, else booleans if every cell is True or False (text once one
    is missing), else text with NaN for a missing cell. ``text_only``: text, a missing
    cell read as ``""`` (the ``table_id`` column)."""
    if text_only:
        return ["" if c in MISSING else c for c in cells], "O"
    present = [c for c in cells if c not in MISSING]
    if not present:
        return [NAN] * len(cells), "f"
    missing = len(present) < len(cells)
    ints = [_as_int(c) for c in present]
    if all(v is not None and abs(v) < 2**63 for v in ints):
        if not missing:
            return ints, "i"
        return [NAN if c in MISSING else float(int(c)) for c in cells], "f"
    if all(_as_float(c) is not None for c in present):
        return [NAN if c in MISSING else float(c) for c in cells], "f"
    if all(c in _TRUE or c in _FALSE for c in present):
        return [NAN if c in MISSING else c in _TRUE for c in cells], "O" if missing else "b"
    return [NAN if c in MISSING else c for c in cells], "O"


def _merge_kinds(kinds: list[str]) -> str:
    """The kind of a column put together from parts of these kinds (as ``pandas.concat``)."""
    found = set(kinds)
    if len(found) == 1:
        return kinds[0]
    if found <= {"i", "f"}:
        return "f"
    return "O"


@dataclass
class Table:
    """Named columns of equal length, in order, each with its kind (see the module)."""

    columns: dict[str, list]
    kinds: dict[str, str]

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()), []))

    @property
    def names(self) -> list[str]:
        return list(self.columns)

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> list:
        return self.columns[name]

    def select(self, names: list[str]) -> Table:
        return Table({n: self.columns[n] for n in names}, {n: self.kinds[n] for n in names})

    def drop(self, names) -> Table:
        return self.select([n for n in self.columns if n not in set(names)])

    def renamed(self, names: dict[str, str]) -> Table:
        """This table with the columns of ``names`` renamed (others as they are)."""
        return Table({names.get(n, n): v for n, v in self.columns.items()},
                     {names.get(n, n): k for n, k in self.kinds.items()})

    def with_column(self, name: str, values: list, kind: str) -> Table:
        """This table with ``name`` set to ``values`` (appended if new)."""
        return Table({**self.columns, name: list(values)}, {**self.kinds, name: kind})

    def rows(self, names: list[str] | None = None) -> list[tuple]:
        return list(zip(*(self.columns[n] for n in (names or self.names)), strict=True))

    def take(self, rows: list[int]) -> Table:
        return Table({n: [v[i] for i in rows] for n, v in self.columns.items()}, dict(self.kinds))

    def as_float(self, name: str) -> Table:
        """``name`` as floats, a cell that is not a number NaN (``pandas.to_numeric(...,
        errors="coerce").astype(float)``)."""
        def number(v) -> float:
            if isinstance(v, (bool, int, float)):
                return float(v)
            try:
                return float(v) if not is_missing(v) else NAN
            except (TypeError, ValueError):
                return NAN
        return self.with_column(name, [number(v) for v in self.columns[name]], "f")

    def as_text(self, name: str) -> Table:
        """``name`` as text (``astype(str)``: a missing cell is ``"nan"``)."""
        return self.with_column(name, [str(v) for v in self.columns[name]], "O")

    @classmethod
    def concat(cls, parts: list[Table]) -> Table:
        """The rows of ``parts`` one after another; the columns of all of them in the order
        first met, a cell of a column its part lacks missing (``pandas.concat``)."""
        names: list[str] = []
        for part in parts:
            names += [n for n in part.names if n not in names]
        columns, kinds = {}, {}
        for name in names:
            values, found = [], []
            for part in parts:
                if name in part:
                    values += part[name]
                    found.append(part.kinds[name])
                else:
                    values += [NAN] * len(part)
                    found.append("f" if not len(part) else "missing")
            kind = _merge_kinds([k for k in found if k != "missing"] or ["f"])
            if "missing" in found and kind in ("i", "b"):
                kind = "f" if kind == "i" else "O"
            if kind == "f":
                values = [NAN if is_missing(v) else float(v) for v in values]
            columns[name], kinds[name] = values, kind
        return cls(columns, kinds)

    @classmethod
    def from_csv(cls, text_: str, text_columns: tuple[str, ...] = ()) -> Table:
        """The table in CSV ``text_`` (a header and rows of as many fields); the
        ``text_columns`` read as text, a missing cell ``""``."""
        rows = list(csv.reader(io.StringIO(text_, newline="")))
        header, body = rows[0], rows[1:]
        columns, kinds = {}, {}
        for i, name in enumerate(header):
            columns[name], kinds[name] = infer([row[i] for row in body], name in text_columns)
        return cls(columns, kinds)

    @classmethod
    def from_frame(cls, df) -> Table:
        """A DataFrame's columns (pandas' NA read as None)."""
        columns, kinds = {}, {}
        for name in df.columns:
            values = [None if type(v).__name__ == "NAType" else v for v in df[name].tolist()]
            columns[str(name)] = values
            kinds[str(name)] = {"i": "i", "u": "i", "f": "f", "b": "b"}.get(
                df[name].dtype.kind, "O")
        return cls(columns, kinds)

    def to_frame(self):
        """This table as a DataFrame (imports pandas)."""
        import pandas as pd

        frame = pd.DataFrame(self.columns)
        for name, kind in self.kinds.items():
            if kind in "if" and frame[name].dtype.kind != kind:
                frame[name] = frame[name].astype("int64" if kind == "i" else "float64")
        return frame

    def to_csv(self) -> str:
        """The table as CSV, as ``DataFrame.to_csv(index=False)`` writes it: a missing cell
        empty, a float as Python writes it."""
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(self.names)
        for row in self.rows():
            writer.writerow(["" if is_missing(v) else repr(v) if isinstance(v, float) else v
                             for v in row])
        return out.getvalue()
