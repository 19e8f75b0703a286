"""A filter on the field itself: the dipole's potentials on a 3-D grid (thesis eqs 5.1-5.32
and the Remark, eqs 5.48-5.49) with sparse noisy measurements of E and H (eq 5.32), Tables
5.1-5.12 in the thesis' layout for this experiment.

Per scenario (the source the filter is told) and noise row:

* truth: the analytic field of the dipole (``estim.fields.dipole``) with the true current
  ``I0 = 1``; the thesis' "noise at the driving source" (2.5e-4, 5e-4 of the current) is
  three orders below the grid's own error and does not enter it (docs/deviations.md);
* sensors: a random ``fraction`` of the grid points between the ``sensors.r`` radii,
  drawn anew for each Monte Carlo run (one layout for all runs when ``sensors.seed`` is
  given, :func:`~estim.experiments.dipole_field.filtering.layout`), measure all six
  components of E and H every step, with white noise ``measurement_sigma``;
* ``plain simulation``: the leapfrog/Mur simulation (``estim.fields.fdtd``) driven by the
  nominal source, no data: the open loop, and with the true source the grid's floor;
* ``KF`` (the ensemble filter, ETKF of ``estim.fields.etkf``): ``members`` simulations whose
  complex source amplitude is part of the state (drawn around the nominal one, spread
  ``amplitude_spread``), spun up for ``spinup_periods``, then analysed at every step; the
  observation error variance is ``measurement_sigma^2 + model_error^2`` (the grid's own
  error in the measured fields, declared);
* ``RLS``: the thesis-style baseline: the project's RLS fits a sinusoid of the known
  frequency to each sensor's time series, and each field point takes its nearest sensor;
* ``measurement``: each field point takes its nearest sensor's raw reading.

RMSE (eq 3.42) of E_r, E_theta, H_phi over the zone's points and the recorded periods,
against the analytic field, per run; the experiment is driven by the real part of the
current; the ``imag`` experiment is the same one a quarter period later, and ``abs`` the
magnitude formed from the two (:func:`_errors`). Normalised units as in
:mod:`estim.experiments.dipole`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from estim.config.builders import check_interval
from estim.config.experiment import Experiment
from estim.errors import ConfigError
from estim.experiments.base import Quote, Result
from estim.experiments.dipole import TABLE_IDS
from estim.experiments.dipole_field.config import (
    DIVERGED_RATIO,
    FIT,
    KF,
    PLAIN,
    RLS,
    SOURCE_ONLY,
    Config,
)
from estim.experiments.dipole_field.filtering import (
    Layout,
    Plan,
    amplitude,
    cycle,
    draw_layout,
    field_analysis,
    fields_of,
    layout,
    levels,
    nis_of,
    observe,
    rows_of,
    sensor_operators,
    sensor_rows,
    setup,
    source_analysis,
    source_analysis_on_basis,
)
from estim.experiments.dipole_field.scoring import figure_slices, run_errors, smoothed
from estim.experiments.shared import claims, plots
from estim.numerics import metrics
from estim.reference.tablespec import TableSpec
from estim.util import lazy
from estim.util.workunits import map_tasks

pd = lazy.load("pandas")
grids = lazy.load("estim.fields.grid")

SCHEMA: dict = Config.schema()

__all__ = ["CLAIMS", "DIVERGED_RATIO", "FIT", "KF", "PLAIN", "QUOTES", "RLS", "SCHEMA",
           "SOURCE_ONLY", "TABLES", "Config", "Layout", "Plan", "amplitude", "draw_layout",
           "layout", "sensor_operators", "cycle", "field_analysis",
           "fields_of", "levels", "nis_of", "observe", "prepare", "rows_of", "run", "run_errors",
           "phasor_losses", "run_point", "sensor_rows", "setup", "smoothed", "source_analysis",
           "source_analysis_on_basis", "printout", "tiny", "work_size", "work_units"]
"""The analysis' protocol, and the parts of the cycle that field_study, the tests and the
DAPPER cross-check use."""


_KEYS = ("table_id", "s_no", "scenario", "zone", "beta_r", "noise_reading", "noise_param",
         "estimator", "field_component", "part")


TABLES = {
    "rmse": TableSpec("rmse.csv", _KEYS, ("rmse", "rmse_se", "runs", "field_rms",
                                          "relative"),
                      reference=("rmse",), join=(("s_no", ("s_no",)), ("part", ("part",))),
                      title="RMSE of the fields against the analytic dipole (field filter)",
                      reference_ids=tuple(TABLE_IDS.values())),
    "claims": claims.TABLE,
    "health": TableSpec("health.csv", ("scenario", "noise_reading", "noise_param",
                                       "estimator", "step"),
                        ("time", "effective_rank_min", "effective_rank_max", "nis", "runs"),
                        title="the ensembles over time: effective rank of the forecast "
                              "(singular values above 1e-6 of the largest), NIS per reading"),
}


CLAIMS = ((KF, FIT), (KF, PLAIN), (KF, SOURCE_ONLY), (KF, RLS), (KF, "measurement"),
          (RLS, "measurement"))
"""The field filter against the amplitude-only fit (the one source amplitude that fits the
whole record best: a smoother),
the plain simulation (the open loop: with the true source, the grid's floor), today's
source-only ETKF, the thesis' RLS baseline (its headline) and the raw nearest sensor; and RLS
against the raw sensor."""


QUOTES = (Quote("relative RMSE (RMSE / field RMS)", "rmse", "relative", by="estimator"),)


def prepare(config: Config, source: str) -> Plan:
    g = config.grid
    if g.n % 2:
        raise ConfigError(source, "grid.n", "expected an even number (no grid point on the "
                          "source's centre, where the analytic field is infinite)")
    grid = grids.Grid(g.n, g.length / g.n)
    half = g.length / 2
    for i, z in enumerate(config.zones):
        check_interval(z.r, source, f"zones[{i}].r")
        check_interval(z.theta_deg, source, f"zones[{i}].theta_deg")
        if z.r[1] > half - grid.spacing:
            raise ConfigError(source, f"zones[{i}].r", f"reaches the box's faces at "
                              f"{half:g}: keep it below {half - grid.spacing:g}")
    check_interval(config.sensors.r, source, "sensors.r")
    names = [s.name for s in config.scenarios]
    for i, s in enumerate(config.scenarios):
        if len(s.nominal_amplitude) != 2:
            raise ConfigError(source, f"scenarios[{i}].nominal_amplitude",
                              "expected [magnitude, phase in degrees]")
        if s.name in names[:i]:
            raise ConfigError(source, f"scenarios[{i}].name", f"repeats {s.name!r}")
    lo, hi = config.sensors.r
    candidates = np.flatnonzero((grid.r >= lo) & (grid.r <= hi))
    count = max(1, int(round(config.sensors.fraction * grid.size)))
    if count > candidates.size:
        raise ConfigError(source, "sensors.fraction", f"asks for {count} sensors; only "
                          f"{candidates.size} grid points lie between the sensor radii")
    fixed = (None if config.sensors.seed is None else
             draw_layout(grid, candidates, count, np.random.default_rng(config.sensors.seed)))
    zones = {}
    for z in config.zones:
        th = np.degrees(grid.theta)
        zones[z.name] = np.flatnonzero((grid.r >= z.r[0]) & (grid.r <= z.r[1])
                                          & (th >= z.theta_deg[0])
                                          & (th <= z.theta_deg[1]))
    if g.n % config.filter.block:
        raise ConfigError(source, "filter.block", f"expected a divisor of grid.n = {g.n}")
    wavelength = config.source.c / config.source.frequency
    beta_r = {z.name: "{:.2f}-{:.2f}".format(*(2 * np.pi * np.array(z.r) / wavelength))
              for z in config.zones}
    return Plan(grid=grid, zones=zones, beta_r=beta_r, candidates=candidates, count=count,
                fixed=fixed)


FIELD_COST_RATIO = 2000
"""``--max-work`` bounds cost in the currency of the other analyses, state-samples of the
stiff integrator. One grid-point update of the vectorised leapfrog costs far less. Measured
from the manifests of the stored results (one machine, the same ``--jobs``), at the earlier
ratio of 1000: ``mosfet_saturation`` did 9.7e3 state-samples per second of wall time,
``dipole_field`` 9.1e4 of these units and ``field_members`` (up to 200 members) 2.0e4. The
ratio is doubled so that the dearest field config costs about what the integrator does per
unit; grid-point updates are divided by it."""


def work_size(config: Config) -> int:
    """Grid-point updates (``4 n^3`` per member and step; two ensembles, the field filter's
    and the source-only one, and three free runs: the plain simulation and the fit's basis)
    over every scenario, noise row and run, over :data:`FIELD_COST_RATIO`."""
    g, t = config.grid, config.time
    per_period = round(g.n / (g.courant * g.length))
    steps = (t.spinup_periods + t.periods) * per_period
    points = len(config.noise.source_levels) * len(config.noise.readings or [1])
    updates = (4 * g.n ** 3 * (2 * config.filter.members + 3) * steps * points
               * len(config.scenarios) * config.monte_carlo.runs)
    return int(updates / FIELD_COST_RATIO)


def work_units(exp: Experiment) -> int:
    return len(_points(exp))


def tiny(config: Config) -> dict:
    """Seconds of work: a 12-point grid, one zone and scenario, 5 members, one period after
    one of spin-up, one run."""
    return {"grid.n": 12, "zones": [{"name": "far", "r": [0.9, 1.5]}],
            "sensors.r": [0.2, 1.5], "sensors.fraction": 0.05,
            "scenarios": [s.to_spec() for s in config.scenarios[:1]],
            "noise.source_levels": config.noise.source_levels[:1],
            "noise.readings": (config.noise.readings or ["sigma"])[:1],
            "filter.members": 5, "time": {"spinup_periods": 1, "periods": 1},
            "monte_carlo.runs": 1}


def _points(exp: Experiment) -> list[tuple]:
    noise = exp.config.noise
    return [(s, r, i) for s in range(len(exp.config.scenarios))
            for r in range(len(noise.readings)) for i in range(len(noise.source_levels))]


def run_point(exp: Experiment, key: tuple) -> tuple[list[dict], list, dict, list[dict]]:
    """Rows of one scenario and noise row over every run; for the first noise row of a
    scenario, the figure's slices from run 1 at the last recorded step; and the filters'
    health over time (effective rank, NIS)."""
    config, plan = exp.config, exp.plan
    grid = plan.grid
    s_idx, r_idx, l_idx = key
    scenario = config.scenarios[s_idx]
    reading = config.noise.readings[r_idx]
    level = float(config.noise.source_levels[l_idx])
    nominal = amplitude(scenario.nominal_amplitude)
    per_run, health = {}, []
    for run in range(config.monte_carlo.runs):
        su = setup(config, plan, layout(config, plan, run))
        sensors = su.layout.sensors
        rng = exp.config.monte_carlo.rng(*key, run)
        out = cycle(exp, su, nominal, rng, euler=run == 0)
        health += [{**h, "run": run} for h in out["health"]]
        smooth = smoothed(out["measured"], out["times"], su.dipole.omega, config.rls)
        per_run[run] = run_errors(exp, grid, out["phasors"], su.dipole, sensors, out["times"],
                               out["traces"], out["measured"], smooth, su.quarter)
        if run == 0 and r_idx == 0 and l_idx == 0:
            slices = figure_slices(grid, out["phasors"], su.dipole, out["times"], out["traces"])
    figure = {"scenario": scenario.name, **slices} if r_idx == 0 and l_idx == 0 else {}
    rows, cells = _rows(exp, key, reading, level, per_run)
    return rows, cells, figure, _health_rows(exp, key, reading, level, health)


def _health_rows(exp, key, reading, level, health) -> list[dict]:
    """Per filter and recorded step: the effective rank of the forecast ensemble (singular
    values of the anomalies of ``A`` and ``Phi`` at ``t`` above 1e-6 of the largest; min and
    max over runs) and the NIS
    per reading (mean over runs)."""
    df = pd.DataFrame(health)
    out = []
    for (name, step), g in df.groupby(["estimator", "step"], sort=False):
        out.append({"scenario": exp.config.scenarios[key[0]].name,
                    "noise_reading": reading, "noise_param": level, "estimator": name,
                    "step": int(step), "time": float(g["time"].iloc[0]),
                    "effective_rank_min": int(g["effective_rank"].min()),
                    "effective_rank_max": int(g["effective_rank"].max()),
                    "nis": float(g["nis"].mean()), "runs": len(g)})
    return out


def _rows(exp, key, reading, level, per_run) -> tuple[list[dict], list]:
    """The rows of one scenario and noise row (a row per zone, component and part), and per
    zone and component the claims cell's per-run losses: the RMSE of the complex phasor,
    ``sqrt(MSE_real + MSE_imag)``, one value per run (the real and imaginary parts of one run
    are one experiment, and ``abs`` is formed from them: parts are columns, not cells). An
    RMSE above :data:`DIVERGED_RATIO` times the field's RMS is a diverged run (reported
    ``inf``)."""
    config = exp.config
    scenario = config.scenarios[key[0]].name
    s_no = key[2] + 1
    rows = []
    complex_mse: dict[tuple, dict[str, list]] = {}
    for cell in per_run[0]:
        name, zone, comp, part = cell
        present = [r for r in per_run if cell in per_run[r]]     # the Euler run: run 1 only
        mse = np.array([per_run[r][cell][0] for r in present])
        ref = float(np.mean([per_run[r][cell][1] for r in present]))
        values = np.sqrt(mse)
        broke = ~(values <= DIVERGED_RATIO * np.sqrt(ref))
        mean, se = metrics.mean_and_se(values) if len(values) > 1 else (float(values[0]),
                                                                        float("nan"))
        if broke.any():
            mean, se = float("inf"), float("nan")
        if part in ("real", "imag"):
            parts = complex_mse.setdefault((zone, comp), {}).setdefault(name, [])
            parts.append((mse, ref))
        rows.append({"table_id": TABLE_IDS.get((comp, zone, name), ""), "s_no": s_no,
                     "scenario": scenario, "zone": zone, "beta_r": exp.plan.beta_r[zone],
                     "noise_reading": reading,
                     "noise_param": level, "estimator": name, "field_component": comp,
                     "part": part, "rmse": mean, "rmse_se": se, "runs": len(values),
                     "field_rms": np.sqrt(ref), "relative": mean / np.sqrt(ref)})
    losses = phasor_losses(complex_mse)
    cells = [(claims.cell(scenario=scenario, zone=zone, noise_reading=reading,
                          noise_param=level, field_component=comp), cell_losses)
             for (zone, comp), cell_losses in losses.items()]
    return rows, cells


def phasor_losses(parts: dict) -> dict:
    """The claims' per-run losses of the complex phasor: for each key and estimator of
    ``parts`` (``{key: {name: [(mse_real, ref_real), (mse_imag, ref_imag)]}}``, each ``mse``
    per run and ``ref`` the mean square truth) ``sqrt(MSE_real + MSE_imag)``, a run diverged
    above :data:`DIVERGED_RATIO` times ``sqrt(ref_real + ref_imag)``. An estimator without
    both parts is left out."""
    out: dict = {}
    for key, by_name in parts.items():
        for name, pair in by_name.items():
            if len(pair) != 2:
                continue
            (mse_re, ref_re), (mse_im, ref_im) = pair
            values = np.sqrt(np.add(mse_re, mse_im))
            broke = ~(values <= DIVERGED_RATIO * np.sqrt(ref_re + ref_im))
            out.setdefault(key, {})[name] = claims.Losses(values, broke)
    return out


def _run_point_args(args):
    return run_point(*args)


def run(exp: Experiment, jobs: int = 1, on_done: Callable[[], None] | None = None) -> Result:
    done = map_tasks(_run_point_args, [(exp, k) for k in _points(exp)], jobs, on_done)
    df = pd.DataFrame([row for part, _, _, _ in done for row in part])[TABLES["rmse"].columns]
    table = claims.table([c for _, cells, _, _ in done for c in cells], CLAIMS, "RMSE")
    health = pd.DataFrame([row for *_, part in done for row in part])[TABLES["health"].columns]
    figures = {}
    for _, _, fig, _ in done:
        if fig:
            name = "field_slices_" + "".join(ch if ch.isalnum() else "_"
                                             for ch in fig["scenario"]).strip("_")
            figures[name] = plots.field_slices(
                fig, f"{fig['scenario']}: |E| and |H| in the x-z plane through the source, "
                f"t = {fig['time']:.3g} periods (run 1)")
    figures["effective_rank"] = plots.ensemble_rank(health)
    return Result(tables={"rmse": df.reset_index(drop=True), "claims": table,
                          "health": health.reset_index(drop=True)}, figures=figures)


def printout(result: Result) -> str:
    df = result.tables["rmse"]
    view = df[df["part"] == "real"].pivot_table(
        index=["scenario", "noise_param", "zone", "field_component"], columns="estimator",
        values="relative", sort=False)
    return "relative RMSE (RMSE / field RMS)\n" + view.to_string(
        float_format=lambda v: f"{v:.3g}")
