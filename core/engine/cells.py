"""The cell store: the finished work units of a run, kept until its folder is written, so
a run stopped by a crash or Ctrl-C resumes with the cells it has, and ``estim merge`` can
gather the cells of shards run elsewhere.

A cell is data that cannot run code: one ``.npz`` file (read with ``allow_pickle=False``)
holding the work unit's arrays and, as JSON, everything else (:func:`encode`), with the
config's hash and estim's source fingerprint. A cell made by another config or another
estim is refused by name (:meth:`CellStore.refused`), never loaded."""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import io
import json
import os
import shutil
from pathlib import Path

from estim.errors import UsageError
from estim.store.folders import atomic_write_bytes
from estim.store.read import read_stored
from estim.util import lazy

np = lazy.load("numpy")

FORMAT = "estim-cell-2"
"""The format tag in a cell's metadata."""
SUFFIX = ".npz"
META = "meta"
"""The array of a cell's ``.npz`` that holds its metadata and value tree as UTF-8 JSON."""
MAX_CELL_BYTES = 1 << 30
"""A cell file larger than this is not read (a work unit's results are far smaller)."""
ARRAY_KINDS = "biufc"
"""The numpy dtype kinds a cell may hold (bool, integers, floats, complex): never objects."""


class CellError(ValueError):
    """A value a cell cannot hold, or a file that is not a cell."""


def encode(value) -> tuple[object, dict]:
    """``(tree, arrays)``: ``value`` as a JSON-able tree whose every node names its type,
    and its numpy arrays by name. Holds None, bool, int, float (exactly, as hex), str,
    list, tuple, dict (any keys of these types), numpy arrays and scalars of
    :data:`ARRAY_KINDS`, and dataclasses of estim's own modules (by their fields)."""
    arrays: dict = {}

    def node(v):
        if isinstance(v, (np.ndarray, np.generic)):       # before float: np.float64 is one
            a = np.asarray(v)
            if a.dtype.kind not in ARRAY_KINDS:
                raise CellError(f"an array of dtype {a.dtype} (a cell holds numbers only)")
            name = f"a{len(arrays)}"
            arrays[name] = a
            return {"t": "scalar" if isinstance(v, np.generic) else "array", "v": name}
        if v is None or isinstance(v, (bool, str)):
            return {"t": type(v).__name__ if v is not None else "none", "v": v}
        if isinstance(v, int) and not isinstance(v, bool):
            return {"t": "int", "v": str(v)}
        if isinstance(v, float):
            return {"t": "float", "v": float.hex(v)}
        if isinstance(v, (list, tuple)):
            return {"t": type(v).__name__, "v": [node(x) for x in v]}
        if isinstance(v, dict):
            return {"t": "dict", "v": [[node(k), node(x)] for k, x in v.items()]}
        cls = type(v)
        if dataclasses.is_dataclass(v) and cls.__module__.startswith("estim."):
            return {"t": "dataclass", "cls": f"{cls.__module__}:{cls.__qualname__}",
                    "v": [[f.name, node(getattr(v, f.name))] for f in dataclasses.fields(v)]}
        raise CellError(f"a {cls.__module__}.{cls.__qualname__} (not a type a cell holds)")

    return node(value), arrays


def _dataclass(path: str) -> type:
    """An estim dataclass named ``module:qualname`` (nothing else is ever constructed)."""
    module, _, name = path.partition(":")
    if not module.startswith("estim.") or "." in name:
        raise CellError(f"names {path!r}, not a dataclass of estim")
    cls = getattr(importlib.import_module(module), name, None)
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise CellError(f"names {path!r}, not a dataclass of estim")
    return cls


def decode(tree, arrays) -> object:
    """The value :func:`encode` made ``tree`` and ``arrays`` of."""
    def value(n):
        if not isinstance(n, dict) or "t" not in n:
            raise CellError("a node of its value tree is malformed")
        t, v = n["t"], n.get("v")
        if t == "none":
            return None
        if t in ("bool", "str") and isinstance(v, (bool, str)):
            return v
        if t == "int":
            return int(v)
        if t == "float":
            return float.fromhex(v)
        if t in ("list", "tuple") and isinstance(v, list):
            items = [value(x) for x in v]
            return items if t == "list" else tuple(items)
        if t == "dict" and isinstance(v, list):
            return {value(k): value(x) for k, x in v}
        if t in ("array", "scalar") and isinstance(v, str) and v in arrays:
            a = arrays[v]
            return a[()] if t == "scalar" else a
        if t == "dataclass" and isinstance(v, list):
            cls = _dataclass(str(n.get("cls")))
            fields = {str(k): value(x) for k, x in v}
            made = cls.__new__(cls)
            for k, x in fields.items():
                object.__setattr__(made, k, x)
            return made
        raise CellError(f"a node of type {str(t)[:40]!r} it cannot hold")

    return value(tree)


def _load(data: bytes) -> tuple[dict, dict]:
    """The metadata and arrays of a cell file's bytes: a zip of uncompressed ``.npy``
    members only (no pickle, no compression to inflate), each within the file's size."""
    import zipfile

    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            for info in archive.infolist():
                if (info.compress_type != zipfile.ZIP_STORED or info.file_size > len(data)
                        or not info.filename.endswith(".npy")):
                    raise CellError("not a cell file (a member it cannot hold)")
        with np.load(io.BytesIO(data), allow_pickle=False) as found:
            arrays = {name: found[name] for name in found.files}
    except CellError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever numpy or zipfile make of junk
        raise CellError(f"not a cell file ({type(exc).__name__})") from None
    meta = arrays.pop(META, None)
    if meta is None or meta.dtype != np.uint8 or meta.ndim != 1:
        raise CellError("not a cell file (no metadata)")
    try:
        return json.loads(meta.tobytes().decode("utf-8")), arrays
    except (UnicodeDecodeError, ValueError):
        raise CellError("not a cell file (unreadable metadata)") from None


class CellStore:
    """Finished work units of one run, one ``.npz`` per cell in ``folder`` (written
    atomically), so a run stopped by a crash or Ctrl-C resumes with the cells it has. The
    folder name carries the config's hash and estim's source fingerprint, and so does each
    cell (``identity``): a cell of another config or estim is refused, never loaded."""

    def __init__(self, folder: Path, identity: dict | None = None) -> None:
        self.folder = Path(folder)
        self.identity = dict(identity or {})
        self.hits = 0
        self.refused: list[str] = []
        """Cell files found and not used, each as ``name (why)``."""

    def _path(self, key: tuple[int, ...]) -> Path:
        return self.folder / ("cell-" + "-".join(str(k) for k in key) + SUFFIX)

    def read(self, path: Path, key: tuple[int, ...] | None = None) -> object:
        """The value of the cell file ``path`` (of ``key`` where given); a ``CellError``
        saying why when it is not a regular file of bounded size, not a cell, or a cell of
        another key, config or estim."""
        if path.is_symlink():
            raise CellError("a symbolic link, not a cell file")
        try:                            # the one reader of stored files: bounded, regular
            data = read_stored(path, MAX_CELL_BYTES, "cell")
        except UsageError as exc:
            raise CellError(str(exc).removeprefix(f"{path}: ")) from None
        meta, arrays = _load(data)
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise CellError("not a cell of this format")
        if any(meta.get(k) != v for k, v in self.identity.items()):
            raise CellError("a cell of another config or estim version")
        if key is not None and meta.get("key") != list(key):
            raise CellError("a cell of another work unit")
        return decode(meta.get("value"), arrays)

    def get(self, key: tuple[int, ...]) -> tuple[bool, object]:
        """``(True, value)`` of a stored cell, ``(False, None)`` when there is none or it is
        not one this run can use (named in :attr:`refused`; it is recomputed)."""
        path = self._path(key)
        if not os.path.lexists(path):
            return False, None
        try:
            value = self.read(path, key)
        except CellError as exc:
            self.refused.append(f"{path.name} ({exc})")
            return False, None
        self.hits += 1
        return True, value

    def put(self, key: tuple[int, ...], value: object) -> None:
        path = self._path(key)
        if os.path.lexists(path) and not path.is_file():
            raise UsageError(f"{path}: not a regular file where a finished cell is kept; "
                             "remove it and run again")
        tree, arrays = encode(value)
        meta = {"format": FORMAT, **self.identity, "key": list(key), "value": tree}
        buf = io.BytesIO()
        np.savez(buf, **{META: np.frombuffer(json.dumps(meta).encode("utf-8"), np.uint8)},
                 **arrays)
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, buf.getvalue())

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
