"""The per-point pipeline every estimation table shares (Chapters 3 and 4): each filter's
health and divergence on a batch (:mod:`estim.experiments.shared.health`), its RMSE over all runs
and over the runs that did not diverge, its residual statistics, the raw measurement's row beside
it, the thesis row each of our rows joins, and the claims judged on the per-run losses
(:mod:`estim.experiments.shared.claims`)."""

from __future__ import annotations

import numpy as np

from estim import reference
from estim.config.experiment import Experiment
from estim.errors import ConfigError
from estim.estimators import breaks
from estim.experiments.shared import claims, health
from estim.numerics import metrics
from estim.util import lazy

pd = lazy.load("pandas")

MEASUREMENT = "measurement"
"""Label of the baseline row: the raw measurement taken as the estimate."""

RMSE_VALUES = ("rmse", "rmse_se", "rmse_median", "runs", "diverged", "rmse_kept",
               "rmse_kept_se")
"""RMSE over every run (the headline; a run whose estimate broke counts as an infinite
error), its standard error and median, the runs and how many diverged, and the RMSE over
the runs that did not diverge."""
HEALTH_VALUES = ("runs", "broken", "diverged", "inconsistent", "nees_mean", "nees_in_band",
                 "nis_mean", "nis_in_band", "white_fraction", "whiteness_lag")
BREAK_VALUES = ("first_break_step", "first_break_state", "first_break_cause")
"""The earliest broken run of a row (:func:`estim.estimators.breaks.first_break`): its step
(1: the first sample after ``t_0``), the state and the cause its filter found (empty
where the filter gives none, or no run broke)."""

def judge(exp: Experiment, data: dict, est, model) -> dict:
    """One estimator's health on one batch (:mod:`estim.experiments.shared.health`): per run
    ``diverged`` (the estimate broke or ran away), ``broken`` and ``inconsistent`` (NIS or NEES
    outside its band; NaN-free only for filters with a noise model), and the batch summaries."""
    cfg = exp.config.health
    nis = None if est.S is None else health.nis(est.innovation, est.S)
    nees = None
    if est.x_hat is not None and est.P is not None and est.x_hat.shape == data["states"].shape:
        nees = health.nees(data["states"], est.x_hat, est.P)
    out = {"diverged": health.diverged(est, data["actual"], model.output_range(),
                                       cfg.consecutive, cfg.growth),
           "broken": np.asarray(est.broken, bool),
           "inconsistent": health.inconsistent(nis, est.innovation.shape[-1], nees,
                                               0 if est.x_hat is None else est.x_hat.shape[-1],
                                               cfg.band)}
    nan = float("nan")
    out["nees_mean"] = out["nees_in_band"] = out["nis_mean"] = out["nis_in_band"] = nan
    if nees is not None:
        out["nees_mean"], out["nees_in_band"] = health.averaged_in_band(
            nees, est.x_hat.shape[-1], cfg.band)
    if nis is not None:
        out["nis_mean"], out["nis_in_band"] = health.averaged_in_band(
            nis, est.innovation.shape[-1], cfg.band)
    out["white_fraction"] = float(np.mean(health.white(
        est.innovation, cfg.whiteness_lag, cfg.whiteness_level)))
    out["whiteness_lag"] = health.effective_lag(est.innovation.shape[1], cfg.whiteness_lag)
    for key in ("regressor_rank", "regressor_size", "lambda_at_floor", "p_max_eig"):
        values = np.asarray(est.diagnostics.get(key, []), float)
        finite = values[np.isfinite(values)]
        out[key] = float(np.median(finite)) if finite.size else nan
    steps = est.diagnostics.get("broken_step")
    if steps is None:                   # a filter that does not say why: the step alone
        steps = breaks.break_steps(est.x_hat if est.x_hat is not None else est.y_hat,
                                   est.broken)
    names = tuple(model.state_names) if est.x_hat is not None else ()
    out.update(zip(BREAK_VALUES, breaks.first_break(
        steps, est.diagnostics.get("broken_state"), est.diagnostics.get("broken_cause"),
        names), strict=True))
    return out


def rmse_columns(actual: np.ndarray, y_hat: np.ndarray, diverged: np.ndarray) -> tuple[dict,
                                                                                       np.ndarray]:
    """The RMSE columns (:data:`RMSE_VALUES`) of one estimator on one batch, and its per-run
    RMSE (a run whose estimate is not finite has an infinite error): the loss its claims
    compare."""
    with np.errstate(invalid="ignore", over="ignore"):
        per_run = metrics.rmse_per_run(actual, y_hat)
    per_run = np.where(np.isfinite(per_run), per_run, np.inf)
    if np.isinf(per_run).any():
        mean, se = float("inf"), float("nan")
    else:
        mean, se = metrics.mean_and_se(per_run)
    kept, kept_se = metrics.mean_and_se(per_run[~diverged])
    return {"rmse": mean, "rmse_se": se, "rmse_median": float(np.median(per_run)),
            "runs": int(per_run.size), "diverged": int(diverged.sum()), "rmse_kept": kept,
            "rmse_kept_se": kept_se}, per_run


STATE_VALUES = ("rmse", "rmse_se", "rmse_kept", "rmse_kept_se", "runs", "diverged")
"""The per-state table's columns: :data:`RMSE_VALUES` of one state's estimate."""


def state_rows(data: dict, filters: tuple, estimates: list, verdicts: list,
               common: dict) -> list[dict]:
    """One row per filter and state: the RMSE (eq 3.42, of each state instead of the output)
    of the filter's estimate against the actual state, over every run (a broken run's error
    is infinite) and over the runs that did not diverge (``verdicts``). A filter with no
    estimate in the actual circuit's states (the RLS) has none. A state the model reports
    in other units (an estimated value, ``value_scales``) is in those."""
    rows = []
    truth = data["states"]
    for (label, _, model, *_), est, diverged in zip(filters, estimates, verdicts,
                                                      strict=True):
        if est.x_hat is None or est.x_hat.shape != truth.shape:
            continue
        scales = getattr(model, "value_scales", (1.0,) * len(model.state_names))
        for j, (name, s) in enumerate(zip(model.state_names, scales, strict=True)):
            columns, _ = rmse_columns(s * truth[..., j:j + 1], s * est.x_hat[..., j:j + 1],
                                      diverged)
            rows.append({**common, "estimator": label, "state": name,
                         **{key: columns[key] for key in STATE_VALUES}})
    return rows


OUTPUT_VALUES = (*RMSE_VALUES, "residual_mean", "residual_variance")
"""The per-output table's columns: :data:`RMSE_VALUES` and the residual's mean and variance
over the runs that did not diverge, of one measured quantity."""


def output_rows(data: dict, filters: tuple, estimates: list, verdicts: list, common: dict,
                names: tuple) -> list[dict]:
    """One row per measured quantity (``names``) for the raw measurement and each filter:
    the RMSE columns (eq 3.42 of that quantity alone) and its residual's mean and variance
    (over the runs that did not diverge; none for the measurement)."""
    rows = []
    none = np.zeros(data["z"].shape[0], bool)
    nan = float("nan")
    for j, name in enumerate(names):
        actual = data["actual"][..., j:j + 1]
        columns, _ = rmse_columns(actual, data["z"][..., j:j + 1], none)
        rows.append({**common, "estimator": MEASUREMENT, "output": name, **columns,
                     "residual_mean": nan, "residual_variance": nan})
        for (label, *_), est, diverged in zip(filters, estimates, verdicts, strict=True):
            columns, _ = rmse_columns(actual, est.y_hat[..., j:j + 1], diverged)
            res_mean, res_var = metrics.residual_stats(est.innovation[~diverged][..., j:j + 1])
            rows.append({**common, "estimator": label, "output": name, **columns,
                         "residual_mean": metrics.mean_and_se(res_mean)[0],
                         "residual_variance": metrics.mean_and_se(res_var)[0]})
    return rows


def score(exp: Experiment, data: dict, filters: tuple, estimates: list, common: dict,
          measured: str = "") -> tuple[list[dict], dict, list]:
    """Rows of every table for one batch: the raw measurement's row, then one per filter
    (``filters``: ``(label, estimator, model, ...)``, with their ``estimates``), each with
    its RMSE and residual columns of the first measured quantity (:func:`output_rows` gives
    each, where there are several) and its health over all of them; the per-run losses of
    every row for the claims; and each filter's per-run divergence flags. ``measured``
    names what the measurement row measures, when the table says."""
    actual = data["actual"][..., :1]          # the first measured quantity (output_rows: each)
    raw = metrics.rmse_per_run(actual, data["z"][..., :1])
    none = np.zeros(raw.size, bool)
    columns, _ = rmse_columns(actual, data["z"][..., :1], none)
    rows = [{**common, **columns, "estimator": MEASUREMENT, "broken": 0,
             **({"measures": measured} if measured else {})}]
    losses = {MEASUREMENT: claims.Losses(raw)}
    verdicts = []
    for (label, _, model, *_), est in zip(filters, estimates, strict=True):
        verdict = judge(exp, data, est, model)
        diverged = verdict["diverged"]
        verdicts.append(diverged)
        columns, per_run = rmse_columns(actual, est.y_hat[..., :1], diverged)
        ok = ~diverged
        res_mean, res_var = metrics.residual_stats(est.innovation[ok][..., :1])
        mean, mean_se = metrics.mean_and_se(res_mean)
        var, var_se = metrics.mean_and_se(res_var)
        flags = verdict["inconsistent"]
        rows.append({
            **common, **{k: v for k, v in verdict.items()
                         if k not in ("diverged", "broken", "inconsistent")},
            **columns, "estimator": label,
            "broken": int(verdict["broken"].sum()),
            "inconsistent": float("nan") if flags is None else int(flags.sum()),
            "residual_mean": mean, "residual_mean_se": mean_se,
            "residual_variance": var, "residual_variance_se": var_se,
        })
        losses[label] = claims.Losses(per_run, diverged)
    return rows, losses, verdicts


def thesis_row_numbers(rows: pd.DataFrame, table_id: str | None) -> pd.Series:
    """The thesis row (``s_no``) of each of our rows: same noise number and frequency (none
    where ``table_id`` is a label of our own, not a thesis table)."""
    if table_id is None or not reference.has_reference_table(table_id):
        return pd.Series([pd.NA] * len(rows), dtype="Int64")
    ref = reference.reference_table(table_id).drop_duplicates("s_no")
    s_no = []
    for level, f in zip(rows["noise_param"], rows["frequency_hz"], strict=True):
        hit = ref[np.isclose(ref["noise_param_value"], level) & np.isclose(ref["frequency_hz"], f)]
        s_no.append(int(hit["s_no"].iloc[0]) if len(hit) else pd.NA)
    return pd.Series(s_no, dtype="Int64")


def check_claims(declared, labels: list[str], source: str) -> None:
    """The config's ``claims`` each compare two of the estimators ``labels`` (a
    ``ConfigError`` at ``claims[i].better`` or ``.worse`` otherwise)."""
    for i, claim in enumerate(declared):
        for side in ("better", "worse"):
            label = getattr(claim, side)
            if label not in labels:
                raise ConfigError(source, f"claims[{i}].{side}",
                                  f"expected an estimator label {labels}, got {label!r}")
        if claim.better == claim.worse:
            raise ConfigError(source, f"claims[{i}].worse", "the same estimator as better: "
                              "a claim compares two")


def claim_pairs(config) -> list[tuple[str, str]]:
    """The claims an estimation table judges: the config's ``claims`` (the thesis' headline),
    then every filter against the raw measurement."""
    pairs = [(c.better, c.worse) for c in config.claims]
    pairs += [(e.label, MEASUREMENT) for e in config.estimators
              if (e.label, MEASUREMENT) not in pairs]
    return pairs


def claims_table(config, rmse: pd.DataFrame, losses: list[dict],
                 keys: tuple[str, ...]) -> pd.DataFrame:
    """The claims of :func:`claim_pairs` judged by :mod:`estim.experiments.shared.claims` in every
    cell; a cell is named by the ``keys`` of its rows in ``rmse`` (its first row per cell, in
    order)."""
    firsts = rmse[rmse["estimator"] == MEASUREMENT]
    cells = [(claims.cell(**{k: row[k] for k in keys}), cell_losses)
             for (_, row), cell_losses in zip(firsts.iterrows(), losses, strict=True)]
    return claims.table(cells, claim_pairs(config), "RMSE")


