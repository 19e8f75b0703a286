"""The filters on measured data: a CSV of a circuit's measured output (and of its input
source), no actual circuit (docs/your-data.md).

There is no truth here, so no RMSE: each filter is judged by its **one-step prediction
error**, the innovation ``z_k - h(x_{k|k-1})`` (eq 3.84), which is the measurement's error
plus the prediction's. Beside the filters, ``last measurement`` predicts each sample by the
one before it (innovation ``z_k - z_{k-1}``): a filter that does not beat it has learnt
nothing from the model. ``innovation.csv`` gives per estimator the innovation's mean (with
its standard error), its RMS, the time-averaged NIS with the fraction of steps inside its
chi-square band and the Ljung-Box whiteness of the innovations (a consistent filter's are
white, with NIS about ``m``); ``estimates.csv`` every state's estimate and standard
deviation and the output's, at every sample; ``claims.csv`` the prediction MSE compared,
paired over ``blocks`` consecutive blocks of the record (batch means). The filters start at
the model's DC point with the source at its first sample.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estim.config import registry
from estim.config.builders import build_estimator, build_model, check_input_vector, operating_point
from estim.config.experiment import Experiment
from estim.config.settings import (
    REQUIRED,
    Settings,
    block,
    blocks,
    file_name,
    integer,
    setting,
    settings_class,
    text,
)
from estim.errors import ConfigError
from estim.estimators.base import takes_generator
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, health, pipeline, plots, records
from estim.experiments.shared.blocks import Claim, EstimatorEntry, Health, Model, SourceLevels
from estim.reference.tablespec import TableSpec
from estim.util import lazy

pd = lazy.load("pandas")

PERSISTENCE = "last measurement"
"""The baseline row: each sample predicted by the one before it."""


@settings_class
class Data(SourceLevels):
    """The measurements: a CSV file with a header line, evenly sampled; the source is
    ``bias_v + input * mix`` (the input column, else 0)."""

    file: str = setting(REQUIRED, text(max_length=1000),
                        doc="the CSV, relative to the config's folder (or a folder above it)")
    time: str = setting("t_s", text(max_length=100), unit="s",
                        doc="the column of sample times (evenly spaced)")
    output: str = setting("z", text(max_length=100), doc="the column of the measured output")
    input: str | None = setting(None, text(max_length=100),
                                doc="the column of the input source; none: the source is "
                                    "held at bias_v")


@settings_class
class Config(Settings):
    """Filters on measured data: innovations, NIS and estimates, no truth."""

    model: Model = block(Model, required=True, doc="the circuit's model")
    data: Data = block(Data, required=True, doc="the measurements")
    estimators: tuple = blocks(EstimatorEntry, max_length=20, doc="the estimators compared")
    health: Health = block(Health, doc="how filter health is judged")
    claims: tuple = blocks(Claim, default=(), nonempty=False, max_length=20,
                           doc="claims on the prediction MSE (each filter is also judged "
                               "against the last measurement)")
    blocks: int = setting(20, integer(6, 100_000),
                          doc="consecutive blocks of the record whose prediction MSEs the "
                              "claims pair")
    seed: int = setting(0, integer(0, 2**63 - 1),
                        doc="root of the generator an ensemble or particle filter draws from")
    figure: str = setting("estimates", file_name, doc="the figure's file name")


SCHEMA: dict = Config.schema()

_VALUES = ("samples", "broken_at_s", "innovation_mean", "innovation_mean_se",
           "innovation_rms", "nis_mean", "nis_in_band", "whiteness_p", "white")
TABLES = {
    "innovation": TableSpec("innovation.csv", ("estimator",), _VALUES,
                            title="one-step prediction errors, NIS and whiteness (no truth)"),
    "estimates": TableSpec("estimates.csv", ("t_s", "estimator", "quantity"), ("value", "sd"),
                           title="every state's and the output's estimate at every sample"),
    "claims": claims.TABLE,
}
QUOTES = (
    Quote("innovation RMS (one-step prediction error)", "innovation", "innovation_rms",
          by="estimator"),
    Quote("time-averaged NIS", "innovation", "nis_mean", by="estimator",
          where="nis_mean == nis_mean"),
)


@dataclass(frozen=True)
class Plan:
    """The model, the estimators and the record, read once."""

    model: object
    filters: tuple
    x0: np.ndarray
    t: np.ndarray
    z: np.ndarray
    source: np.ndarray


def read_columns(name: str, source: str, wanted: dict[str, str]) -> dict[str, np.ndarray]:
    """The columns ``wanted`` (key path -> column name) of the CSV ``name``
    (:func:`estim.experiments.shared.records.read_rows`) as numbers; one ``ConfigError`` at
    the first problem."""
    path, header, body = records.read_rows(name, source, "data.file")
    out = {}
    for key, column in wanted.items():
        if column not in header:
            raise ConfigError(source, key, f"no column {column!r} in {path} (it has "
                              f"{', '.join(header) or 'no header'})")
        j = header.index(column)
        try:
            out[key] = np.array([float(row[j]) for row in body])
        except (ValueError, IndexError):
            bad = next(i for i, row in enumerate(body, 2)
                       if len(row) <= j or not _number(row[j]))
            raise ConfigError(source, key, f"{path} line {bad}: column {column!r} is not a "
                              "number") from None
        if not np.all(np.isfinite(out[key])):
            raise ConfigError(source, key, f"{path}: column {column!r} holds a value that is "
                              "not finite")
    return out


def _number(text_: str) -> bool:
    try:
        float(text_)
    except ValueError:
        return False
    return True


def prepare(config: Config, source: str) -> Plan:
    """The record read and checked (evenly sampled, long enough for the blocks), the model
    and the estimators built, the DC point at the first input sample."""
    data = config.data
    model_cls = registry.MODELS[config.model.name]
    for key in ("bias_v", "mix"):
        check_input_vector(getattr(data, key), model_cls, source, f"data.{key}")
    wanted = {"data.time": data.time, "data.output": data.output}
    if data.input is not None:
        wanted["data.input"] = data.input
    columns = read_columns(data.file, source, wanted)
    t = columns["data.time"]
    if len(t) < 2 * config.blocks + 1:
        raise ConfigError(source, "data.file", f"{len(t)} samples: at least {2 * config.blocks + 1}"
                          f" needed for blocks: {config.blocks}")
    steps = np.diff(t)
    dt = float(steps[0])
    uneven = np.flatnonzero(np.abs(steps - dt) > 1e-6 * abs(dt))
    if not dt > 0 or uneven.size:
        row = int(uneven[0]) + 3 if uneven.size else 3
        raise ConfigError(source, "data.time", f"{data.file} line {row}: the times must "
                          "increase evenly (one sample time)")
    bias, mix = np.asarray(data.bias_v, float), np.asarray(data.mix, float)
    level = columns.get("data.input", np.zeros_like(t))
    record = bias + level[:, None] * mix
    model = build_model(model_cls, config.model.variant, config.model.params, source,
                        "model.params")
    if model.n_outputs != 1:
        raise ConfigError(source, "model", f"model {model.name} has {model.n_outputs} outputs; "
                          "the data give one (data.output)")
    x0 = operating_point(model, record[0], source, "model.params")
    filters, labels = [], []
    for i, est in enumerate(config.estimators):
        path = f"estimators[{i}]"
        if est.label in labels or est.label == PERSISTENCE:
            raise ConfigError(source, f"{path}.label", f"{est.label!r} is taken; choose another")
        labels.append(est.label)
        own = build_model(model_cls, config.model.variant,
                          {**config.model.params, **est.model_params}, source,
                          f"{path}.model_params")
        estimator = build_estimator(registry.ESTIMATORS[est.type], est.settings, own, source,
                                    f"{path}.settings")
        est.settings.clear()
        est.settings.update(estimator.to_spec())
        filters.append((est.label, estimator, own))
    pipeline.check_claims(config.claims, labels, source)
    return Plan(model=model, filters=tuple(filters), x0=x0, t=t,
                z=columns["data.output"], source=record)


def work_units(exp: Experiment) -> int:
    return 1


def work_size(config: Config) -> int:
    """A nominal size: the record is read by :func:`prepare`, after the work bound is
    checked, so ``--max-work`` does not bound a measured run (its cost is one pass of each
    filter over the record)."""
    return 1000 * max(1, len(config.estimators))


def tiny(config: Config) -> dict:
    """The record is the work: a quick run is the whole run."""
    return {}


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    """Every estimator over the record, then the tables and the figure."""
    plan, config = exp.plan, exp.config
    dt = float(plan.t[1] - plan.t[0])
    z = plan.z[None, 1:, None]
    times = plan.t[1:]
    rows, estimates, errors = [], [], {PERSISTENCE: np.diff(plan.z)[None, :, None]}
    rows.append(_row(PERSISTENCE, errors[PERSISTENCE], None, times, config.health))
    for i, (label, est, model) in enumerate(plan.filters):
        extra = ({"rng": np.random.default_rng(np.random.SeedSequence(config.seed,
                                                                     spawn_key=(i,)))}
                 if takes_generator(est) else {})
        u = model.source_to_input(plan.source[None], dt)
        out = est.run(model, z, u, dt, x0=plan.x0, **extra)
        errors[label] = out.innovation
        rows.append(_row(label, out.innovation, out.S, times, config.health))
        estimates += _estimates(label, model, out, times)
    cells = [(claims.cell(record=Path(config.data.file).name),
              {label: claims.Losses(_block_mse(e, config.blocks)) for label, e in errors.items()})]
    pairs = [(c.better, c.worse) for c in config.claims]
    pairs += [(label, PERSISTENCE) for label, _, _ in plan.filters
              if (label, PERSISTENCE) not in pairs]
    table = claims.table(cells, pairs, "prediction MSE")
    if on_done:
        on_done()
    return Result(tables={"innovation": pd.DataFrame(rows, columns=TABLES["innovation"].columns),
                          "estimates": pd.DataFrame(estimates,
                                                    columns=TABLES["estimates"].columns),
                          "claims": table},
                  figures={config.figure: _figure(exp, errors)})


def _row(label: str, innovation: np.ndarray, S: np.ndarray | None, times: np.ndarray,
         judged) -> dict:
    """One row of ``innovation.csv``."""
    e = innovation[0, :, 0]
    finite = np.isfinite(e)
    broken = not finite.all()
    kept = e[finite]
    nis_mean = in_band = float("nan")
    if S is not None and kept.size:
        values = health.nis(innovation[:, finite], S[:, finite])
        nis_mean, in_band = health.averaged_in_band(values, 1, judged.band)
    lag = health.effective_lag(kept.size, judged.whiteness_lag)
    p = float(health.ljung_box(kept[None], lag)[0]) if kept.size > 4 else float("nan")
    return {"estimator": label, "samples": int(kept.size),
            "broken_at_s": float(times[np.argmin(finite)]) if broken else float("nan"),
            "innovation_mean": float(np.mean(kept)) if kept.size else float("nan"),
            "innovation_mean_se": (float(np.std(kept, ddof=1) / np.sqrt(kept.size))
                                   if kept.size > 1 else float("nan")),
            "innovation_rms": float(np.sqrt(np.mean(kept ** 2))) if kept.size else float("nan"),
            "nis_mean": nis_mean, "nis_in_band": in_band, "whiteness_p": p,
            "white": bool(p > judged.whiteness_level) if np.isfinite(p) else False}


def _block_mse(innovation: np.ndarray, count: int) -> np.ndarray:
    """The mean squared innovation of each of ``count`` consecutive blocks (a block with a
    broken step: ``inf``)."""
    e = innovation[0, :, 0]
    return np.array([float(np.mean(part ** 2)) if np.all(np.isfinite(part)) else np.inf
                     for part in np.array_split(e, count)])


def _estimates(label: str, model, out, times: np.ndarray) -> list[dict]:
    """The long rows of ``estimates.csv`` for one estimator: every state and the output."""
    rows = []
    names = list(model.state_names)
    x_hat = out.x_hat[0] if out.x_hat is not None else None
    sd = np.sqrt(np.abs(out.P_diag[0])) if out.P is not None else None
    for k, t in enumerate(times):
        if x_hat is not None:
            for j, name in enumerate(names):
                rows.append({"t_s": float(t), "estimator": label, "quantity": name,
                             "value": float(x_hat[k, j]),
                             "sd": float(sd[k, j]) if sd is not None else float("nan")})
        rows.append({"t_s": float(t), "estimator": label, "quantity": "output",
                     "value": float(out.y_hat[0, k, 0]), "sd": float("nan")})
    return rows


def _figure(exp: Experiment, errors: dict):
    """The measured output and every filter's prediction of it (measurement minus
    innovation), over the record."""
    plan = exp.plan
    predicted = {label: plan.z[1:] - e[0, :, 0] for label, e in errors.items()
                 if label != PERSISTENCE}
    return plots.predictions(plan.t, plan.z, predicted,
                             f"{exp.title}: one-step predictions" if exp.title
                             else "one-step predictions")


def printout(result: Result) -> str:
    """The innovation table, and why there is no RMSE."""
    df = result.tables["innovation"]
    shown = df[["estimator", "innovation_rms", "innovation_mean", "nis_mean", "whiteness_p"]]
    return "\n".join([shown.to_string(index=False, float_format=lambda v: f"{v:.4g}"),
                      "no actual signal: RMSE needs the truth; the innovation (one-step "
                      "prediction error) is each filter's error against the data"])
