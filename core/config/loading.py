"""Loading a config: YAML text (:mod:`.yaml_reader`) and overrides (:mod:`.overrides`) ->
common keys -> the analysis' own schema and checks -> a frozen Experiment.

Every error is a :class:`estim.errors.ConfigError` naming the file, the key path and what was
expected, raised before any work starts. The common keys are declared here; everything else
belongs to the analysis (``ANALYSES[name].SCHEMA`` and ``.prepare``).
"""

from __future__ import annotations

import copy
import itertools
import math
import re
import stat
import weakref
from pathlib import Path
from typing import Any

from estim import reference
from estim.config import registry
from estim.config.builders import recording_models
from estim.config.experiment import Experiment
from estim.config.overrides import OVERRIDE_KEY, apply_overrides, key_path
from estim.config.registry import ANALYSES
from estim.config.settings import (
    Settings,
    block,
    list_of,
    mapping,
    number,
    setting,
    settings_class,
    text,
    validate,
)
from estim.config.yaml_reader import load_yaml, read_config
from estim.errors import ConfigError, ConfigErrors, UsageError


@settings_class
class Tolerance(Settings):
    """How ``estim check`` compares one column (:func:`estim.engine.compare.compare_tables`); a cell
    passes when any criterion holds."""

    rtol: float = setting(0.0, number(minimum=0.0, maximum=1.0), doc="relative tolerance")
    atol: float = setting(0.0, number(minimum=0.0, maximum=1.0), doc="absolute tolerance")
    se: float | None = setting(None, number(positive=True, maximum=10.0),
                               doc="within this many combined standard errors")
    se_column: str | None = setting(None, text(max_length=100),
                                    doc="the standard errors' column (default <column>_se)")
    binomial: float | None = setting(None, number(positive=True, maximum=10.0),
                                     doc="a count within this many binomial standard "
                                         "deviations")
    trials: list | None = setting(None, list_of(text(max_length=100), max_length=4),
                                  doc="the columns whose sum is the count's number of runs")
    skip: str | None = setting(None, text(), doc="do not compare; the reason, printed by check")


TOLERANCE: dict = Tolerance.schema()


@settings_class
class Check(Settings):
    """What ``estim check`` allows per column (docs/checking.md)."""

    tolerances: dict = setting({}, mapping, doc="column -> tolerance (rtol, atol, se, ...)")


@settings_class
class Common(Settings):
    """Keys every config has, whatever its analysis."""

    name: str | None = setting(None, text(max_length=100),
                               doc="the results folder's name; none: the file's stem")
    title: str = setting("", text(), doc="the figures' title")
    analysis: str = setting("estimation", text(ANALYSES), doc="a registered analysis")
    reproduces: list = setting([], list_of(text(max_length=20), nonempty=False, max_length=50),
                               doc="the thesis tables it reproduces (estim list)")
    plugins: list = setting([], list_of(text(max_length=4096), nonempty=False, max_length=20),
                            doc="Python files (relative to the config) that register models "
                                "and estimators of your own")
    claim_margin: float = setting(0.0, number(minimum=0.0, below=1.0), unit="fraction",
                                  doc="margin of practical significance of every claim: a "
                                      "difference whose interval does not clear this fraction "
                                      "of the worse loss is undecided (docs/claims.md)")
    check: Check = block(Check, doc="estim check's tolerances")


COMMON: dict = Common.schema()
"""Keys every config may have; an analysis' ``SCHEMA`` adds its own."""


def schema_of(analysis: str) -> dict:
    return {**COMMON, **ANALYSES[analysis].SCHEMA}


MAX_WORK = 50_000_000
"""Default bound on an experiment's work (state-samples, ``work_size`` of its analysis);
``--max-work`` raises it."""


QUICK_WORK = 2**62
"""The work bound of the whole config behind a ``--quick`` run (whose own profile is held
to ``--max-work``): the grid it does not run may be large, not unbounded."""


def parse(text_: str, source: str, default_name: str, max_work: int = MAX_WORK) -> Experiment:
    """Validate YAML ``text_`` read from ``source`` (a path shown in messages)."""
    return parse_data(load_yaml(text_, source), source, default_name, max_work)


def parse_data(data: dict, source: str, default_name: str,
               max_work: int = MAX_WORK, plan: bool = True) -> Experiment:
    """Validate an already loaded config mapping; ``max_work`` bounds its work size. With
    ``plan=False`` the analysis' ``prepare`` (models built, DC points found, grids laid) is
    skipped: the keys, values and table ids are checked, and ``Experiment.plan`` is None
    (``estim list`` reads titles, not plans)."""
    data = copy.deepcopy(data)
    sweep = data.pop("sweep", None) if isinstance(data, dict) else None
    plugins = load_plugins(data.get("plugins") if isinstance(data, dict) else None, source)
    with registry.plugin_scope(plugins):
        return _parse_checked(data, sweep, source, default_name, max_work, plan)


def _parse_checked(data: dict, sweep: Any, source: str, default_name: str, max_work: int,
                   plan: bool) -> Experiment:
    """:func:`parse_data` once the config's plugins are loaded: only theirs are visible."""
    registry.resolve_model_block(data, source)
    analysis = data.get("analysis") or "estimation"
    validate(analysis, text(ANALYSES), source, "analysis")
    try:
        spec = validate(data, schema_of(analysis), source, "")
    except ConfigErrors as exc:
        raise _wrong_analysis(exc, data, analysis, source) or exc from None
    spec["analysis"] = analysis
    from_file_name = not spec["name"]
    spec["name"] = spec["name"] or default_name
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", spec["name"]) or spec["name"].strip(".") == "":
        given = (" (no name: key, so the file's name; give one)" if from_file_name else "")
        raise ConfigError(source, "name", "expected ASCII letters, digits, '_', '-' or '.' "
                          f"only (it names the results folder), got {spec['name']!r}{given}")
    if spec.get("model") is not None:
        model_cls = registry.MODELS[spec["model"]["name"]]
        variant = spec["model"]["variant"]
        if model_cls.variants and variant is not None and variant not in model_cls.variants:
            raise ConfigError(source, "model.variant",
                              f"expected one of {sorted(model_cls.variants)}, got {variant!r}")
    module = ANALYSES[analysis]
    _check_table_ids(spec, module, source)
    config = module.Config.build(spec)
    work = module.work_size(config)
    if work > max_work:
        limit = (": too much for any run (--quick too checks the whole config, whose profile "
                 "it cuts)" if max_work >= QUICK_WORK else
                 f", more than the limit {max_work:.3g} (raise it with --max-work)")
        raise ConfigError(source, "", f"the experiment computes about {work:.3g} "
                          f"state-samples{limit}")
    if not plan:
        return Experiment(name=spec["name"], source=source, spec=spec, plan=None, models={},
                          config=config)
    with recording_models() as models:
        prepared = module.prepare(config, source)
    _check_tolerances(spec, module, source)
    if sweep is not None:
        spec["sweep"] = _check_sweep(sweep, data, source, default_name, max_work, work)
    return Experiment(name=spec["name"], source=source, spec=spec, plan=prepared,
                      models=models, config=config)


def _wrong_analysis(exc: ConfigErrors, data: dict, analysis: str,
                    source: str) -> ConfigError | None:
    """One line in place of a line per key when the config's top-level keys are another
    analysis' (``analysis`` is valid, but not this file's): None when it is not so."""
    unknown = [e.path for e in exc.errors if "." not in e.path and "[" not in e.path
               and e.message.startswith("unknown key")]
    if len(unknown) < 2:
        return None
    fits = [name for name in ANALYSES if name != analysis
            and all(key in schema_of(name) for key in unknown)]
    shown = ", ".join(unknown[:6]) + (f" and {len(unknown) - 6} more" if len(unknown) > 6
                                      else "")
    where = f"; they are keys of {', '.join(repr(n) for n in fits)}" if fits else ""
    return ConfigError(source, "analysis", f"{analysis!r} takes none of the keys {shown}"
                       f"{where}: is the analysis the file's?")


MAX_PLUGIN_BYTES = 1 << 20


def load_plugins(plugins: Any, source: str) -> list[str]:
    """Import the config's ``plugins`` (Python files, relative to the config's folder) so the
    models and estimators they define register themselves before the config is validated;
    their module names (:func:`estim.config.registry.plugin_scope`). A file that is missing, not a
    regular ``.py`` file of at most 1 MiB, or fails to import is a ``ConfigError`` naming
    it."""
    if plugins is None:
        return []
    validate(plugins, COMMON["plugins"][0], source, "plugins")
    base = Path(source).parent if source else Path.cwd()
    paths = []
    for i, name in enumerate(plugins):
        path = (base / name).resolve()
        where = f"plugins[{i}]"
        try:
            info = path.stat()
        except OSError as exc:
            raise ConfigError(source, where, f"cannot read {name!r} "
                              f"({exc.strerror or exc})") from None
        if path.suffix != ".py" or not stat.S_ISREG(info.st_mode):
            raise ConfigError(source, where, f"expected a Python file (.py), got {name!r}")
        if info.st_size > MAX_PLUGIN_BYTES:
            raise ConfigError(source, where, f"{name!r} is larger than 1 MiB")
        paths.append((where, path))
    names = []
    for where, path in paths:
        try:
            names += registry.load_plugins([path])
        except SystemExit as exc:       # sys.exit() in the user's module would end estim
            raise ConfigError(source, where, f"importing {path.name} called sys.exit"
                              f"({str(exc.code)[:60]}); a plugin must only define") from None
        except Exception as exc:  # noqa: BLE001 - the user's code: any failure is theirs
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            raise ConfigError(source, where, f"importing {path.name} failed: "
                              f"{type(exc).__name__}: {first}") from None
    return names


MAX_SWEEP_CELLS = 10_000


MAX_CHECKED_CELLS = 1_000      # grids up to this size have every combination validated up front


def _check_sweep(sweep: Any, data: dict, source: str, default_name: str, max_work: int,
                 work: int) -> dict:
    """``sweep: {key.path: [values], ...}``: every value of every key makes a valid config on
    its own, and so does every combination of a grid of up to :data:`MAX_CHECKED_CELLS`
    cells (checked here, before any work; a larger grid's cells are parsed when it runs,
    before its first cell), and the whole grid stays under ``max_work``
    (each value scales the work of the config as it does alone, e.g. ``monte_carlo.runs``).
    The grid is the product of the lists in the order given, the last key fastest."""
    if not isinstance(sweep, dict) or not sweep:
        raise ConfigError(source, "sweep", "expected a mapping of key paths to lists of values")
    out, total = {}, float(max(work, 1))
    for key, values in sweep.items():
        if not isinstance(key, str) or not OVERRIDE_KEY.fullmatch(key) or key.startswith(
                ("sweep", "name", "analysis")):
            raise ConfigError(source, f"sweep.{key}", "expected a key path of the config "
                              "(list items by index), not name, analysis or sweep")
        if not isinstance(values, list) or not values or len(values) > MAX_SWEEP_CELLS:
            raise ConfigError(source, f"sweep.{key}", f"expected a list of 1 to "
                              f"{MAX_SWEEP_CELLS} values")
        path = key_path(key)
        scale = 0.0
        for i, value in enumerate(values):
            try:
                cell = parse_data(apply_overrides(data, {path: value}, source), source,
                                  default_name, max_work)
            except ConfigError as exc:
                raise ConfigError(source, f"sweep.{key}[{i}]",
                                  f"{exc.path}: {exc.message}" if exc.path else exc.message
                                  ) from None
            scale += ANALYSES[cell.analysis].work_size(cell.config) / max(work, 1)
        if path in out:
            raise ConfigError(source, f"sweep.{key}", "the same key path as another sweep key")
        out[path] = values
        total *= scale
    cells = math.prod(len(v) for v in out.values())
    if cells > MAX_SWEEP_CELLS or total > max_work:
        raise ConfigError(source, "sweep", f"{cells} cells of about {total:.3g} state-samples "
                          f"in all exceed the limits ({MAX_SWEEP_CELLS} cells, {max_work:.3g} "
                          "state-samples; raise the latter with --max-work)")
    if len(out) > 1 and cells <= MAX_CHECKED_CELLS:
        for combo in itertools.product(*out.values()):
            values = dict(zip(out, combo, strict=True))
            try:
                parse_data(apply_overrides(data, values, source), source, default_name,
                           2**62)
            except ConfigError as exc:
                shown = ", ".join(f"{k}={v!r}" for k, v in values.items())
                raise ConfigError(source, "sweep", f"the cell {shown}: " + (
                    f"{exc.path}: {exc.message}" if exc.path else exc.message)) from None
    return out


def _check_table_ids(spec: dict, module, source: str) -> None:
    """Each ``tables.<metric>`` names a shipped reference table this metric may join, or is
    :data:`estim.reference.OWN_TABLE`."""
    for metric, table_id in (spec.get("tables") or {}).items():
        table = module.TABLES.get(metric)
        if table_id is None or table is None or table_id == reference.OWN_TABLE:
            continue
        if table.reference_ids and table_id not in table.reference_ids:
            raise ConfigError(source, f"tables.{metric}", f"expected one of "
                              f"{[*table.reference_ids, reference.OWN_TABLE]} for a {metric} "
                              f"table, got {table_id!r} ('{reference.OWN_TABLE}': a table of our "
                              "own, joined to no printed one)")
        if not reference.has_reference_table(table_id):
            raise ConfigError(source, f"tables.{metric}",
                              f"no thesis Table {table_id} ships with estim")


def _check_tolerances(spec: dict, module, source: str) -> None:
    """Tolerances are for columns the analysis writes, and name columns that exist."""
    columns = {c for table in module.TABLES.values() for c in table.columns}
    tolerances = spec["check"]["tolerances"]
    for column, tol in tolerances.items():
        path = f"check.tolerances.{column}"
        if column not in columns:
            raise ConfigError(source, path, f"no table of a {spec['analysis']} analysis has "
                              f"this column; expected one of {sorted(columns)}")
        tolerances[column] = tol = validate(tol, TOLERANCE, source, path)
        named = [tol["se_column"]] if tol["se_column"] else []
        for other in named + (tol["trials"] or []):
            if other not in columns:
                raise ConfigError(source, path, f"no column {other!r}")
        if tol["binomial"] is not None and not tol["trials"]:
            raise ConfigError(source, f"{path}.trials", "binomial needs the columns whose sum "
                              "is the number of runs")


_CELLS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def sweep_cells(exp: Experiment) -> list[tuple[dict, Experiment]]:
    """The experiments of a ``sweep:`` block, each with its values (the product of the lists
    in the order given, the last key fastest); ``[({}, exp)]`` without one. Every cell keeps
    the config's seed: the cells share their random numbers, so their differences are the
    swept values' own. Expanded once per experiment."""
    sweep = exp.sweep
    if not sweep:
        return [({}, exp)]
    if exp in _CELLS:
        return _CELLS[exp]
    base = {k: v for k, v in exp.spec.items() if k != "sweep"}
    keys = list(sweep)
    cells = []
    for combo in itertools.product(*(sweep[k] for k in keys)):
        values = dict(zip(keys, combo, strict=True))
        cells.append((values, parse_data(apply_overrides(base, values, exp.source), exp.source,
                                         exp.name, max_work=2**62)))
    _CELLS[exp] = cells
    return cells


def load_file(path: Path, overrides: dict | None = None, max_work: int = MAX_WORK,
              quick: bool = False, plan: bool = True) -> Experiment:
    """Read and validate one config file (a regular file of at most 1 MiB of UTF-8) with
    ``overrides`` (key path -> value) applied first; with ``quick``, shrunk to its analysis'
    quick profile (``tiny``: the first cell of a sweep) and validated again."""
    path = Path(path)
    text_ = read_config(path)
    return load_data(load_yaml(text_, str(path)), str(path), path.stem, overrides, max_work,
                     quick, plan)


def load_data(data: dict, source: str, default_name: str, overrides: dict | None = None,
              max_work: int = MAX_WORK, quick: bool = False, plan: bool = True) -> Experiment:
    """:func:`load_file` for a config already read into a mapping."""
    if overrides:
        data = apply_overrides(data, overrides, source)
    exp = parse_data(data, source, default_name, QUICK_WORK if quick else max_work, plan)
    if quick:
        exp = parse_data(quick_data(exp), f"{source} (--quick)", default_name, max_work, plan)
    return exp


def quick_data(exp: Experiment) -> dict:
    """The config of ``exp``'s quick profile (``--quick``): the first cell of a sweep (the
    grid's size is moot), shrunk by the overrides its analysis' ``tiny`` gives."""
    spec = {k: v for k, v in exp.spec.items() if k != "sweep"}
    config = exp.config
    if exp.sweep:
        spec = apply_overrides(spec, {k: v[0] for k, v in exp.sweep.items()}, exp.source)
        config = parse_data(spec, exp.source, exp.name, max_work=2**62, plan=False).config
    return apply_overrides(spec, ANALYSES[exp.analysis].tiny(config), exp.source)


def load_files(paths, overrides: dict | None = None, max_work: int = MAX_WORK,
               quick: bool = False, plan: bool = True) -> list[Experiment]:
    """:func:`load_file` of every path; two configs of one name are a ``UsageError`` (they
    would write one results folder)."""
    exps = [load_file(Path(p), overrides, max_work, quick, plan) for p in paths]
    names = [e.name for e in exps]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise UsageError(f"two configs share the name {dupes[0]!r}")
    return exps
