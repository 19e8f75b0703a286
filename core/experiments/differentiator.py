"""Maximally linear FIR differentiators against minimax relative-error designs (the paper
in ``shared/seeds/002_a5009dd315ab9542.txt``: Table II and Fig 3).

For every cell of Table II (band ``[omega_p pi, pi]`` x relative-error bound): the order
``N2`` of the maximally linear design that meets it (:mod:`estim.numerics.fir_differentiators`,
exact rational coefficients) and the number of taps ``N1`` of the full-band minimax
relative-error design (``scipy.signal.remez``) that meets it, searched up to ``max_taps``;
with the relative error each achieves. The paper's N1 designs cover the whole band
``[0, pi]`` (its remark 1), as ours do here: that is the paper's comparison. Beside it,
``n_band_minimax``: the minimax design of the proposed mixed structure over ``[omega_p pi,
pi]`` only (linear programming, :func:`estim.numerics.fir_differentiators.minimax_band`), which the
paper does not compare with (docs/deviations.md D63).

Fig 3: RE in dB against ``w / pi`` for ``n = 1, 2, 3, 5, 7, 10`` (RE -> -inf at pi: the
axis is clipped).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estim.config.experiment import Experiment
from estim.config.settings import (
    Settings,
    block,
    file_name,
    integer,
    list_of,
    number,
    setting,
    settings_class,
    text,
)
from estim.experiments.base import Quote, Result
from estim.experiments.shared import claims, plots
from estim.numerics import fir_differentiators as fd
from estim.reference.tablespec import TableSpec
from estim.util import lazy

pd = lazy.load("pandas")


@settings_class
class Tables(Settings):
    """The paper's table joined."""

    orders: str = setting("fir_II", text(), doc="the paper's Table II")


@settings_class
class Figures(Settings):
    """Fig 3: relative error against frequency."""

    orders_n: list = setting([1, 2, 3, 5, 7, 10], list_of(integer(1, 60), max_length=12),
                             doc="the orders drawn")
    name: str = setting("fig_3", file_name, doc="the figure's file name")


@settings_class
class Config(Settings):
    """Maximally linear FIR differentiators against minimax designs (Table II, Fig 3)."""

    bands: list = setting([0.95, 0.90, 0.80, 0.70, 0.60, 0.50],
                          list_of(number(minimum=0.01, maximum=0.999), max_length=50),
                          doc="omega_p: the band [omega_p pi, pi]")
    thresholds_db: list = setting([-40.0, -60.0, -80.0, -100.0],
                                  list_of(number(minimum=-300.0, maximum=-1.0), max_length=20),
                                  unit="dB", doc="the relative-error bounds")
    max_n: int = setting(40, integer(1, 60), doc="largest maximally linear order searched")
    max_taps: int = setting(128, integer(4, 1024), doc="largest minimax length searched")
    tables: Tables = block(Tables, doc="the table joined")
    figures: Figures = block(Figures, doc="Fig 3")


SCHEMA: dict = Config.schema()

TABLES = {
    "orders": TableSpec("orders.csv", ("table_id", "omega_p", "threshold_db"),
                        ("n1", "n1_re_db", "n2", "n2_re_db", "n_band_minimax",
                         "n_band_minimax_re_db"),
                        reference=("n1", "n2"),
                        join=(("omega_p", ("omega_p",)), ("threshold_db", ("threshold_db",))),
                        title="orders meeting each relative-error bound (Table II)",
                        reference_ids=("fir_II",)),
    "claims": claims.TABLE,
}
ML, FULL, BAND = "maximally linear (N2)", "full-band minimax (N1)", "band minimax"
CLAIMS = ((ML, FULL), (ML, BAND))
"""The paper's claim (the maximally linear design meets each bound with a lower order than
the full-band minimax design needs taps), and the same against a minimax design of the
mixed structure over the band only (D63). Deterministic: judged exactly; a design that
meets no bound within the search is an infinite loss."""
QUOTES = (
    Quote("N2, maximally linear order", "orders", "n2"),
    Quote("N1, full-band minimax taps (inf: none up to max_taps)", "orders", "n1"),
    Quote("band minimax order", "orders", "n_band_minimax"),
)


@dataclass(frozen=True)
class Plan:
    """The typed config: this analysis builds nothing else before its work units."""

    config: Config


def prepare(config: Config, source: str) -> Plan:
    return Plan(config)


def work_units(exp: Experiment) -> int:
    return 1


def work_size(config: Config) -> int:
    return len(config.bands) * len(config.thresholds_db) * (config.max_n + config.max_taps)


def tiny(config: Config) -> dict:
    """Seconds of work: one band, one threshold."""
    return {"bands": config.bands[:1], "thresholds_db": config.thresholds_db[:1]}


def _re_minimax(taps: int, omega_p: float) -> float:
    w = fd.band(omega_p, 4_000)
    return fd.relative_error_db(fd.minimax_response(fd.minimax_full_band(taps), w), w)


def _re_maximally_linear(order: int, omega_p: float) -> float:
    w = fd.band(omega_p)
    return fd.relative_error_db(fd.response(order // 2, w), w)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    config = exp.config
    rows = []
    for omega_p in config.bands:
        for threshold in config.thresholds_db:
            n2 = fd.order_maximally_linear(omega_p, threshold, config.max_n)
            n1 = fd.order_minimax(omega_p, threshold, config.max_taps)
            n3 = fd.order_minimax_band(omega_p, threshold)
            rows.append({"table_id": config.tables.orders, "omega_p": omega_p,
                         "threshold_db": threshold,
                         "n1": float(n1) if n1 else float("inf"),
                         "n1_re_db": _re_minimax(n1 or config.max_taps, omega_p),
                         "n2": float(n2) if n2 else float("inf"),
                         "n2_re_db": _re_maximally_linear(n2, omega_p) if n2 else float("nan"),
                         "n_band_minimax": float(n3) if n3 else float("inf"),
                         "n_band_minimax_re_db": (fd.minimax_band(n3 // 2, omega_p)[1] if n3
                                                  else float("nan"))})
    w = np.linspace(0.005, 1.0, 2000, endpoint=False) * np.pi
    curves = {n: 20 * np.log10(np.abs(fd.response(n, w) - w) / w) for n in
              config.figures.orders_n}
    figure = plots.relative_error_curves(w / np.pi, curves)
    if on_done:
        on_done()
    cells = [(claims.cell(omega_p=row["omega_p"], threshold_db=row["threshold_db"]),
              {ML: claims.Losses([row["n2"]]), FULL: claims.Losses([row["n1"]]),
               BAND: claims.Losses([row["n_band_minimax"]])}) for row in rows]
    return Result(tables={"orders": pd.DataFrame(rows)[TABLES["orders"].columns],
                          "claims": claims.table(cells, CLAIMS, "order", exact=True)},
                  figures={config.figures.name: figure})


def printout(result: Result) -> str:
    df = result.tables["orders"]
    view = df.pivot_table(index="omega_p", columns="threshold_db", values=["n1", "n2"],
                          sort=False)
    return view.to_string(float_format=lambda v: f"{v:g}")
