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

from core.errors import UsageError

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


def ensure_writable(folder: Path) -> None:
    """Create ``folder`` and prove a file can be written in it, before any work starts.

    Raises :class:`core.errors.UsageError` naming the folder and the reason.
    """
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".estim-probe.", suffix=".tmp")
        os.close(fd)
        Path(probe).unlink()
    except OSError as exc:
        raise UsageError(f"cannot write to {folder} ({exc.strerror or exc})") from None


def write_manifest(folder: Path, spec: dict, config_sha256: str, wall_time_s: float,
                   command: str = "") -> None:
    """``manifest.json``: resolved config and its hash, seed and runs, versions, wall time,
    and the sha256 of every file written beside it."""
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name != "manifest.json")
    mc = spec.get("monte_carlo") or {}
    manifest = {
        "config": spec,
        "config_sha256": config_sha256,
        "seed": mc.get("seed"),
        "runs": mc.get("runs"),
        "command": command,
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

    NaN equals NaN. ``skip: reason`` leaves a column out (the reason is shown by the CLI).
    Non-numeric columns must match exactly. A change of shape is one difference.
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
                if np.isnan(x) and np.isnan(y):
                    continue
                if not np.isnan(x - y) and _cell_tolerated(x, y, i, tol, stored, new, col):
                    continue
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": x - y})
            elif not (pd.isna(x) and pd.isna(y)) and str(x) != str(y):
                diffs.append({"row": i, "column": col, "expected": y, "obtained": x,
                              "difference": ""})
    return diffs
