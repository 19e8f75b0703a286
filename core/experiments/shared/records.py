"""A CSV record a config names (an input waveform's file, a measured record): found as
:func:`estim.util.shipped.find_beside` finds it, read into its header and rows, or one
:class:`~estim.errors.ConfigError` at the key that names it."""

from __future__ import annotations

import csv
from pathlib import Path

from estim.errors import ConfigError
from estim.util.shipped import find_beside


def read_rows(name: str, source: str, key: str) -> tuple[Path, list[str], list[list[str]]]:
    """The file ``name`` of the config ``source`` (named at ``key`` in messages): its path,
    its header line's cells and its other non-empty lines' cells."""
    path = find_beside(name, source)
    if path is None:
        raise ConfigError(source, key, f"cannot read {name!r}: no file {name!r} beside the "
                          "config, in a folder above it, in the working folder or among the "
                          "data shipped with estim's configs")
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = [row for row in csv.reader(handle) if row]
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(source, key, f"cannot read {path}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    header = [cell.strip() for cell in rows[0]] if rows else []
    return path, header, rows[1:]
