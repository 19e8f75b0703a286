"""Result folders written as a unit (all old or all new) and atomic file writes (what goes
into a folder is :mod:`estim.store.writing`'s). These functions take paths from their caller
(the CLI); nothing here picks a location."""

from __future__ import annotations

import ctypes
import errno
import fcntl
import hashlib
import os
import shutil
import tempfile
from pathlib import Path

from estim.errors import UsageError

_UMASK = os.umask(0)
os.umask(_UMASK)


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


MIN_FREE_BYTES = 20 * 2**20
"""Free space a run needs in its output folder before it starts."""


def ensure_free(folder: Path, need: int = MIN_FREE_BYTES) -> None:
    """A :class:`UsageError` before any work when ``folder``'s disk has less than ``need``
    bytes free (a run would otherwise fail when the disk fills, after its work)."""
    free = shutil.disk_usage(folder).free
    if free < need:
        raise UsageError(f"not enough free space in {folder}: {free / 2**20:.1f} MiB, "
                         f"need {need / 2**20:.1f} MiB")


class ResultFolder:
    """A result folder written as a unit: ``with ResultFolder(out, name) as rf:`` locks
    ``out/name`` against other runs, hands out a staging folder ``rf.path`` beside it, and
    ``rf.commit()`` swaps the staging folder in. Until the swap ``out/name`` is all old;
    after it all new; a run that fails or is killed before leaves it untouched (its staging
    folder is removed now, or by the next run).

    The swap is one ``renameat2(RENAME_EXCHANGE)`` on Linux; elsewhere two renames, and a
    folder caught between them is restored by the next run.
    """

    def __init__(self, out: Path, name: str, min_free_bytes: int = MIN_FREE_BYTES) -> None:
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
        try:
            ensure_free(self.out, max(self.min_free_bytes, 2 * _size(self.final)))
        except UsageError:
            self._release()
            raise
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


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


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


NAME_MAX, PATH_MAX = 255, 4096
"""The longest file name and path (bytes) a POSIX system accepts."""


def output_file(path: Path, option: str) -> None:
    """Refuse, before any work, a file a command was asked to write (``report --out``,
    ``tune --out``, ``summary --readme``) that it must not: a name or path over the
    system's limits, something other than a regular file where it would go, or a file
    inside a result folder (a folder with a ``manifest.json``), whose files ``estim
    reproduce`` writes and ``estim check`` compares. Raises
    :class:`estim.errors.UsageError` naming ``option`` and the reason."""
    shown = str(path) if len(str(path)) <= 80 else str(path)[:77] + "..."
    if (len(os.fsencode(str(path))) > PATH_MAX
            or any(len(os.fsencode(part)) > NAME_MAX for part in Path(path).parts)):
        raise UsageError(f"{option} {shown}: a path longer than the system allows")
    if Path(path).is_dir():
        raise UsageError(f"{option} {shown}: a folder; name the file to write")
    if os.path.lexists(path) and not Path(path).is_file():
        raise UsageError(f"{option} {shown}: not a regular file")
    for folder in Path(os.path.abspath(path)).parents:
        if (folder / "manifest.json").is_file():
            raise UsageError(f"{option} {shown}: inside the result folder {folder}, which "
                             "estim reproduce writes; give a file elsewhere")
