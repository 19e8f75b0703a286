"""Result tables in thesis layout, and the thesis' own tables beside them."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pandas as pd

KEYS = ["table_id", "s_no", "noise_reading", "noise_param", "noise_sigma", "frequency_hz",
        "samples_per_period", "estimator"]

PERTURBATION_KEYS = ["table_id", "s_no", "amplitude_v", "frequency_hz", "row_params"]

METRICS: dict[str, dict] = {
    "rmse": {"file": "rmse.csv", "keys": KEYS,
             "values": ["rmse", "rmse_se", "runs", "diverged"], "thesis": ["rmse"]},
    "residual": {"file": "residual.csv", "keys": KEYS,
                 "values": ["residual_mean", "residual_mean_se", "residual_variance",
                            "residual_variance_se", "runs", "diverged"],
                 "thesis": ["residual_mean", "residual_variance"]},
    "distortion": {"file": "distortion.csv", "keys": PERTURBATION_KEYS,
                   "values": ["percent_distortion", "thd_percent", "gain_db", "output_rms",
                              "err_linear_rms", "err_first_order_rms", "order_linear",
                              "order_first_order", "shooting_iterations"],
                   "thesis": ["percent_distortion"]},
    "gain": {"file": "distortion.csv", "keys": PERTURBATION_KEYS,
             "values": ["gain_db"], "thesis": ["gain_db"]},
}


def thesis_table(table_id: str) -> pd.DataFrame:
    """A thesis table as printed (shipped in :mod:`core.reference`)."""
    name = "table_" + table_id.replace(".", "_") + ".csv"
    with resources.files("core.reference").joinpath(name).open("r") as fh:
        return pd.read_csv(fh, dtype={"noise_param_value": float, "table_id": str})


def _thesis_row_numbers(rows: pd.DataFrame, table_id: str | None) -> pd.Series:
    if table_id is None:
        return pd.Series([pd.NA] * len(rows), dtype="Int64")
    ref = thesis_table(table_id).drop_duplicates("s_no")
    s_no = []
    for level, f in zip(rows["noise_param"], rows["frequency_hz"], strict=True):
        hit = ref[np.isclose(ref["noise_param_value"], level) & np.isclose(ref["frequency_hz"], f)]
        s_no.append(int(hit["s_no"].iloc[0]) if len(hit) else pd.NA)
    return pd.Series(s_no, dtype="Int64")


def result_table(rows: list[dict], metric: str, table_id: str | None) -> pd.DataFrame:
    """The ``metric`` table from analysis rows, with thesis table id and row number."""
    df = pd.DataFrame(rows)
    df.insert(0, "table_id", table_id if table_id else "")
    df.insert(1, "s_no", _thesis_row_numbers(df, table_id))
    return df[KEYS + METRICS[metric]["values"]].reset_index(drop=True)


def distortion_table(rows: list[dict], table_id: str) -> pd.DataFrame:
    """``distortion.csv`` of a perturbation analysis, in thesis row order."""
    df = pd.DataFrame(rows)
    df.insert(0, "table_id", table_id)
    return df[PERTURBATION_KEYS + METRICS["distortion"]["values"]].reset_index(drop=True)


def view(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """The columns of ``metric`` in a stored table (several metrics may share a file)."""
    columns = METRICS[metric]["keys"] + METRICS[metric]["values"]
    return df[[c for c in columns if c in df.columns]]


def with_thesis(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Add ``thesis_<value>`` and ``ratio_<value>`` (ours / thesis) beside each value.

    Rows are matched by thesis row number (``s_no``; ``row_order`` in Table 2.1) and, where
    both tables have one, by estimator.
    """
    named = {value: f"thesis_{value}" for value in METRICS[metric]["thesis"]}
    parts = []
    for table_id, part in view(df, metric).groupby("table_id", sort=False):
        if table_id:
            ref = thesis_table(table_id).rename(columns={"row_order": "s_no", **named})
            on = [c for c in ("s_no", "estimator") if c in part and c in ref]
            ref = ref[on + [c for c in named.values() if c in ref]].drop_duplicates(on)
            part = part.merge(ref.astype({"s_no": float}), how="left",
                              on=on).set_index(part.index)
        parts.append(part.reindex(columns=[*part.columns.drop(named.values(), errors="ignore"),
                                           *named.values()]))
    out = pd.concat(parts).sort_index()
    for value in METRICS[metric]["thesis"]:
        out[f"ratio_{value}"] = out[value] / out[f"thesis_{value}"]
    return out


def claims(rmse: pd.DataFrame, better: str = "EKF", worse: str = "RLS") -> pd.DataFrame:
    """The headline claim of Tables 3.1, 3.2, 3.5 row by row: RMSE of ``better`` < ``worse``.

    A diverged run has an unbounded error, so any divergence of ``better`` fails the claim
    and any divergence of ``worse`` (with none of ``better``) makes it hold; otherwise the
    RMSEs decide.
    """
    keys = ["noise_reading", "noise_param", "frequency_hz"]
    a = rmse.loc[rmse["estimator"] == better, ["s_no", *keys, "rmse", "diverged"]]
    b = rmse.loc[rmse["estimator"] == worse, [*keys, "rmse", "diverged"]]
    joined = a.merge(b, on=keys, suffixes=(f"_{better}", f"_{worse}"))
    ra, rb = joined[f"rmse_{better}"], joined[f"rmse_{worse}"]
    da, db = joined[f"diverged_{better}"], joined[f"diverged_{worse}"]
    joined["ratio"] = ra / rb
    joined["holds"] = pd.array(
        [_verdict(x, y, p, q) for x, y, p, q in zip(ra, rb, da, db, strict=True)],
        dtype="boolean")
    joined.insert(0, "claim", f"{better} RMSE < {worse} RMSE")
    return joined[["claim", "s_no", *keys, f"rmse_{better}", f"rmse_{worse}", "ratio",
                   f"diverged_{better}", f"diverged_{worse}", "holds"]]


def _verdict(better: float, worse: float, diverged_better: int, diverged_worse: int):
    if diverged_better > 0:
        return False
    if diverged_worse > 0:
        return True
    if np.isfinite(better) and np.isfinite(worse):
        return bool(better < worse)
    return pd.NA


def has_thesis_table(table_id: str) -> bool:
    name = "table_" + table_id.replace(".", "_") + ".csv"
    return resources.files("core.reference").joinpath(name).is_file()


def render(df: pd.DataFrame, fmt: str) -> str:
    """Text, CSV, Markdown or LaTeX rendering of a table."""
    if fmt == "csv":
        return df.to_csv(index=False)
    if fmt == "markdown":
        return df.to_markdown(index=False, floatfmt=".4g")
    if fmt == "latex":
        return df.to_latex(index=False, float_format="%.4g", na_rep="--")
    return df.to_string(index=False, float_format=lambda v: f"{v:.4g}", na_rep="--")
