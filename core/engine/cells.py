"""The cell store: the finished work units of a run, kept until its folder is written, so
a run stopped by a crash or Ctrl-C resumes with the cells it has."""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

from estim.errors import UsageError
from estim.store.folders import atomic_write_bytes
from estim.util import lazy

pd = lazy.load("pandas")


_CELL = "estim-cell-1"
"""The tag of a stored cell: a pickle of ``(tag, key, value)``."""


class CellStore:
    """Finished work units of one run, one pickle per cell in ``folder`` (written
    atomically), so a run stopped by a crash or Ctrl-C resumes with the cells it has. The
    folder name carries the config's hash: another config never reads them. Only estim
    writes these files; they are read back by the same user's runs."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.hits = 0

    def _path(self, key: tuple[int, ...]) -> Path:
        return self.folder / ("cell-" + "-".join(str(k) for k in key) + ".pkl")

    def get(self, key: tuple[int, ...]) -> tuple[bool, object]:
        """``(True, value)`` of a stored cell, ``(False, None)`` when there is none or it is
        damaged (not a regular file, not a pickle, or not a cell of this key: a file of
        another shape, say one a shard left half-copied, is recomputed, never used)."""
        import pickle

        path = self._path(key)
        if not path.is_file():
            return False, None
        try:
            data = pickle.loads(path.read_bytes())
        except Exception:  # noqa: BLE001 - a damaged cell is recomputed
            return False, None
        if not (isinstance(data, tuple) and len(data) == 3 and data[0] == _CELL
                and data[1] == tuple(key)):
            return False, None
        self.hits += 1
        return True, data[2]

    def put(self, key: tuple[int, ...], value: object) -> None:
        import pickle

        path = self._path(key)
        if os.path.lexists(path) and not path.is_file():
            raise UsageError(f"{path}: not a regular file where a finished cell is kept; "
                             "remove it and run again")
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, pickle.dumps((_CELL, tuple(key), value),
                                              protocol=pickle.HIGHEST_PROTOCOL))

    def clear(self) -> None:

        shutil.rmtree(self.folder, ignore_errors=True)


_FINGERPRINT: list[str] = []


def code_fingerprint() -> str:
    """A hash of estim's own source (every ``.py`` file of ``core``): stored cells of a run
    are reused only by the same code."""
    if not _FINGERPRINT:
        root = Path(__file__).resolve().parents[1]
        digest = hashlib.sha256()
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
        _FINGERPRINT.append(digest.hexdigest())
    return _FINGERPRINT[0]
