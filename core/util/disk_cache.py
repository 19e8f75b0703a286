"""Small arrays kept on disk between processes, so a command does not compute them again.

``estim validate CONFIG`` finds each model's DC operating point, which imports scipy's root
finder and, where Newton needs the circuit to settle first, the compiled integrator: most of
the command's time. :mod:`estim.models.base` keeps each point found here, keyed by
everything it depends on, and reads it back bit for bit.

The folder is ``$ESTIM_CACHE_DIR``, else ``$XDG_CACHE_HOME/estim``, else ``~/.cache/estim``;
``ESTIM_CACHE_DIR=off`` turns the cache off. Deleting the folder is always safe. A folder
that cannot be written is the same as no cache: nothing is kept and nothing fails.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from functools import cache
from pathlib import Path

import numpy as np

OFF = "off"


def directory() -> Path | None:
    """The cache folder, or ``None`` when the cache is off."""
    chosen = os.environ.get("ESTIM_CACHE_DIR")
    if chosen is not None:
        return None if chosen in ("", OFF) else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "estim"


@cache
def fingerprint(*files: str) -> str:
    """sha256 of the bytes of ``files`` (a key part that changes with the code)."""
    digest = hashlib.sha256()
    for name in files:
        digest.update(name.encode())
        digest.update(Path(name).read_bytes())
    return digest.hexdigest()


def key(*parts) -> str:
    """A file name from the ``repr`` of ``parts`` (floats' ``repr`` is exact)."""
    return hashlib.sha256(repr(parts).encode()).hexdigest()


def load(kind: str, name: str) -> np.ndarray | None:
    """The array kept as ``name`` (from :func:`key`), or ``None``."""
    folder = directory()
    if folder is None:
        return None
    try:
        values = json.loads((folder / kind / f"{name}.json").read_text())
        return np.array([float.fromhex(v) for v in values], dtype=float)
    except (OSError, ValueError, TypeError):
        return None


def store(kind: str, name: str, value: np.ndarray) -> None:
    """Keep the 1-d float array ``value`` as ``name``, written whole (a temporary file
    renamed) so that a reader never sees part of it."""
    folder = directory()
    if folder is None:
        return
    try:
        target = folder / kind
        target.mkdir(parents=True, exist_ok=True)
        text = json.dumps([float(v).hex() for v in np.asarray(value, float).ravel()])
        with tempfile.NamedTemporaryFile("w", dir=target, suffix=".tmp", delete=False) as f:
            f.write(text)
        os.replace(f.name, target / f"{name}.json")
    except OSError:
        return
