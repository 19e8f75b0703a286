"""Reading stored results: regular files only, each bounded in size, every problem one
``UsageError`` naming the file."""

from __future__ import annotations

import csv
import io
import json
import os
import stat
from pathlib import Path

from estim.errors import UsageError
from estim.store.writing import MACHINE_DIR, RUN_RECORD
from estim.util import lazy

pd = lazy.load("pandas")


MAX_TABLE_BYTES = 8 << 20
"""Largest stored table read (50 times the largest a shipped config writes, 155 KB)."""
MAX_MANIFEST_BYTES = 4 << 20
"""Largest stored manifest read (the shipped ones are at most 23 KB)."""


def read_stored(path: Path, limit: int, what: str) -> bytes:
    """The bytes of a stored file, which must be a regular file of at most ``limit`` bytes:
    a FIFO, a device, a directory or a symbolic-link loop is refused before anything is read
    (opening a FIFO would wait for a writer). Raises :class:`UsageError` naming the file."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise UsageError(f"{path}: cannot read ({exc.strerror or exc})") from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):       # before fdopen, which refuses a folder itself
        os.close(fd)
        raise UsageError(f"{path}: not a regular file (a stored {what} must be one)")
    with os.fdopen(fd, "rb") as fh:
        if info.st_size > limit:
            raise UsageError(f"{path}: larger than {limit >> 20} MiB, the limit of a stored "
                             f"{what}")
        try:
            data = fh.read(limit + 1)
        except OSError as exc:
            raise UsageError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise UsageError(f"{path}: larger than {limit >> 20} MiB, the limit of a stored {what}")
    return data


def stored_table_path(folder: Path, spec) -> Path | None:
    """``folder``'s file of the table ``spec`` (beside the manifest, or under ``machine/``
    for one that measures the machine): None when there is none; a
    :class:`UsageError` when something that is not a regular file stands in its place."""
    path = Path(folder) / spec.file
    if not os.path.lexists(path):
        path = Path(folder) / MACHINE_DIR / spec.file      # a table measuring the machine
    if not os.path.lexists(path):
        return None
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        raise UsageError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(mode):
        raise UsageError(f"{path}: not a regular file (a stored table must be one)")
    return path


def _table_text(path: Path, data: bytes | None) -> str:
    """The text of a stored table with its rows checked (see :func:`read_table`)."""
    try:
        if data is None:
            data = read_stored(path, MAX_TABLE_BYTES, "table")
        text_ = data.decode("utf-8")
        rows = list(csv.reader(io.StringIO(text_, newline="")))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise UsageError(f"{path}: cannot read ({exc})") from None
    if not rows or not rows[0]:
        raise UsageError(f"{path}: empty, not a table")
    if len(rows) == 1:
        raise UsageError(f"{path}: a header and no rows (estim writes no empty table)")
    width = len(rows[0])
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != width:
            raise UsageError(f"{path}: line {number} has {len(row)} fields, the header {width}")
    return text_


def _check_columns(path: Path, spec, names: list[str], numeric, values) -> None:
    """``spec``'s columns are among ``names``, and each of its value columns that is not
    ``numeric(column)`` holds only numbers, True/False and missing cells (``values(column)``
    its cells)."""
    from estim.util.columns import is_missing

    missing = [c for c in spec.columns if c not in names]
    if missing:
        raise UsageError(f"{path}: no column {missing[0]!r}")
    for column in (c for c in spec.values if c not in spec.text):
        if numeric(column):
            continue
        for i, cell in enumerate(values(column)):
            if is_missing(cell) or str(cell) in ("True", "False"):
                continue
            try:
                float(cell)
            except ValueError:
                raise UsageError(f"{path}: line {i + 2}, column {column}: "
                                 f"{str(cell)[:40]!r} is not a number") from None


def read_table(path: Path, spec=None, data: bytes | None = None) -> pd.DataFrame:
    """A stored result table, with an empty ``table_id`` kept as an empty string (``data``:
    the file's bytes, already read and checked by :meth:`estim.store.stored.Stored.read`).

    Raises :class:`UsageError` naming the file when it cannot be read as a table: not a
    regular file, over :data:`MAX_TABLE_BYTES`, empty or a header alone, not CSV, ragged
    rows, missing columns of ``spec``, or text in one of its value columns.
    """
    text_ = _table_text(path, data)
    try:
        df = pd.read_csv(io.StringIO(text_), dtype={"table_id": str}, keep_default_na=False,
                         na_values=["", "NaN", "nan", "<NA>"])
    except (ValueError, pd.errors.ParserError) as exc:
        raise UsageError(f"{path}: not a table ({str(exc).splitlines()[0]})") from None
    if "table_id" in df:
        df["table_id"] = df["table_id"].fillna("")
    if spec is not None:
        _check_columns(path, spec, list(df.columns),
                       lambda c: pd.api.types.is_numeric_dtype(df[c]), lambda c: df[c])
    return df


def read_columns(path: Path, spec=None, data: bytes | None = None):
    """:func:`read_table` as plain columns (:class:`estim.util.columns.Table`), read without
    pandas: the same checks, column types and values."""
    from estim.util.columns import Table

    text_ = _table_text(path, data)
    table = Table.from_csv(text_, text_columns=("table_id",))
    if spec is not None:
        _check_columns(path, spec, table.names, lambda c: table.kinds[c] in "ifb",
                       lambda c: table[c])
    return table


def read_manifest(folder: Path) -> dict | None:
    """``folder``'s manifest.json as a mapping; None when it is missing, is not a bounded
    regular file (:func:`read_stored`), or is not JSON that Python can hold (a document
    nested deeper than the interpreter's recursion limit is not)."""
    try:
        data = read_stored(Path(folder) / "manifest.json", MAX_MANIFEST_BYTES, "manifest")
        manifest = json.loads(data.decode("utf-8"))
    except (UsageError, ValueError, RecursionError):
        return None
    return manifest if isinstance(manifest, dict) else None


def read_run_record(folder: Path) -> dict:
    """``folder``'s untracked run record (``run.json``: command, commit, wall time, host) as
    a mapping; empty when there is none (a fresh clone's results) or it cannot be read."""
    try:
        data = read_stored(Path(folder) / RUN_RECORD, MAX_MANIFEST_BYTES, "run record")
        record = json.loads(data.decode("utf-8"))
    except (UsageError, ValueError, RecursionError):
        return {}
    return record if isinstance(record, dict) else {}
