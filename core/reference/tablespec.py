"""How a result table is declared: its file, key and value columns, and its join to the
reference (thesis or paper) table. A module of its own so that any module may declare a
table without importing the analyses."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TableSpec:
    """A result table: ``file`` holds ``keys + values`` in this order.

    ``reference`` names the value columns the reference table prints under the same name;
    ``join`` pairs each of our key columns with the reference column (or the first present of
    several accepted names) it matches. Each of our rows must match at most one reference
    row, and every reference row must be matched (:func:`estim.reference.with_reference`).
    """

    file: str
    keys: tuple[str, ...]
    values: tuple[str, ...]
    reference: tuple[str, ...] = ()
    join: tuple[tuple[str, tuple[str, ...]], ...] = ()
    title: str = ""
    reference_ids: tuple[str, ...] = ()
    """The reference tables a config may name for this table (``tables.<metric>``)."""
    optional_join: tuple[str, ...] = ()
    """Join keys a reference table may lack (Table 4.1 has no W/L columns): where it does,
    rows are joined on the other keys."""
    text: tuple[str, ...] = ()
    """Value columns that hold words, not numbers (a claim's verdict and method)."""

    @property
    def columns(self) -> list[str]:
        return [*self.keys, *self.values]
