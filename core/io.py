"""Atomic writes, manifests and the comparison of stored and new tables.

These functions take paths from their caller (the CLI); nothing here picks a location.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import platform
import tempfile
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

_UMASK = os.umask(0)
os.umask(_UMASK)

PACKAGES = ("estim", "numpy", "scipy", "pandas", "matplotlib", "click", "PyYAML")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path`` and rename it into place."""
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


def remove_stale(folder: Path, produced: set[str]) -> None:
    """Delete tables, figures and temporary files in ``folder`` that this run did not write."""
    for path in list(folder.rglob("*")):
        rel = str(path.relative_to(folder))
        stale = path.suffix in (".csv", ".png") and rel not in produced
        if path.is_file() and (stale or path.name.endswith(".tmp")):
            path.unlink()


def write_csv(df: pd.DataFrame, path: Path) -> None:
    """Tidy CSV; floats as repr, so they round-trip."""
    atomic_write_bytes(path, df.to_csv(index=False, lineterminator="\n").encode())


def write_figure(fig, path: Path) -> None:
    """PNG without a timestamp or software tag, written atomically."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi, metadata={"Software": None})
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


def write_manifest(folder: Path, spec: dict, seed: int, runs: int, wall_time_s: float) -> None:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != "manifest.json")
    manifest = {
        "config": spec,
        "seed": seed,
        "runs": runs,
        "versions": versions(),
        "wall_time_s": round(wall_time_s, 3),
        "files": {str(p.relative_to(folder)): sha256(p) for p in files},
    }
    text = json.dumps(manifest, indent=2, sort_keys=True, default=float) + "\n"
    atomic_write_bytes(folder / "manifest.json", text.encode())


def compare_tables(stored: pd.DataFrame, new: pd.DataFrame,
                   tolerances: dict[str, dict]) -> list[dict]:
    """Cells that differ. Floats use ``|a - b| <= atol + rtol |b|`` (per column, default exact);
    NaN equals NaN; other columns must match exactly. Shape changes are one difference."""
    if list(stored.columns) != list(new.columns) or len(stored) != len(new):
        return [{"row": "-", "column": "(shape)",
                 "expected": f"{len(stored)} rows {list(stored.columns)}",
                 "obtained": f"{len(new)} rows {list(new.columns)}", "difference": ""}]
    diffs = []
    for col in stored.columns:
        a, b = new[col], stored[col]
        numeric = pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b)
        for i in range(len(a)):
            x, y = a.iloc[i], b.iloc[i]
            if numeric:
                x, y = float(x) if pd.notna(x) else np.nan, float(y) if pd.notna(y) else np.nan
                if np.isnan(x) and np.isnan(y):
                    continue
                tol = tolerances.get(col, {})
                limit = tol.get("atol", 0.0) + tol.get("rtol", 0.0) * abs(y)
                if not np.isnan(x - y) and abs(x - y) <= limit:
                    continue
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": x - y})
            elif not (pd.isna(x) and pd.isna(y)) and str(x) != str(y):
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": ""})
    return diffs
