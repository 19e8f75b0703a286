"""Atomic writes, manifests and the comparison of stored and new tables.

These functions take paths from their caller (the CLI); nothing here picks a location.
"""

from __future__ import annotations

import csv
import ctypes
import errno
import fcntl
import hashlib
import io
import json
import os
import platform
import shutil
import stat
import tempfile
from importlib import metadata
from pathlib import Path

import numpy as np

from estim import lazy
from estim.errors import UsageError

pd = lazy.load("pandas")

_UMASK = os.umask(0)
os.umask(_UMASK)

PACKAGES = ("estim", "numpy", "scipy", "pandas", "matplotlib", "click", "PyYAML")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path`` and rename it into place. Something
    at ``path`` that is not a regular file (a folder, a FIFO, a device; a symbolic link is
    followed) is a :class:`UsageError`, never replaced: renaming over ``/dev/full`` as root
    would replace the device."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise UsageError(f"{path}: exists and is not a regular file; not replaced")
    if path.is_symlink():
        path = path.resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one atomic step (Linux ``renameat2(RENAME_EXCHANGE)``); False where
    the system has no such call."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ResultFolder:
    """A result folder written as a unit: ``with ResultFolder(out, name) as rf:`` locks
    ``out/name`` against other runs, hands out a staging folder ``rf.path`` beside it, and
    ``rf.commit()`` swaps the staging folder in. Until the swap ``out/name`` is all old;
    after it all new; a run that fails or is killed before leaves it untouched (its staging
    folder is removed now, or by the next run).

    The swap is one ``renameat2(RENAME_EXCHANGE)`` on Linux; elsewhere two renames, and a
    folder caught between them is restored by the next run.
    """

    def __init__(self, out: Path, name: str, min_free_bytes: int = 20 * 2**20) -> None:
        self.out, self.name = Path(out), name
        self.final = self.out / name
        self.path = self.out / f".{name}.partial-{os.getpid()}"
        self._old = self.out / f".{name}.old-{os.getpid()}"
        self.min_free_bytes = min_free_bytes
        self._lock_fd: int | None = None
        self.committed = False

    def __enter__(self) -> ResultFolder:
        ensure_writable(self.out)
        if (self.final.exists() or self.final.is_symlink()) and not self.final.is_dir():
            raise UsageError(f"{self.final} exists and is not a folder; move it away or give "
                             "another --out")
        lock = self.out / f".{self.name}.lock"
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_UMASK)
        except OSError as exc:
            raise UsageError(f"cannot open the lock file {lock} ({exc.strerror or exc})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise UsageError(f"another estim run is writing {self.final}; try again when it "
                             "has finished") from None
        self._lock_fd = fd
        self._recover()
        need = max(self.min_free_bytes, 2 * _size(self.final))
        free = shutil.disk_usage(self.out).free
        if free < need:
            self._release()
            raise UsageError(f"not enough free space in {self.out}: {free / 2**20:.1f} MiB, "
                             f"need {need / 2**20:.1f} MiB")
        self.path.mkdir()
        return self

    def _recover(self) -> None:
        """Undo what a killed run left: staging folders, and a folder caught mid-swap."""
        olds = sorted(self.out.glob(f".{self.name}.old-*"))
        if not self.final.exists() and olds:
            os.rename(olds[-1], self.final)
            olds = olds[:-1]
        for stale in [*olds, *self.out.glob(f".{self.name}.partial-*")]:
            shutil.rmtree(stale, ignore_errors=True)

    def commit(self) -> None:
        for path in self.path.rglob("*"):
            if path.is_dir():
                _fsync_dir(path)
        _fsync_dir(self.path)
        if self.final.exists():
            if _exchange(self.path, self.final):
                shutil.rmtree(self.path)
            else:
                os.rename(self.final, self._old)
                os.rename(self.path, self.final)
                shutil.rmtree(self._old)
        else:
            os.rename(self.path, self.final)
        _fsync_dir(self.out)
        self.committed = True

    def _release(self) -> None:
        if self._lock_fd is not None:
            fcntl.flock(self._lock_fd, fcntl.LOCK_UN)
            os.close(self._lock_fd)
            self._lock_fd = None

    def __exit__(self, *exc) -> None:
        try:
            if not self.committed:
                shutil.rmtree(self.path, ignore_errors=True)
        finally:
            self._release()


def _size(folder: Path) -> int:
    if not folder.is_dir():
        return 0
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def write_csv(df: pd.DataFrame, path: Path) -> None:
    """Tidy CSV; floats as repr, so they round-trip."""
    atomic_write_bytes(path, df.to_csv(index=False, lineterminator="\n").encode())


FIGURE_FORMATS = ("png", "pdf", "svg")


def write_figure(fig, path: Path) -> None:
    """A figure in the format its suffix names (PNG, PDF or SVG), without a timestamp or
    software tag (the same figure gives the same bytes), written atomically."""
    fmt = path.suffix.lstrip(".").lower() or "png"
    if fmt not in FIGURE_FORMATS:
        raise ValueError(f"figure format {fmt!r}: expected one of {FIGURE_FORMATS}")
    meta = {"png": {"Software": None}, "pdf": {"Creator": None, "Producer": None,
                                               "CreationDate": None},
            "svg": {"Creator": None, "Date": None}}[fmt]
    buf = io.BytesIO()
    import matplotlib

    from estim.plots import DRAWING

    with DRAWING, matplotlib.rc_context({"svg.hashsalt": "estim"}):
        fig.savefig(buf, format=fmt, dpi=fig.dpi, metadata=meta)
    atomic_write_bytes(path, buf.getvalue())


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def ensure_writable(folder: Path) -> None:
    """Create ``folder`` and prove a file can be written in it, before any work starts.

    Raises :class:`estim.errors.UsageError` naming the folder and the reason.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".estim-probe.", suffix=".tmp")
        os.close(fd)
        Path(probe).unlink()
    except OSError as exc:
        raise UsageError(f"cannot write to {folder} ({exc.strerror or exc})") from None


def git_commit() -> str | None:
    """The commit of the project checkout this package runs from (with "+dirty" when its
    tracked files differ), or ``None`` outside a git checkout (an installed copy)."""
    import subprocess

    here = Path(__file__).resolve().parent.parent
    if not (here / ".git").exists():
        return None
    try:
        head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain",
                                "--untracked-files=no"], capture_output=True, text=True,
                               timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty else "")


def write_manifest(folder: Path, spec: dict, config_sha256: str, wall_time_s: float,
                   command: str = "", overrides: dict | None = None,
                   models: dict | None = None) -> None:
    """``manifest.json``: resolved config (every default filled in) and its hash, every model
    the config builds with every parameter, seed and runs, versions, wall time, and the sha256
    of every file written beside it."""
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != "manifest.json")
    mc = spec.get("monte_carlo") or {}
    manifest = {
        "config": spec,
        "config_sha256": config_sha256,
        "models": models or {},
        "seed": mc.get("seed"),
        "runs": mc.get("runs"),
        "command": command,
        "overrides": overrides or {},
        "git_commit": git_commit(),
        "versions": versions(),
        "wall_time_s": round(wall_time_s, 3),
        "files": {str(p.relative_to(folder)): sha256(p) for p in files},
    }
    text = json.dumps(manifest, indent=2, sort_keys=True, default=float) + "\n"
    atomic_write_bytes(folder / "manifest.json", text.encode())


def _cell_tolerated(x: float, y: float, i: int, tol: dict, stored: pd.DataFrame,
                    new: pd.DataFrame, col: str) -> bool:
    """Whether the new value ``x`` passes against the stored ``y`` (row ``i`` of ``col``)."""
    if abs(x - y) <= tol.get("atol", 0.0) + tol.get("rtol", 0.0) * abs(y):
        return True
    if tol.get("se") is not None:
        se_col = tol.get("se_column") or f"{col}_se"
        if se_col in stored and se_col in new:
            se = np.hypot(float(stored[se_col].iloc[i]), float(new[se_col].iloc[i]))
            if np.isfinite(se) and abs(x - y) <= tol["se"] * se:
                return True
    if tol.get("binomial") is not None:
        trials = tol.get("trials") or []
        if trials and all(c in stored for c in trials):
            n = float(sum(stored[c].iloc[i] for c in trials))
            p = (x + y) / (2 * n) if n > 0 else 0.0
            spread = np.sqrt(2 * n * p * (1 - p)) if 0 < p < 1 else 0.0
            if abs(x - y) <= tol["binomial"] * spread:
                return True
    return False


def _too_few_runs(tol: dict, stored: pd.DataFrame, new: pd.DataFrame, col: str,
                  i: int) -> bool:
    """With an ``se`` criterion: a mean whose standard error is undefined on either side
    (fewer than two runs behind it, e.g. all runs but one diverged) is no Monte Carlo
    estimate to compare; the run counts beside it are compared instead."""
    if tol.get("se") is None:
        return False
    se_col = tol.get("se_column") or f"{col}_se"
    if se_col not in stored or se_col not in new:
        return False
    return bool(pd.isna(stored[se_col].iloc[i]) or pd.isna(new[se_col].iloc[i]))


def compare_tables(stored: pd.DataFrame, new: pd.DataFrame,
                   tolerances: dict[str, dict]) -> list[dict]:
    """Cells that differ, under each column's tolerance (default: exact).

    A numeric cell passes when any of its criteria holds:

    * ``|new - stored| <= atol + rtol |stored|``;
    * ``se: k``: within ``k`` combined standard errors, ``k sqrt(se_stored^2 + se_new^2)``,
      the standard errors read from column ``se_column`` (default ``<column>_se``) of each
      table: for Monte Carlo means, which another machine's rounding may move by a run;
    * ``binomial: k``: a count of runs out of ``n`` (the sum of the ``trials`` columns)
      within ``k sqrt(2 n p (1 - p))``, ``p`` the pooled fraction: for divergence counts.

    NaN equals NaN and an infinity itself, and nothing else (no tolerance admits a finite
    value for a stored infinity, or the reverse); with ``se``, a mean with no standard error on
    either side (fewer than two runs) is not compared. ``skip: reason`` leaves a column out
    (the CLI shows why). Non-numeric columns must match exactly. A change of shape is one
    difference.
    """
    if list(stored.columns) != list(new.columns) or len(stored) != len(new):
        return [{"row": "-", "column": "(shape)",
                 "expected": f"{len(stored)} rows {list(stored.columns)}",
                 "obtained": f"{len(new)} rows {list(new.columns)}", "difference": ""}]
    diffs = []
    for col in stored.columns:
        tol = tolerances.get(col, {})
        if tol.get("skip"):
            continue
        a, b = new[col], stored[col]
        numeric = pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b) \
            and not pd.api.types.is_bool_dtype(a)
        for i in range(len(a)):
            x, y = a.iloc[i], b.iloc[i]
            if numeric:
                x, y = float(x) if pd.notna(x) else np.nan, float(y) if pd.notna(y) else np.nan
                if (np.isnan(x) and np.isnan(y)) or x == y:
                    continue
                if _too_few_runs(tol, stored, new, col, i):
                    continue
                finite = np.isfinite(x) and np.isfinite(y)     # |5 - inf| <= rtol inf holds
                if finite and _cell_tolerated(x, y, i, tol, stored, new, col):
                    continue
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": x - y})
            elif not (pd.isna(x) and pd.isna(y)) and str(x) != str(y):
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": ""})
    return diffs


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
        import shutil

        shutil.rmtree(self.folder, ignore_errors=True)


_FINGERPRINT: list[str] = []


def code_fingerprint() -> str:
    """A hash of estim's own source (every ``.py`` file of ``core``): stored cells of a run
    are reused only by the same code."""
    if not _FINGERPRINT:
        root = Path(__file__).resolve().parent
        digest = hashlib.sha256()
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
        _FINGERPRINT.append(digest.hexdigest())
    return _FINGERPRINT[0]


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
    """``folder``'s file of the table ``spec``: None when there is none; a
    :class:`UsageError` when something that is not a regular file stands in its place."""
    path = Path(folder) / spec.file
    if not os.path.lexists(path):
        return None
    try:
        mode = path.stat().st_mode
    except OSError as exc:
        raise UsageError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(mode):
        raise UsageError(f"{path}: not a regular file (a stored table must be one)")
    return path


def read_table(path: Path, spec=None) -> pd.DataFrame:
    """A stored result table, with an empty ``table_id`` kept as an empty string.

    Raises :class:`UsageError` naming the file when it cannot be read as a table: not a
    regular file, over :data:`MAX_TABLE_BYTES`, empty or a header alone, not CSV, ragged
    rows, missing columns of ``spec``, or text in one of its value columns.
    """
    try:
        text_ = read_stored(path, MAX_TABLE_BYTES, "table").decode("utf-8")
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
    try:
        df = pd.read_csv(io.StringIO(text_), dtype={"table_id": str}, keep_default_na=False,
                         na_values=["", "NaN", "nan", "<NA>"])
    except (ValueError, pd.errors.ParserError) as exc:
        raise UsageError(f"{path}: not a table ({str(exc).splitlines()[0]})") from None
    if "table_id" in df:
        df["table_id"] = df["table_id"].fillna("")
    if spec is not None:
        missing = [c for c in spec.columns if c not in df.columns]
        if missing:
            raise UsageError(f"{path}: no column {missing[0]!r}")
        for column in (c for c in spec.values if c not in spec.text):
            if not pd.api.types.is_numeric_dtype(df[column]):
                for i, cell in enumerate(df[column]):
                    if pd.isna(cell) or str(cell) in ("True", "False"):
                        continue
                    try:
                        float(cell)
                    except ValueError:
                        raise UsageError(f"{path}: line {i + 2}, column {column}: "
                                         f"{str(cell)[:40]!r} is not a number") from None
    return df


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


def stored_tables(results: Path, metric: str, analyses: dict):
    """``(folder, TableSpec, path)`` of every stored experiment under ``results`` that has
    the table ``metric``; a manifest that cannot be read is a ``UsageError`` naming it."""
    for manifest_path in sorted(Path(results).glob("*/manifest.json")):
        folder = manifest_path.parent
        manifest = read_manifest(folder)
        if manifest is None or not isinstance(manifest.get("config"), dict):
            raise UsageError(f"{manifest_path}: not a readable estim manifest")
        name = manifest["config"].get("analysis", "estimation")
        analysis = analyses.get(name) if isinstance(name, str) else None
        if analysis is None:
            raise UsageError(f"{manifest_path}: names an unknown analysis {str(name)[:60]!r}")
        spec = analysis.TABLES.get(metric)
        path = stored_table_path(folder, spec) if spec is not None else None
        if path is not None:
            yield folder, spec, path
