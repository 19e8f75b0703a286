"""The figures of an estimation experiment (Figs 3.2-3.7, 3.9-3.11), drawn from the traces of
the batches the analysis simulated (:mod:`estim.experiments.estimation` chooses them)."""

from __future__ import annotations

from estim.config.experiment import Experiment
from estim.config.settings import file_name, validate
from estim.errors import ConfigError
from estim.experiments.estimation import parameters as estimated
from estim.experiments.estimation import source as waveforms
from estim.experiments.estimation.config import FIGURE_KINDS
from estim.experiments.shared import plots
from estim.numerics import metrics

__all__ = ["FIGURE_KINDS", "figures", "traces"]


def check(config, source: str) -> None:
    """The figures' file names: known kinds, valid names, none shared."""
    names = config.figures.names
    for kind, name in names.items():
        if kind not in FIGURE_KINDS:
            raise ConfigError(source, f"figures.names.{kind}",
                              f"unknown figure kind; expected one of {list(FIGURE_KINDS)}")
        validate(name, file_name, source, f"figures.names.{kind}")
    used = {names.get(kind, kind): f"figures.names.{kind}" for kind in FIGURE_KINDS}
    if len(used) < len(FIGURE_KINDS):
        raise ConfigError(source, "figures.names", "two figure kinds share one file name")
    for i, extra in enumerate(config.figures.extra_noisy):
        if extra.name in used:
            raise ConfigError(source, f"figures.extra_noisy[{i}].name",
                              f"{extra.name!r} is already the file of {used[extra.name]}")
        used[extra.name] = f"figures.extra_noisy[{i}].name"


def traces(exp: Experiment, data: dict, estimates: list, diverged: list) -> dict:
    """What a figure draws of a batch: run 0's signals and every estimator's running RMSE
    over the runs that did not diverge."""
    labels = [label for label, _, _ in exp.plan.filters]
    pairs = list(zip(labels, estimates, strict=True))
    kept = dict(zip(labels, diverged, strict=True))
    return {
        "t": data["t"], "source": data["source"][0, 1:, 0], "clean": data["clean"][1:, 0],
        "actual": data["actual"][0, :, 0], "z": data["z"][0, :, 0],
        "y_hat": {lab: e.y_hat[0, :, 0] for lab, e in pairs},
        "innovation": {lab: e.innovation[0, :, 0] for lab, e in pairs},
        "running_rmse": {lab: metrics.running_rmse(data["actual"][~kept[lab]],
                                                   e.y_hat[~kept[lab]]) for lab, e in pairs},
        "parameters": (estimated.traces(exp.plan.filters, estimates, exp.plan.theta)
                       if exp.plan.parameters else {}),
    }


def figures(exp: Experiment, data: dict, f: float, level: float, reading: str) -> dict:
    """Figs 3.2-3.7, 3.9-3.11 from the traces ``data`` (:func:`traces` of each figure batch,
    by key): estimates without and with input noise, running RMSE, residuals and the
    estimated values (the kinds of ``figures.kinds``), under the names of ``figures.names``;
    ``f``, ``level`` and ``reading`` are the noisy batch's."""
    names = exp.config.figures.names
    what = exp.title
    period = 1.0 / f

    def noise(level: float, reading: str) -> str:
        return (f"input noise σ = {level:g} V" if reading == "sigma"
                else f"input noise variance = {level:g} V²")

    source = waveforms.label(exp.config.input, f)
    where = f"{source}, {noise(level, reading)}"
    makers = {
        "noiseless": lambda: plots.estimates(data["noiseless"], f"{what}; {source}, no input "
                                             "noise", period),
        "noisy": lambda: plots.estimates(data["noisy"], f"{what}; {where}", period),
        "rmse": lambda: plots.running_rmse(data["noisy"], f"RMSE over runs: {what}; {where}"),
        "residual": lambda: plots.residuals(data["noisy"], f"Residual (run 1): {what}; {where}"),
        "parameters": lambda: plots.parameters(data["noisy"]["t"], data["noisy"]["parameters"],
                                               f"Estimated values (run 1): {what}; {where}"),
    }
    out = {names.get(kind, kind): makers[kind]() for kind in exp.config.figures.kinds
           if kind != "parameters" or exp.plan.parameters}
    for extra in exp.config.figures.extra_noisy:
        title = f"{what}; {source}, {noise(extra.noise_level, extra.reading)}"
        out[extra.name] = plots.estimates(data[extra.name], title, period)
    return out
