"""What a result folder holds, written file by file into the folder a
:class:`~estim.store.folders.ResultFolder` holds open: each table as CSV, each figure,
``manifest.json`` (tracked: the resolved config and its hash, the models, seed and runs, the
numeric packages' versions and the sha256 of every file beside it) and ``run.json``
(untracked: command, commit, wall time, host); what measures the machine goes under
``machine/`` (untracked)."""

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
    software tag (the same figure gives the same bytes), written atomically. Its axes'
    titles and labels (:func:`estim.experiments.shared.plots.style.described`) go into the
    file's description (PNG and SVG ``Description``, PDF ``Subject``)."""
    fmt = path.suffix.lstrip(".").lower() or "png"
    if fmt not in FIGURE_FORMATS:
        raise ValueError(f"figure format {fmt!r}: expected one of {FIGURE_FORMATS}")
    described = getattr(fig, "estim_description", None)
    meta = {"png": {"Software": None, "Description": described},
            "pdf": {"Creator": None, "Producer": None, "CreationDate": None,
                    "Subject": described},
            "svg": {"Creator": None, "Date": None, "Description": described}}[fmt]
    meta = {k: v for k, v in meta.items() if v is not None or k != "Description" and
            k != "Subject"}
    buf = io.BytesIO()
    import matplotlib

    from estim.util.drawing import DRAWING

    with DRAWING, matplotlib.rc_context({"svg.hashsalt": "estim"}):
        fig.savefig(buf, format=fmt, dpi=fig.dpi, metadata=meta)
    atomic_write_bytes(path, buf.getvalue())


NUMERIC_PACKAGES = ("numpy", "scipy", "pandas", "matplotlib", "numba", "llvmlite",
                    "PyWavelets", "scikit-image")
"""The packages whose versions the tables and figures can depend on: recorded, with
Python's, in the tracked manifest."""

OTHER_PACKAGES = ("estim", "click", "PyYAML", "rich")
"""Recorded in the run record only: they change no number."""

MACHINE_DIR = "machine"
"""The sub-folder of a result folder holding what measures the machine that ran it (an
analysis' ``MACHINE`` tables and figures: wall times); git ignores it (``.gitignore``) and
``estim check`` does not compare it."""

RUN_RECORD = "run.json"
"""The untracked run record beside ``manifest.json``: command, commit, wall time, host, every
package's version and the sha256 of the machine files (git ignores it)."""


def versions(packages: tuple[str, ...] = NUMERIC_PACKAGES) -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in packages:
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


def host() -> dict[str, object]:
    """The machine a run ran on, for the run record."""
    import os

    return {"node": platform.node(), "machine": platform.machine(),
            "processor": platform.processor(), "system": platform.platform(),
            "cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
            else os.cpu_count()}


def write_manifest(folder: Path, spec: dict, wall_time_s: float, command: str = "",
                   overrides: dict | None = None, models: dict | None = None) -> None:
    """Two records of a result folder:

    * ``manifest.json`` (tracked): what the tables depend on, the same on every run of the
      same config with the same numeric packages: the resolved config (every default
      filled in) and its hash, every model the config builds with every parameter, seed,
      runs, overrides, the numeric packages' versions and the sha256 of every file beside it
      but the machine files;
    * ``run.json`` (:data:`RUN_RECORD`, untracked): how this run went: command, commit,
      wall time, host, every package's version and the sha256 of the machine files
      (:data:`MACHINE_DIR`)."""
    files = sorted(p for p in folder.rglob("*") if p.is_file()
                   and p.name not in ("manifest.json", RUN_RECORD))
    machine = [p for p in files if p.relative_to(folder).parts[0] == MACHINE_DIR]
    mc = spec.get("monte_carlo") or {}
    manifest = {
        "config": spec,
        "config_sha256": spec_hash(spec),
        "models": models or {},
        "seed": mc.get("seed"),
        "runs": mc.get("runs"),
        "overrides": overrides or {},
        "versions": versions(),
        "files": {str(p.relative_to(folder)): sha256(p) for p in files if p not in machine},
    }
    record = {
        "command": command,
        "git_commit": git_commit(),
        "wall_time_s": round(wall_time_s, 3),
        "host": host(),
        "versions": versions(NUMERIC_PACKAGES + OTHER_PACKAGES),
        "machine_files": {str(p.relative_to(folder)): sha256(p) for p in machine},
    }
    for name, data in ((RUN_RECORD, record), ("manifest.json", manifest)):
        text = json.dumps(data, indent=2, sort_keys=True, default=float) + "\n"
        atomic_write_bytes(folder / name, text.encode())


def table_path(folder: Path, metric: str, machine: tuple[str, ...] = ()) -> Path:
    """Where table ``metric`` is written: ``<metric>.csv``, or under :data:`MACHINE_DIR`
    when it measures the machine (``machine``: the analysis' ``MACHINE`` names)."""
    return (folder / MACHINE_DIR if metric in machine else folder) / f"{metric}.csv"


def figure_path(folder: Path, name: str, figure_format: str,
                machine: tuple[str, ...] = ()) -> Path:
    """Where figure ``name`` is written: ``figures/``, or ``machine/figures/``."""
    return (folder / MACHINE_DIR if name in machine else folder) / "figures" / \
        f"{name}.{figure_format}"


def write_tables_and_manifest(folder: Path, tables: dict, spec: dict, wall_time_s: float,
                              command: str = "", overrides: dict | None = None,
                              models: dict | None = None,
                              machine: tuple[str, ...] = ()) -> None:
    """Each table as ``<metric>.csv`` (:func:`table_path`), then ``manifest.json`` and
    ``run.json`` over everything in ``folder`` (the figures written before it included):
    how ``estim run`` and ``Result.save`` end a result folder."""
    for metric, df in tables.items():
        path = table_path(folder, metric, machine)
        path.parent.mkdir(exist_ok=True)
        write_csv(df, path)
    write_manifest(folder, spec, wall_time_s, command=command, overrides=overrides,
                   models=models)
