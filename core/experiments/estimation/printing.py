"""What ``estim run`` prints of an estimation experiment: the RMSE by estimator and sweep
point, and a line for each estimator that broke in every run of some rows."""

from __future__ import annotations

from estim.experiments.base import Result


def printout(result: Result) -> str:
    """RMSE by estimator (columns) and sweep point (rows), then a line for each estimator
    that broke in every run of some rows (:func:`broken_lines`)."""
    df = result.tables.get("rmse")
    if df is None:
        return ""
    view = df.pivot(index=["measurement", "noise_reading", "noise_param", "frequency_hz"],
                    columns="estimator", values="rmse")
    return "\n".join([view.to_string(float_format=lambda v: f"{v:.4g}"), *broken_lines(df)])


def broken_lines(rmse) -> list[str]:
    """One line per estimator whose every run broke (its estimate became non-finite or left
    the filter's bound) in some rows of the ``rmse`` table: those rows' RMSEs are infinite
    and their health columns empty, which a reader should not have to find out alone."""
    lines = []
    if not {"estimator", "runs", "diverged"} <= set(rmse.columns):
        return lines
    for name, rows in rmse.groupby("estimator", sort=False):
        every = rows[(rows["runs"] > 0) & (rows["diverged"] >= rows["runs"])]
        if len(every):
            lines.append(f"note: {name} broke in every run of {len(every)} of {len(rows)} "
                         "rows (a non-finite estimate or one beyond divergence_bound): its "
                         "RMSE is inf there; for a UKF, a smaller alpha keeps its sigma "
                         "points inside the circuit's range (docs/your-circuit.md)")
    return lines
