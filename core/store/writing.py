"""What a result folder holds, written file by file into the folder a
:class:`~estim.store.folders.ResultFolder` holds open: each table as CSV, each figure, and
``manifest.json`` (the resolved config and its hash, the models, seed and runs, versions, wall
time and the sha256 of every file beside it)."""

from __future__ import annotations

import hashlib
import io
import json
import platform
from importlib import metadata
from pathlib import Path

from estim.store.folders import atomic_write_bytes, sha256
from estim.util import lazy

pd = lazy.load("pandas")


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

    from estim.util.drawing import DRAWING

    with DRAWING, matplotlib.rc_context({"svg.hashsalt": "estim"}):
        fig.savefig(buf, format=fmt, dpi=fig.dpi, metadata=meta)
    atomic_write_bytes(path, buf.getvalue())


PACKAGES = ("estim", "numpy", "scipy", "pandas", "matplotlib", "click", "PyYAML")


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def git_commit() -> str | None:
    """The commit of the project checkout this package runs from (with "+dirty" when its
    tracked files differ), or ``None`` outside a git checkout (an installed copy)."""
    import subprocess

    here = Path(__file__).resolve().parents[2]
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


def spec_hash(spec: dict) -> str:
    """sha256 of the resolved config: what ``estim check`` compares with the manifest."""
    text_ = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=float)
    return hashlib.sha256(text_.encode()).hexdigest()


def write_manifest(folder: Path, spec: dict, wall_time_s: float, command: str = "",
                   overrides: dict | None = None, models: dict | None = None) -> None:
    """``manifest.json``: resolved config (every default filled in) and its hash, every model
    the config builds with every parameter, seed and runs, versions, wall time, and the sha256
    of every file written beside it."""
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != "manifest.json")
    mc = spec.get("monte_carlo") or {}
    manifest = {
        "config": spec,
        "config_sha256": spec_hash(spec),
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


def write_tables_and_manifest(folder: Path, tables: dict, spec: dict, wall_time_s: float,
                              command: str = "", overrides: dict | None = None,
                              models: dict | None = None) -> None:
    """Each table as ``<metric>.csv``, then ``manifest.json`` over everything in ``folder``
    (the figures written before it included): how ``estim run`` and ``Result.save`` end a
    result folder."""
    for metric, df in tables.items():
        write_csv(df, folder / f"{metric}.csv")
    write_manifest(folder, spec, wall_time_s, command=command, overrides=overrides,
                   models=models)
