"""Perturbation analysis and distortion of the Chapter 2 circuits (Tables 2.1-2.4).

For each configured row (one per thesis row, in thesis order) the circuit is built with the
row's parameters, driven with the row's amplitude ``A`` and, for a check of the expansion,
with ``A/2``; :func:`estim.numerics.expansion.respond` gives the zeroth-order output ``y0``, the
first-order output ``y1`` and the full nonlinear output over one period of the periodic
steady state (a sine sampled at ``samples_per_period`` points and fed as each model's
``source_to_input`` maps it: a staircase for the amplifiers, piecewise linear for the MOSFET,
docs/deviations.md D29) or over the row's window after a step. The row of ``distortion.csv``:

``percent_distortion``  eq 2.43 as an RMS ratio, ``100 rms(y1) / rms(y0 + y1)``
``thd_percent``         total harmonic distortion of the full output (harmonics 2-10)
``gain_db``             fundamental of the full output over the source amplitude
``err_linear_rms``      ``rms(y_full - y0)``: the error of keeping the linear term only
``err_first_order_rms`` ``rms(y_full - y0 - y1)``: the error left after the first order
``order_linear``, ``order_first_order``  ``log2`` of each error's ratio between ``A`` and
                        ``A/2``: about 2 and 3 when the expansion works as it should
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from estim import reference
from estim.config import registry
from estim.config.builders import build_model, check_input_vector, operating_point
from estim.config.experiment import Experiment
from estim.config.settings import (
    MAX_VOLTS,
    REQUIRED,
    Settings,
    block,
    blocks,
    file_name,
    integer,
    list_of,
    mapping,
    number,
    setting,
    settings_class,
    text,
)
from estim.errors import ConfigError, SimulationError
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.experiments.shared.blocks import VOLTS, simulation
from estim.experiments.shared.blocks import Model as ModelBlock
from estim.numerics import metrics, signals
from estim.numerics.expansion import Response, check_expansion, expand, respond
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")


@settings_class
class Excitation(Settings):
    """How every row drives the circuit: a sine or a step on top of a DC bias."""

    waveform: str = setting(REQUIRED, text({"sine", "step"}), doc="sine or step")
    bias_v: list = setting(REQUIRED, list_of(VOLTS), unit="V", doc="DC level of each input")
    mix: list = setting(REQUIRED, list_of(number(minimum=-1e3, maximum=1e3)),
                        doc="the excitation's weight in each input")
    samples_per_period: int = setting(200, integer(8, 10_000),
                                      doc="samples per period of a sine (D29)")
    samples: int = setting(2000, integer(8, 1_000_000), doc="samples of a step's window")


@settings_class
class Row(Settings):
    """One thesis row: amplitude, frequency or window, and its parameters."""

    s_no: int = setting(REQUIRED, integer(1, 10_000), doc="the thesis' row number")
    amplitude_v: float = setting(REQUIRED, number(minimum=1e-9, maximum=MAX_VOLTS), unit="V",
                                 doc="peak amplitude of the sine, or the step's height")
    frequency_hz: float | None = setting(None, number(minimum=1e-3, maximum=1e9), unit="Hz",
                                         doc="the sine's frequency (waveform sine)")
    duration_s: float | None = setting(None, number(minimum=1e-9, maximum=1e3), unit="s",
                                       doc="the window after a step (waveform step)")
    params: dict = setting({}, mapping, doc="the row's model parameters")


@settings_class
class Tables(Settings):
    """The thesis table the rows join."""

    distortion: str = setting(REQUIRED, text(), doc="2.1, 2.2, 2.3 or 2.4, or ours (a "
                              "circuit the thesis did not have)")


@settings_class
class Figures(Settings):
    """The figure of one row."""

    row: int | None = setting(None, integer(1, 10_000), doc="its s_no; none: the first row")
    name: str = setting("perturbation", file_name, doc="the figure's file name")


@settings_class
class Config(Settings):
    """A Chapter 2 experiment: perturbation analysis and distortion, row by row."""

    model: Any = block(ModelBlock, required=True, doc="the circuit")
    excitation: Excitation = block(Excitation, required=True, doc="how the rows drive it")
    rows: tuple = blocks(Row, max_length=100, doc="the thesis' rows, in order")
    simulation: Any = block(simulation(rtol=1e-8, atol=1e-10), doc="the solver")
    tables: Tables = block(Tables, required=True, doc="the thesis table joined")
    figures: Figures = block(Figures, doc="the figure")


SCHEMA: dict = Config.schema()

_KEYS = ("table_id", "s_no", "amplitude_v", "frequency_hz", "row_params")
_VALUES = ("percent_distortion", "thd_percent", "gain_db", "output_rms", "err_linear_rms",
           "err_first_order_rms", "order_linear", "order_first_order", "shooting_iterations")
_JOIN = (("s_no", ("s_no", "row_order")),)

TABLES = {
    "distortion": TableSpec("distortion.csv", _KEYS, _VALUES,
                            reference=("percent_distortion",), join=_JOIN,
                            title="percent distortion (eq 2.43), THD, gain, expansion errors",
                            reference_ids=("2.1", "2.2", "2.3", "2.4")),
    "gain": TableSpec("distortion.csv", _KEYS, ("gain_db",), reference=("gain_db",),
                      join=_JOIN, title="gain of the full circuit",
                      reference_ids=("2.1", "2.2", "2.3", "2.4")),
    "claims": claims.TABLE,
}
FIRST, LINEAR = "x0 + x1", "x0"
CLAIMS = ((FIRST, LINEAR),)
"""Chapter 2's premise: the first-order expansion is closer to the full nonlinear circuit
than the linear response alone (the RMS output error of each against the full circuit over
the analysis window). Deterministic: judged exactly."""
QUOTES = (
    Quote("percent distortion (eq 2.43, RMS ratio)", "distortion", "percent_distortion"),
    Quote("THD of the full output (%)", "distortion", "thd_percent"),
    Quote("gain (dB)", "distortion", "gain_db"),
    Quote("error order of x0 (A against A/2)", "distortion", "order_linear"),
    Quote("error order of x0 + x1", "distortion", "order_first_order"),
)


@dataclass(frozen=True)
class Plan:
    """The circuit of every row (by ``s_no``), built once."""

    models: dict


def prepare(config: Config, source: str) -> Plan:
    """Cross-checks beyond the schema; the model of every row, built once (by ``s_no``)."""
    if config.simulation.solver == "ngspice":
        raise ConfigError(source, "simulation.solver", "ngspice is the actual circuit of an "
                          "estimation config only; here: batched_radau or scipy")
    model_cls = registry.MODELS[config.model.name]
    variant = config.model.variant
    build_model(model_cls, variant, config.model.params, source, "model.params")
    exc = config.excitation
    for key in ("bias_v", "mix"):
        check_input_vector(getattr(exc, key), model_cls, source, f"excitation.{key}")
    if not any(exc.mix):
        raise ConfigError(source, "excitation.mix", "expected at least one non-zero entry")
    needed, unused = ("frequency_hz", "duration_s") if exc.waveform == "sine" else (
        "duration_s", "frequency_hz")
    models = {}
    for i, row in enumerate(config.rows):
        path = f"rows[{i}]"
        if getattr(row, needed) is None:
            raise ConfigError(source, f"{path}.{needed}",
                              f"missing required key (excitation.waveform is {exc.waveform})")
        if getattr(row, unused) is not None:
            raise ConfigError(source, f"{path}.{unused}",
                              f"not used with excitation.waveform {exc.waveform}; remove it")
        if row.s_no in models:
            raise ConfigError(source, f"{path}.s_no", f"duplicate row number {row.s_no}")
        models[row.s_no] = build_model(model_cls, variant,
                                          {**config.model.params, **row.params},
                                          source, f"{path}.params")
        _check_expansion(models[row.s_no], exc.bias_v, source,
                         f"{path}.params" if row.params else "model.params")
    row = config.figures.row
    if row is not None and row not in models:
        raise ConfigError(source, "figures.row",
                          f"expected the s_no of a row ({sorted(models)}), got {row}")
    return Plan(models)


def _check_expansion(model, bias: list, source: str, path: str) -> None:
    """The row's circuit has a DC operating point, a finite linear + quadratic part there,
    and is stable about it (else a perturbation series about the point diverges): checked
    before any work, as a config error at ``path``."""
    x_op = operating_point(model, bias, source, path)
    held = np.broadcast_to(np.asarray(bias, float), (1, 2, model.n_inputs))
    u_op = model.source_to_input(held, 1.0)[0, 0]
    with np.errstate(all="ignore"):
        e = expand(model, x_op, u_op)
    try:
        check_expansion(e, model.name)
    except SimulationError as exc:
        raise ConfigError(source, path, str(exc)) from None


def tiny(config: Config) -> dict:
    """Seconds of work: the first row only, at 32 samples a period (or 64 after a step)."""
    return {"rows": [config.rows[0].to_spec()], "excitation.samples_per_period": 32,
            "excitation.samples": 64, "figures": {"name": config.figures.name}}


def work_size(config: Config) -> int:
    """State-samples of the three responses at two amplitudes, every row (shooting repeats
    a period a few times: counted as four)."""
    n = len(registry.MODELS[config.model.name].state_names)
    exc = config.excitation
    steps = exc.samples_per_period * 4 if exc.waveform == "sine" else exc.samples
    return int(len(config.rows) * 2 * 3 * n * steps)


def work_units(exp: Experiment) -> int:
    return len(exp.config.rows) + 1


def source(exp: Experiment, row: Row, amplitudes: np.ndarray) -> tuple[np.ndarray, float]:
    """Sampled sources ``(len(amplitudes), steps + 1, p)`` of one row, and the sample time."""
    exc = exp.config.excitation
    bias, mix = np.asarray(exc.bias_v, float), np.asarray(exc.mix, float)
    if exc.waveform == "sine":
        steps = exc.samples_per_period
        dt = 1.0 / (row.frequency_hz * steps)
        shape = signals.sine(1.0, row.frequency_hz, np.arange(steps + 1) * dt)[:, 0]
    else:
        steps = exc.samples
        dt = row.duration_s / steps
        shape = np.ones(steps + 1)
        shape[0] = 0.0
    wave = amplitudes[:, None, None] * shape[None, :, None] * mix
    return bias + wave, dt


def respond_row(exp: Experiment, row: Row) -> tuple[Response, np.ndarray]:
    """Responses at the row's amplitude and at half of it."""
    amplitudes = np.array([row.amplitude_v, row.amplitude_v / 2])
    src, dt = source(exp, row, amplitudes)
    sim = exp.config.simulation
    response = respond(exp.plan.models[row.s_no], src,
                       np.asarray(exp.config.excitation.bias_v), dt,
                       periodic=exp.config.excitation.waveform == "sine",
                       solver=sim.solver, rtol=sim.rtol, atol=sim.atol)
    return response, amplitudes


def row_params(row: Row) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in row.params.items())


def summarize(exp: Experiment, row: Row, r: Response, amplitudes: np.ndarray) -> dict:
    """The ``distortion.csv`` row of the responses ``r`` at ``amplitudes`` (A, A/2)."""
    periodic = exp.config.excitation.waveform == "sine"
    # one period of samples t_0..t_{N-1} (t_N repeats t_0); the whole window after a step
    window = slice(0, -1) if periodic else slice(1, None)
    y0, y1, y = r.y0[:, window], r.y1[:, window], r.y_full[:, window]
    err_lin = metrics.rms(y - y0)
    err_first = metrics.rms(y - y0 - y1)
    nan = float("nan")
    return {
        "s_no": row.s_no, "amplitude_v": row.amplitude_v,
        "frequency_hz": row.frequency_hz if periodic else nan,
        "row_params": row_params(row),
        "percent_distortion": float(metrics.percent_distortion(y0[0], y1[0])),
        "thd_percent": float(metrics.thd_percent(y[0])) if periodic else nan,
        "gain_db": float(metrics.gain_db(y[0], amplitudes[0])) if periodic else nan,
        "output_rms": float(metrics.rms(y[0])),
        "err_linear_rms": float(err_lin[0]), "err_first_order_rms": float(err_first[0]),
        "order_linear": float(np.log2(err_lin[0] / err_lin[1])),
        "order_first_order": float(np.log2(err_first[0] / err_first[1])),
        "shooting_iterations": r.shooting_iterations,
    }


def _evaluate(args: tuple[Experiment, dict]) -> tuple[dict, Response]:
    exp, row = args
    r, amplitudes = respond_row(exp, row)
    return summarize(exp, row, r, amplitudes), r


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    """``distortion.csv`` (rows in thesis order whatever the number of jobs) and the figure
    of one row (deterministic: no seed)."""
    results = map_tasks(_evaluate, [(exp, row) for row in exp.config.rows], jobs, on_done)
    df = pd.DataFrame([summary_row for summary_row, _ in results])
    table_id = exp.config.tables.distortion
    df.insert(0, "table_id", "" if table_id == reference.OWN_TABLE else table_id)
    cells = [(claims.cell(s_no=int(row["s_no"]), amplitude_v=row["amplitude_v"],
                          frequency_hz=row["frequency_hz"], params=row["row_params"] or None),
              {FIRST: claims.Losses([row["err_first_order_rms"]]),
               LINEAR: claims.Losses([row["err_linear_rms"]])}) for _, row in df.iterrows()]
    out = Result(tables={"distortion": df[TABLES["distortion"].columns].reset_index(drop=True),
                         "claims": claims.table(cells, CLAIMS, "RMS error against the full "
                                                "circuit", exact=True)})
    data = figure_data(exp, {s["s_no"]: r for s, r in results})
    row = data["row"]
    what = f"amplitude {row.amplitude_v:g} V"
    if row.frequency_hz is not None:
        what += f", {row.frequency_hz:g} Hz"
    if row.params:
        what += "\n" + ", ".join(plots.with_unit(k, v) for k, v in row.params.items())
    out.figures[exp.config.figures.name] = plots.perturbation(
        data, f"{exp.title}; {what}")
    if on_done:
        on_done()
    return out


def printout(result: Result) -> str:
    """The distortion table's main columns."""
    columns = ["s_no", "amplitude_v", "frequency_hz", "percent_distortion", "thd_percent",
               "gain_db", "err_linear_rms", "err_first_order_rms"]
    return result.tables["distortion"][columns].to_string(
        index=False, float_format=lambda v: f"{v:.4g}", na_rep="--")


def figure_data(exp: Experiment, responses: dict[int, Response]) -> dict:
    """Traces of the figure row (``figures.row``, default the first) from the rows'
    ``responses`` by ``s_no``: two periods of the steady state for a sine, the whole window
    after a step."""
    wanted = exp.config.figures.row
    row = next((r for r in exp.config.rows if r.s_no == wanted), exp.config.rows[0])
    r = responses[row.s_no]
    src, _ = source(exp, row, np.array([row.amplitude_v]))
    mix = np.asarray(exp.config.excitation.mix, float)
    drive = (src[0] - np.asarray(exp.config.excitation.bias_v, float)) @ mix / (mix @ mix)
    traces = {"t": r.t, "input": drive, "y0": r.y0[0], "y1": r.y1[0], "y_full": r.y_full[0]}
    if exp.config.excitation.waveform == "sine":
        period = r.t[-1]
        traces = {k: np.concatenate([v[:-1], v]) for k, v in traces.items() if k != "t"} | {
            "t": np.concatenate([r.t[:-1], r.t + period])}
    traces["row"] = row
    return traces
