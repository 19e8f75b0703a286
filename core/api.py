"""estim from Python (a notebook, a script): run a config, read stored results, and use the
models and estimators directly on arrays.

    import estim
    r = estim.run("configs/mosfet_saturation.yaml", runs=3)
    r.tables["rmse"]            # pandas DataFrames, one per table
    r.claims                    # the claims, judged (docs/claims.md)
    r.save("scratch")           # scratch/mosfet_saturation/: CSV, PNG, manifest.json
    stored = estim.load("results/mosfet_saturation")

    model = estim.models.get("mosfet_ekv")(V_IN=0.35)
    ekf = estim.estimators.get("ekf")(Q=1e-3, R=0.01, P0=1e-3)
    estimate = ekf.run(model, z, u, dt, x0=model.operating_point())
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from estim import store
from estim.config.experiment import Experiment
from estim.config.loading import MAX_WORK, load_data, load_file
from estim.errors import UsageError
from estim.experiments.base import Result
from estim.reference import view
from estim.util import lazy
from estim.util.shipped import shipped_folder

pd = lazy.load("pandas")


def _overrides(keys: dict, overrides: dict | None) -> dict:
    """``runs`` and ``seed`` as ``monte_carlo.*``; other keywords with ``__`` for ``.``
    (``simulation__rtol=1e-6``); ``overrides`` as key paths (list items by index, as on the
    command line: ``estimators[0].settings.Q`` or ``estimators.0.settings.Q``). Values as a
    config holds them (numpy numbers and arrays as plain ones); a key that is not a key
    path is a ``UsageError`` naming it."""
    from estim.config.overrides import OVERRIDE_KEY, key_path
    from estim.config.settings import plain, shown

    if overrides is not None and not isinstance(overrides, dict):
        raise UsageError(f"overrides: expected a mapping of key paths to values, got "
                         f"{type(overrides).__name__}")
    out = {}
    for key, value in (overrides or {}).items():
        if not isinstance(key, str) or not OVERRIDE_KEY.fullmatch(key.strip()):
            raise UsageError(f"overrides: key {shown(key)} is not a key path such as "
                             "'monte_carlo.runs' or 'estimators[0].settings.Q'")
        out[key_path(key.strip())] = plain(value)
    for key, value in keys.items():
        if key in ("runs", "seed") and value is None:          # None: the config's own
            continue
        path = {"runs": "monte_carlo.runs", "seed": "monte_carlo.seed"}.get(
            key, key.replace("__", "."))
        out[path] = plain(value)
    return out


def config_path(config: str | Path) -> Path:
    """``config`` as given when it exists; else a shipped config of that name
    (``configs/mosfet_saturation.yaml`` or ``mosfet_saturation`` from any folder)."""
    path = Path(config)
    if path.exists() or path.parent.name not in ("", "configs") or path.suffix not in ("",
                                                                                      ".yaml"):
        return path                          # (a typo such as .yml is not a shipped config)
    shipped = shipped_folder("configs") / f"{path.stem}.yaml"
    if shipped.is_file():
        return shipped
    return path


def experiment(config: str | Path | dict, overrides: dict | None = None, quick: bool = False,
               max_work: int = MAX_WORK, **keys: Any) -> Experiment:
    """The validated experiment of a config file or mapping, with overrides (see
    :func:`run`); a mistake is a :class:`estim.errors.ConfigError` naming the key path."""
    given = _overrides(keys, overrides)
    if isinstance(config, dict):
        from estim.config.settings import plain

        config = plain(config)
        return load_data(config, "<config>", str(config.get("name") or "experiment"), given,
                         max_work, quick)
    return load_file(config_path(config), given, max_work, quick)


def run(config: str | Path | dict, overrides: dict | None = None, *, jobs: int = 1,
        quick: bool = False, max_work: int = MAX_WORK, **keys: Any) -> Result:
    """Run a config (a YAML file, a shipped config's name, or a mapping) in this process and
    return its results.

    ``runs=3``, ``seed=7`` set the Monte Carlo runs and seed; any other key path as a
    keyword with ``__`` for ``.`` (``simulation__rtol=1e-6``) or in ``overrides``
    (``{"estimators.0.settings.Q": [...]}``). ``quick``: the analysis' quick profile."""
    import numpy as np

    from estim.engine import runner

    for name, value, least in (("jobs", jobs, 1), ("max_work", max_work, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
            raise ValueError(f"{name}: expected an integer >= {least}, got {value!r}")
    jobs, max_work = int(jobs), int(max_work)
    exp = experiment(config, overrides, quick, max_work, **keys)
    start = time.perf_counter()
    out = runner.execute(exp, jobs)
    return Result(out.tables, out.figures, name=exp.name, config=exp.spec, models=exp.models,
                  wall_time_s=time.perf_counter() - start, quick=quick)


def load(folder: str | Path) -> Result:
    """The results stored in ``folder`` (one experiment's folder: ``results/<name>``): its
    tables as DataFrames, its figures as file paths, its config and models from the
    manifest. A folder that holds none is a ``UsageError``."""
    from estim.config.registry import ANALYSES

    folder = Path(folder)
    if not (folder / "manifest.json").exists():
        raise UsageError(f"{folder}: no readable manifest.json (not an estim results folder)")
    stored = store.open_stored(folder, ANALYSES)
    config, manifest = stored.config, stored.manifest
    tables = {}
    for metric, spec in stored.analysis.TABLES.items():
        df = stored.table(spec)
        if df is not None:
            tables[metric] = view(df, spec)
    figures = {p.stem: p for where in (folder, folder / store.MACHINE_DIR)
               for p in sorted((where / "figures").glob("*"))
               if p.suffix in (".png", ".svg", ".pdf")}
    seconds = store.read_run_record(folder).get("wall_time_s")
    return Result(tables, figures, name=folder.name, config=config,
                  models=manifest.get("models") or {},
                  wall_time_s=float(seconds) if isinstance(seconds, int | float) else 0.0)


def from_netlist(path: str | Path, input: str | list[str], output: str,
                 name: str | None = None) -> type:
    """The model class of the SPICE netlist at ``path``, driven through the voltage
    source(s) ``input`` and measuring ``output`` (``v(node)`` or ``v(a,b)``), as a config's
    ``model: {netlist: ..., input: ..., output: ...}`` block makes it. It is registered under
    ``name`` (default ``netlist:<file stem>``), so ``estim.models.get(name)`` gives it too.
    Make a model with its parameters (``cls(vin_bias=0.35)``); its states are
    ``model.state_names``: the node voltages ``v(node)`` in the alphabetical order of the
    node names, then the inductor currents, which is the order of a vector ``Q`` or ``P0``
    given in ``noise_units: state``."""
    from estim.spice import model_class

    return model_class(Path(path), input, output, name=name)
