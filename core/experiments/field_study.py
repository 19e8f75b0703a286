"""Studies of the Chapter 5 field filter (D61): one ``dipole_field`` experiment run over a
list of values of one setting (the grid's points per side, the sensor fraction, the
ensemble size), everything else as configured. For each value the same cycle as
``dipole_field`` (:func:`estim.experiments.dipole_field.cycle`): the field filter (LETKF), the
source-only ETKF, the amplitude-only fit, the plain simulation, RLS and the raw nearest
sensor, with their RMSE per zone, component and part.

The first noise row of the config is run (the thesis' source-noise rows do not enter the
field, D59). A figure shows the relative RMSE of the real part against the value.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.experiment import Experiment
from estim.config.settings import REQUIRED, Settings, block, list_of, number, settings_class, text
from estim.config.settings import setting as declare
from estim.errors import ConfigError
from estim.experiments import dipole_field as field
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")

SETTINGS = {"grid.n": int, "sensors.fraction": float, "filter.members": int}
"""The settings a study may vary, and their type."""
IN_WORDS = {"grid.n": "grid points per side", "sensors.fraction":
            "fraction of grid points with a sensor", "filter.members": "ensemble members"}
"""Each setting of :data:`SETTINGS` as its figure names it."""


@settings_class
class StudySettings(Settings):
    """The setting varied and its values."""

    setting: str = declare(REQUIRED, text(set(SETTINGS)), doc="the setting varied")
    values: list = declare(REQUIRED, list_of(number(positive=True, maximum=1e4),
                                             max_length=12),
                           doc="its values, one experiment each")


@settings_class
class Config(field.Config):
    """The field filter over one setting's values (D61)."""

    study: StudySettings = block(StudySettings, required=True, doc="the setting varied")


SCHEMA: dict = Config.schema()

_KEYS = ("study", "value", "scenario", "zone", "beta_r", "estimator", "field_component",
         "part")
TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS, ("rmse", "rmse_se", "runs", "field_rms", "relative",
                                          "sensors", "members"),
                      title="RMSE of the fields against the analytic dipole, per value of the "
                            "studied setting"),
    "claims": claims.TABLE,
}
QUOTES = (Quote("relative RMSE (RMSE / field RMS)", "rmse", "relative", by="estimator"),)
CLAIMS = ((field.KF, field.FIT), (field.KF, field.PLAIN), (field.KF, field.SOURCE_ONLY))
"""At each value: the field filter against the amplitude-only fit, the plain simulation and
the source-only ETKF."""


@dataclass(frozen=True)
class Plan:
    """Per value: the experiment ``dipole_field`` would run with it."""

    experiments: tuple


def _with(config: Config, path: str, value) -> field.Config:
    """The ``dipole_field`` config of one value of the study: ``config`` without its study
    block, with the studied setting (``block.key``) set to ``value``."""
    head, key = path.split(".")
    values = {f.name: getattr(config, f.name) for f in dataclasses.fields(field.Config)}
    values[head] = dataclasses.replace(values[head], **{key: SETTINGS[path](value)})
    return field.Config(**values)


def prepare(config: Config, source: str) -> Plan:
    study = config.study
    if not study.values:
        raise ConfigError(source, "study.values", "expected at least one value")
    exps = []
    for i, value in enumerate(study.values):
        kind = SETTINGS[study.setting]
        if kind is int and value != int(value):
            raise ConfigError(source, f"study.values[{i}]", f"expected a whole number for "
                              f"{study.setting}")
        try:
            one = _with(config, study.setting, value)
            plan = field.prepare(one, source)
        except ConfigError as e:
            raise ConfigError(source, f"study.values[{i}]", f"{study.setting} = {value:g}: "
                              f"{e.path}: {e.message}") from None
        except ValueError as e:             # the setting's own check (Settings.__post_init__)
            raise ConfigError(source, f"study.values[{i}]", f"{study.setting} = {value:g}: "
                              f"{e}") from None
        exps.append(Experiment(name=f"{study.setting}={value:g}", source=source,
                               spec=one.to_spec(), plan=plan, config=one))
    return Plan(experiments=tuple(exps))


def work_size(config: Config) -> int:
    return sum(field.work_size(_with(config, config.study.setting, v))
               for v in config.study.values)


def _tasks(exp: Experiment) -> list[tuple]:
    return [(v, s, r) for v in range(len(exp.plan.experiments))
            for s in range(len(exp.config.scenarios))
            for r in range(exp.config.monte_carlo.runs)]


def work_units(exp: Experiment) -> int:
    return len(_tasks(exp))


def tiny(config: Config) -> dict:
    """The field filter's quick profile, with two values of the studied setting."""
    values = {"grid.n": [8, 12], "sensors.fraction": [0.05, 0.1], "filter.members": [4, 6]}
    return {**field.tiny(config), "study.values": values[config.study.setting]}


def _one(args) -> dict:
    """One value, scenario and run: per (estimator, zone, component, part) the mean squared
    error and the mean squared truth."""
    exp, v, s, run = args
    one = exp.plan.experiments[v]
    su = field.setup(one.config, one.plan, field.layout(one.config, one.plan, run))
    scenario = one.config.scenarios[s]
    rng = exp.config.monte_carlo.rng(v, s, run)
    out = field.cycle(one, su, field.amplitude(scenario.nominal_amplitude), rng)
    smooth = field.smoothed(out["measured"], out["times"], su.dipole.omega, one.config.rls)
    return field.run_errors(one, one.plan.grid, out["phasors"], su.dipole, su.layout.sensors,
                         out["times"], out["traces"], out["measured"], smooth, su.quarter)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    tasks = _tasks(exp)
    done = map_tasks(_one, [(exp, *t) for t in tasks], jobs, on_done)
    study = exp.config.study
    grouped: dict = {}
    for (v, s, _), errors in zip(tasks, done, strict=True):
        for (name, zone, comp, part), (mse, ref) in errors.items():
            grouped.setdefault((v, s, zone, comp, part), {}).setdefault(name, []).append(
                (mse, ref))
    rows, cells = [], []
    complex_mse: dict = {}      # claims: one cell per zone and component (dipole_field._rows)
    for (v, s, zone, comp, part), by_name in grouped.items():
        one = exp.plan.experiments[v]
        value = study.values[v]
        scenario = exp.config.scenarios[s].name
        for name, pairs in by_name.items():
            values = np.sqrt([p[0] for p in pairs])
            ref = float(np.mean([p[1] for p in pairs]))
            broke = ~(values <= field.DIVERGED_RATIO * np.sqrt(ref))
            mean, se = (metrics.mean_and_se(values) if len(values) > 1
                        else (float(values[0]), float("nan")))
            if broke.any():
                mean, se = float("inf"), float("nan")
            if part in ("real", "imag"):
                complex_mse.setdefault((v, s, zone, comp), {}).setdefault(name, []).append(
                    ([p[0] for p in pairs], ref))
            rows.append({"study": study.setting, "value": value, "scenario": scenario,
                         "zone": zone, "beta_r": one.plan.beta_r[zone], "estimator": name,
                         "field_component": comp, "part": part, "rmse": mean, "rmse_se": se,
                         "runs": len(values), "field_rms": np.sqrt(ref),
                         "relative": mean / np.sqrt(ref),
                         "sensors": int(one.plan.count),
                         "members": int(one.config.filter.members)})
    for (v, s, zone, comp), losses in field.phasor_losses(complex_mse).items():
        cells.append((claims.cell(study=study.setting, value=f"{study.values[v]:g}",
                                  scenario=exp.config.scenarios[s].name, zone=zone,
                                  field_component=comp), losses))
    df = pd.DataFrame(rows)[TABLES["rmse"].columns]
    table = claims.table(cells, CLAIMS, "RMSE")
    figure = plots.field_study(df, IN_WORDS[study.setting], (field.KF, field.FIT, field.PLAIN,
                                                      field.SOURCE_ONLY))
    return Result(tables={"rmse": df, "claims": table}, figures={"study": figure})


def printout(result: Result) -> str:
    df = result.tables["rmse"]
    view = df[(df["part"] == "real") & df["estimator"].isin(
        [field.KF, field.FIT, field.PLAIN])].pivot_table(
        index=["scenario", "zone", "field_component", "estimator"], columns="value",
        values="relative", sort=False)
    return "relative RMSE (RMSE / field RMS), real part\n" + view.to_string(
        float_format=lambda v: f"{v:.3g}")
