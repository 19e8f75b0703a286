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
    return "\n".join([view.to_string(float_format=lambda v: f"{v:.4g}"),
                      *broken_lines(df, result.tables.get("health"))])


def broken_lines(rmse, health=None) -> list[str]:
    """One line per estimator whose every run broke (its estimate became non-finite or left
    the filter's bound) in some rows of the ``rmse`` table: those rows' RMSEs are infinite
    and their health columns empty, which a reader should not have to find out alone. With
    the ``health`` table, the line says where the earliest run broke and why."""
    lines = []
    if not {"estimator", "runs", "diverged"} <= set(rmse.columns):
        return lines
    for name, rows in rmse.groupby("estimator", sort=False):
        every = rows[(rows["runs"] > 0) & (rows["diverged"] >= rows["runs"])]
        if len(every):
            lines.append(f"note: {name} broke in every run of {len(every)} of {len(rows)} "
                         f"rows (a non-finite estimate or one beyond divergence_bound"
                         f"{_first(health, name)}): its RMSE is inf there; for a UKF, a "
                         "smaller alpha keeps its sigma points inside the circuit's range "
                         "(docs/your-circuit.md)")
    return lines


def _first(health, name: str) -> str:
    """``"; first at step k, state s: cause"`` of the estimator's earliest broken run in the
    ``health`` table, or nothing."""
    if health is None or "first_break_step" not in health:
        return ""
    rows = health[(health["estimator"] == name) & health["first_break_step"].notna()]
    if not len(rows):
        return ""
    row = rows.loc[rows["first_break_step"].astype(float).idxmin()]
    where = f", {row['first_break_state']}" if str(row["first_break_state"]) not in (
        "", "nan") else ""
    why = f": {row['first_break_cause']}" if str(row["first_break_cause"]) not in (
        "", "nan") else ""
    return f"; the first at step {int(row['first_break_step'])}{where}{why}"
