"""What every analysis module provides, and what the runner, the CLI and ``estim check`` use.

An analysis is a module registered by one line in :data:`estim.config.registry.ANALYSES`. It owns:

``SCHEMA``      its config keys beyond the common ones of :mod:`estim.config.loading` (a schema of
                :mod:`estim.config.settings`; it may re-declare a common key, e.g. make ``model``
                required)
``TABLES``      ``{metric: TableSpec}``: every table it writes, its columns and the key that
                joins a row to the reference (thesis or paper) table
``Config``      its settings (:mod:`estim.config.settings`); ``SCHEMA = Config.schema()``
``prepare(config, source) -> Plan`` cross-checks beyond the schema (raising ``ConfigError``
                with the key path) and the objects built once per experiment (models,
                estimators) as the analysis' own typed ``Plan``; stored as
                ``Experiment.plan``
``work_units(exp) -> int``          for progress reports
``work_size(config) -> int``        state-samples the run computes, bounded by ``--max-work``
``run(exp, jobs, on_done) -> Result``  tables (one DataFrame per metric) and figures
``printout(result) -> str``         what ``estim run`` prints after a run
``tiny(config) -> overrides``      the experiment shrunk to seconds (``--quick``, the
                                    contract tests), as key path -> value
``RUNS_ALONE``  optional, True for an analysis whose tables are timings: run with no other
                config's work beside it (:mod:`estim.engine.scheduler`)
``MACHINE``     optional: the names of the tables and figures that measure the machine
                running it (wall times): written under ``machine/`` in the result folder,
                which git ignores; left out of the manifest and never compared by
                ``estim check``
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from estim import store
from estim.errors import UsageError
from estim.util import lazy

pd = lazy.load("pandas")


@dataclass
class Result:
    """An experiment's results: its tables (DataFrames by metric) and figures (matplotlib
    figures from a run, file paths from :func:`estim.load`). An analysis' ``run`` fills these
    two; :func:`estim.run` and :func:`estim.load` add the experiment's name, its resolved
    config and every model it built."""

    tables: dict[str, pd.DataFrame]
    figures: dict[str, Any] = field(default_factory=dict)
    name: str = ""
    config: dict = field(default_factory=dict)
    models: dict = field(default_factory=dict)
    wall_time_s: float = 0.0
    quick: bool = False
    """Made by the analysis' quick profile (:func:`estim.run` with ``quick=True``)."""

    def __repr__(self) -> str:
        tables = ", ".join(f"{m} ({len(df)} rows)" for m, df in self.tables.items())
        return (f"Result({self.name or 'unnamed'}: tables {tables or 'none'}; "
                f"{len(self.figures)} figures)")

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
        if not self.name:
            raise UsageError("save: a result without a name (an analysis' own result: save "
                             "the one estim.run returns)")
        if figure_format.lower() not in store.FIGURE_FORMATS:
            raise ValueError(f"figure_format {figure_format!r}: expected one of "
                             f"{store.FIGURE_FORMATS}")
        out = Path(folder)
        store.ensure_writable(out)
        stored = store.read_manifest(out / self.name) if self.quick else None
        made_by = store.read_run_record(out / self.name).get("command", "") if stored else ""
        if stored is not None and "quick" not in str(made_by):
            raise UsageError(f"{out / self.name} holds a full run's results; a quick result "
                             "does not replace them (save it elsewhere)")
        command = "estim.run(quick=True)" if self.quick else "estim.run"
        from estim.config.registry import ANALYSES

        analysis = ANALYSES.get(self.config.get("analysis", "estimation"))
        machine = tuple(getattr(analysis, "MACHINE", ()))
        with store.ResultFolder(out, self.name) as target:
            for name, fig in self.figures.items():
                if isinstance(fig, (str, Path)):
                    dest = store.figure_path(target.path, Path(fig).stem,
                                             Path(fig).suffix.lstrip("."), machine)
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    store.atomic_write_bytes(dest, Path(fig).read_bytes())
                else:
                    dest = store.figure_path(target.path, name, figure_format, machine)
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    store.write_figure(fig, dest)
            store.write_tables_and_manifest(target.path, self.tables, self.config,
                                         self.wall_time_s, command=command,
                                         models=self.models, machine=machine)
            target.commit()
        return out / self.name


@dataclass(frozen=True)
class Quote:
    """A quantity a summary quotes: the range of ``column`` (a column of table ``metric``,
    or an expression of its columns for :meth:`pandas.DataFrame.eval`) over the rows that
    ``where`` selects (a :meth:`pandas.DataFrame.query`), one range per value of ``by``; with
    ``total``, the sum of ``column`` against the sum of ``total`` instead ("3 of 360")."""

    label: str
    metric: str
    column: str
    by: str | None = None
    where: str | None = None
    total: str | None = None
