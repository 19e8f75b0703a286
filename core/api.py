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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from estim import io, lazy
from estim.config import MAX_WORK, load_data, load_file, spec_hash
from estim.errors import UsageError
from estim.schema import Experiment

pd = lazy.load("pandas")


@dataclass
class Result:
    """An experiment's results: its tables (DataFrames by metric), its figures (matplotlib
    figures after :func:`run`; file paths after :func:`load`), the resolved config and every
    model it built."""

    name: str
    config: dict
    tables: dict[str, pd.DataFrame]
    figures: dict[str, Any] = field(default_factory=dict)
    models: dict = field(default_factory=dict)
    wall_time_s: float = 0.0
    quick: bool = False
    """Made by the analysis' quick profile (:func:`run` with ``quick=True``)."""

    @property
    def claims(self) -> pd.DataFrame | None:
        """The claims table (docs/claims.md), or ``None``."""
        return self.tables.get("claims")

    def save(self, folder: str | Path, figure_format: str = "png") -> Path:
        """Write ``folder/<name>/`` as ``estim run`` does (tables as CSV, figures, manifest),
        as a unit; returns that folder. Figures that are file paths (a loaded result) are
        copied."""
        if not str(folder).strip():
            raise UsageError("save: an empty folder name (give '.' for the working folder)")
        if figure_format.lower() not in io.FIGURE_FORMATS:
            raise ValueError(f"figure_format {figure_format!r}: expected one of "
                             f"{io.FIGURE_FORMATS}")
        out = Path(folder)
        io.ensure_writable(out)
        stored = io.read_manifest(out / self.name) if self.quick else None
        if stored is not None and "quick" not in str(stored.get("command", "")):
            raise UsageError(f"{out / self.name} holds a full run's results; a quick result "
                             "does not replace them (save it elsewhere)")
        command = "estim.run(quick=True)" if self.quick else "estim.run"
        with io.ResultFolder(out, self.name) as target:
            for metric, df in self.tables.items():
                io.write_csv(df, target.path / f"{metric}.csv")
            for name, fig in self.figures.items():
                if isinstance(fig, (str, Path)):
                    dest = target.path / "figures" / Path(fig).name
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    io.atomic_write_bytes(dest, Path(fig).read_bytes())
                else:
                    io.write_figure(fig, target.path / "figures" / f"{name}.{figure_format}")
            io.write_manifest(target.path, self.config, spec_hash(self.config),
                              self.wall_time_s, command=command, models=self.models)
            target.commit()
        return out / self.name


def _overrides(keys: dict, overrides: dict | None) -> dict:
    """``runs`` and ``seed`` as ``monte_carlo.*``; other keywords with ``__`` for ``.``
    (``simulation__rtol=1e-6``); ``overrides`` as key paths."""
    out = dict(overrides or {})
    for key, value in keys.items():
        if key in ("runs", "seed") and value is None:          # None: the config's own
            continue
        path = {"runs": "monte_carlo.runs", "seed": "monte_carlo.seed"}.get(
            key, key.replace("__", "."))
        out[path] = value
    return out


def config_path(config: str | Path) -> Path:
    """``config`` as given when it exists; else a shipped config of that name
    (``configs/mosfet_saturation.yaml`` or ``mosfet_saturation`` from any folder)."""
    path = Path(config)
    if path.exists() or path.parent.name not in ("", "configs") or path.suffix not in ("",
                                                                                      ".yaml"):
        return path                          # (a typo such as .yml is not a shipped config)
    from importlib.util import find_spec

    try:
        spec = find_spec("estim.cli.configs")
    except ModuleNotFoundError:
        spec = None
    folders = [Path(f) for f in (spec.submodule_search_locations or [])] if spec else []
    folders.append(Path(__file__).resolve().parents[1] / "configs")     # a source checkout
    for folder in folders:
        shipped = folder / f"{path.stem}.yaml"
        if shipped.is_file():
            return shipped
    return path


def experiment(config: str | Path | dict, overrides: dict | None = None, quick: bool = False,
               max_work: int = MAX_WORK, **keys: Any) -> Experiment:
    """The validated experiment of a config file or mapping, with overrides (see
    :func:`run`); a mistake is a :class:`estim.errors.ConfigError` naming the key path."""
    given = _overrides(keys, overrides)
    if isinstance(config, dict):
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
    from estim import runner

    for name, value, least in (("jobs", jobs, 1), ("max_work", max_work, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ValueError(f"{name}: expected an integer >= {least}, got {value!r}")
    exp = experiment(config, overrides, quick, max_work, **keys)
    start = time.perf_counter()
    out = runner.execute(exp, jobs)
    return Result(exp.name, exp.spec, out.tables, out.figures, exp.models,
                  time.perf_counter() - start, quick=quick)


def load(folder: str | Path) -> Result:
    """The results stored in ``folder`` (one experiment's folder: ``results/<name>``): its
    tables as DataFrames, its figures as file paths, its config and models from the
    manifest. A folder that holds none is a ``UsageError``."""
    from estim.analyses import ANALYSES

    folder = Path(folder)
    manifest = io.read_manifest(folder)
    if manifest is None or not isinstance(manifest.get("config"), dict):
        raise UsageError(f"{folder}: no readable manifest.json (not an estim results folder)")
    config = manifest["config"]
    analysis = ANALYSES.get(config.get("analysis", "estimation"))
    if analysis is None:
        raise UsageError(f"{folder}: its manifest names an unknown analysis "
                         f"{str(config.get('analysis'))[:60]!r}")
    tables = {}
    for metric, spec in analysis.TABLES.items():
        path = folder / spec.file
        if path.is_file():
            from estim.tables import view

            tables[metric] = view(io.read_table(path, spec), spec)
    figures = {p.stem: p for p in sorted((folder / "figures").glob("*"))
               if p.suffix in (".png", ".svg", ".pdf")}
    return Result(folder.name, config, tables, figures, manifest.get("models") or {},
                  float(manifest.get("wall_time_s") or 0.0))
