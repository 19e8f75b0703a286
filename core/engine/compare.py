"""The comparison of stored and new tables under each column's tolerance (``estim check``,
docs/checking.md)."""

from __future__ import annotations

import numpy as np

from estim.config.loading import Tolerance
from estim.util import lazy

pd = lazy.load("pandas")


def _cell_tolerated(x: float, y: float, i: int, tol: Tolerance, stored: pd.DataFrame,
                    new: pd.DataFrame, col: str) -> bool:
    """Whether the new value ``x`` passes against the stored ``y`` (row ``i`` of ``col``)."""
    if abs(x - y) <= tol.atol + tol.rtol * abs(y):
        return True
    if tol.se is not None:
        se_col = tol.se_column or f"{col}_se"
        if se_col in stored and se_col in new:
            se = np.hypot(float(stored[se_col].iloc[i]), float(new[se_col].iloc[i]))
            if np.isfinite(se) and abs(x - y) <= tol.se * se:
                return True
    if tol.binomial is not None:
        trials = tol.trials or []
        if trials and all(c in stored for c in trials):
            n = float(sum(stored[c].iloc[i] for c in trials))
            p = (x + y) / (2 * n) if n > 0 else 0.0
            spread = np.sqrt(2 * n * p * (1 - p)) if 0 < p < 1 else 0.0
            if abs(x - y) <= tol.binomial * spread:
                return True
    return False


def _too_few_runs(tol: Tolerance, stored: pd.DataFrame, new: pd.DataFrame, col: str,
                  i: int) -> bool:
    """With an ``se`` criterion: a mean whose standard error is undefined on either side
    (fewer than two runs behind it, e.g. all runs but one diverged) is no Monte Carlo
    estimate to compare; the run counts beside it are compared instead."""
    if tol.se is None:
        return False
    se_col = tol.se_column or f"{col}_se"
    if se_col not in stored or se_col not in new:
        return False
    return bool(pd.isna(stored[se_col].iloc[i]) or pd.isna(new[se_col].iloc[i]))


def compare_tables(stored: pd.DataFrame, new: pd.DataFrame,
                   tolerances: dict[str, dict | Tolerance]) -> list[dict]:
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
        tol = tolerances.get(col) or {}
        tol = tol if isinstance(tol, Tolerance) else Tolerance(**tol)   # its declared defaults
        if tol.skip:
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
