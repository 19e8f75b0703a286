"""YAML text -> common keys -> the analysis' own schema and checks -> a frozen Experiment.

Every error is a :class:`estim.errors.ConfigError` naming the file, the key path and what was
expected, raised before any work starts. The common keys are declared here; everything else
belongs to the analysis (``ANALYSES[name].SCHEMA`` and ``.prepare``).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
from typing import Any

import yaml
from estim import registry, tables
from estim.analyses import ANALYSES
from estim.errors import ConfigError, UsageError
from estim.schema import Experiment, integer, list_of, mapping, model_block, number, text, validate

TOLERANCE: dict = {
    "rtol": (number(minimum=0.0, maximum=1.0), 0.0),
    "atol": (number(minimum=0.0, maximum=1.0), 0.0),
    "se": (number(positive=True, maximum=10.0), None),
    "se_column": (text(max_length=100), None),
    "binomial": (number(positive=True, maximum=10.0), None),
    "trials": (list_of(text(max_length=100), max_length=4), None),
    "skip": (text(), None),
}
"""How ``estim check`` compares one column (see :func:`estim.io.compare_tables`)."""

COMMON: dict = {
    "name": (text(max_length=100), None),
    "title": (text(), ""),
    "analysis": (text(ANALYSES), "estimation"),
    "reproduces": (list_of(text(max_length=20), nonempty=False, max_length=50), []),
    "model": (model_block(registry.MODELS)[0], None),
    "monte_carlo": ({
        "runs": (integer(1, 1_000_000), 1),
        "seed": (integer(0, 2**63 - 1), 0),
    }, None),
    "check": ({
        "tolerances": (mapping, {}),
    }, {}),
}
"""Keys every config may have; an analysis' ``SCHEMA`` adds its own and may make a common
key required (``model`` and ``monte_carlo`` are optional here: not every analysis has a
circuit or draws random numbers)."""


def schema_of(analysis: str) -> dict:
    return {**COMMON, **ANALYSES[analysis].SCHEMA}


def spec_hash(spec: dict) -> str:
    """sha256 of the resolved config: what ``estim check`` compares with the manifest."""
    text_ = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=float)
    return hashlib.sha256(text_.encode()).hexdigest()


MAX_WORK = 50_000_000
"""Default bound on an experiment's work (state-samples, ``work_size`` of its analysis);
``--max-work`` raises it."""

MAX_ALIASES = 64
MAX_DEPTH = 32
MAX_VALUES = 100_000
"""Bounds on a YAML config: anchors/aliases, nesting depth, values after alias expansion."""


class _ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses duplicate keys and bounds aliases and depth."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._aliases = 0
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise _Refused(self.peek_event().start_mark,
                               f"more than {MAX_ALIASES} YAML aliases")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(self.peek_event().start_mark,
                               f"nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:
                raise _Refused(key_node.start_mark, "a key that is not a plain value") from None
            if duplicate:
                raise _Refused(key_node.start_mark, f"duplicate key {key!r}")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_ConfigLoader.add_implicit_resolver(                  # YAML 1.2 floats: 1e-6, 2E3 (1.1: text)
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"))


class _Refused(Exception):
    def __init__(self, mark, message: str) -> None:
        super().__init__(message)
        self.mark, self.message = mark, message


def _count_values(data: Any, source: str) -> None:
    """Refuse a config that expands (through aliases) to more than ``MAX_VALUES`` values."""
    stack, seen = [data], 0
    while stack:
        node = stack.pop()
        seen += 1
        if seen > MAX_VALUES:
            raise ConfigError(source, "", f"the config expands to more than {MAX_VALUES} "
                              "values (YAML aliases?)")
        if isinstance(node, dict):
            stack.extend(node.keys())
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)


def load_yaml(text_: str, source: str) -> dict:
    """The mapping in YAML ``text_``; every problem a one-line :class:`ConfigError`."""
    try:
        data = yaml.load(text_, Loader=_ConfigLoader)  # noqa: S506 - a SafeLoader subclass
    except _Refused as exc:
        raise ConfigError(source, f"line {exc.mark.line + 1}", exc.message) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else ""
        problem = str(getattr(exc, "problem", None) or exc).splitlines()[0]
        raise ConfigError(source, where, f"not valid YAML ({problem})") from None
    except RecursionError:
        raise ConfigError(source, "", f"nested deeper than {MAX_DEPTH} levels") from None
    if data is None:
        raise ConfigError(source, "", "the file is empty")
    if not isinstance(data, dict):
        raise ConfigError(source, "", f"expected a mapping, got {type(data).__name__}")
    _count_values(data, source)
    return data


def parse(text_: str, source: str, default_name: str, max_work: int = MAX_WORK) -> Experiment:
    """Validate YAML ``text_`` read from ``source`` (a path shown in messages)."""
    return parse_data(load_yaml(text_, source), source, default_name, max_work)


def parse_data(data: dict, source: str, default_name: str,
               max_work: int = MAX_WORK) -> Experiment:
    """Validate an already loaded config mapping; ``max_work`` bounds its work size."""
    data = copy.deepcopy(data)
    sweep = data.pop("sweep", None) if isinstance(data, dict) else None
    analysis = data.get("analysis") or "estimation"
    validate(analysis, text(ANALYSES), source, "analysis")
    spec = validate(data, schema_of(analysis), source, "")
    spec["analysis"] = analysis
    spec["name"] = spec["name"] or default_name
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", spec["name"]) or spec["name"].strip(".") == "":
        raise ConfigError(source, "name", "expected letters, digits, '_', '-' or '.' only "
                          f"(it names the results folder), got {spec['name']!r}")
    if spec["model"] is not None:
        model_cls = registry.MODELS[spec["model"]["name"]]
        variant = spec["model"]["variant"]
        if model_cls.variants and variant is not None and variant not in model_cls.variants:
            raise ConfigError(source, "model.variant",
                              f"expected one of {sorted(model_cls.variants)}, got {variant!r}")
    module = ANALYSES[analysis]
    _check_table_ids(spec, module, source)
    work = module.work_size(spec)
    if work > max_work:
        raise ConfigError(source, "", f"the experiment computes about {work:.3g} state-samples, "
                          f"more than the limit {max_work:.3g} (raise it with --max-work)")
    plan = module.prepare(spec, source)
    _check_tolerances(spec, module, source)
    if sweep is not None:
        spec["sweep"] = _check_sweep(sweep, data, source, default_name, max_work, work)
    return Experiment(name=spec["name"], source=source, spec=spec, plan=plan)


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
            scale += ANALYSES[cell.analysis].work_size(cell.spec) / max(work, 1)
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
    :data:`estim.tables.OWN_TABLE`."""
    for metric, table_id in (spec.get("tables") or {}).items():
        table = module.TABLES.get(metric)
        if table_id is None or table is None or table_id == tables.OWN_TABLE:
            continue
        if table.reference_ids and table_id not in table.reference_ids:
            raise ConfigError(source, f"tables.{metric}", f"expected one of "
                              f"{list(table.reference_ids)} for a {metric} table, got "
                              f"{table_id!r}")
        if not tables.has_reference_table(table_id):
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


OVERRIDE_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:\[\d+\]|\.[A-Za-z0-9_]+)*")
"""A dotted key path, list items by index (``estimators.1.settings.Q`` or
``estimators[1].settings.Q``)."""


def parse_override(text_: str) -> tuple[str, Any]:
    """``key.path=value`` -> ``(key.path, value)`` with the value read as YAML (``1e-6``,
    ``[1, 2]``, ``{a: 1}``, ``true``, ``null``). Raises ``UsageError`` for a bad one."""
    key, sep, value = text_.partition("=")
    key = key.strip()
    if not sep or not OVERRIDE_KEY.fullmatch(key):
        raise UsageError(f"{text_!r}: expected key.path=value (list items by index)")
    try:
        parsed = yaml.load(value, Loader=_ConfigLoader) if value.strip() else ""  # noqa: S506
    except (yaml.YAMLError, _Refused) as exc:
        first = str(exc).strip().splitlines()[0]
        raise UsageError(f"{text_!r}: the value is not YAML ({first})") from None
    return key_path(key), parsed


def key_path(key: str) -> str:
    """A key path with list items by dot: ``estimators[0].label`` -> ``estimators.0.label``."""
    return re.sub(r"\[(\d+)\]", r".\1", key)


def _shown(keys: list[str]) -> str:
    """A key path as validation messages write it: ``estimators[1].settings``."""
    out = ""
    for key in keys:
        out += f"[{key}]" if key.isdigit() else (f".{key}" if out else key)
    return out


def _refuse_swept(data: dict, overrides: dict[str, Any], source: str) -> None:
    sweep = data.get("sweep") if isinstance(data, dict) else None
    if not isinstance(sweep, dict):
        return
    for key in sweep:
        swept = key_path(str(key))
        for given in overrides:
            if given == swept or swept.startswith(given + ".") or given.startswith(swept + "."):
                raise ConfigError(source, given, f"the config's sweep block sets {key} in "
                                  "every cell; give the whole block instead, e.g. "
                                  f"'sweep={{{key}: [...]}}'")


def apply_overrides(data: dict, overrides: dict[str, Any], source: str = "") -> dict:
    """``data`` with each dotted key path of ``overrides`` set (list items by index). A path
    through a missing list item or a plain value raises ``ConfigError`` naming it; a new
    mapping key is set, so validation names it if it is not a key. A key that ``data``'s
    ``sweep:`` block sets in every cell is refused (the sweep would overwrite it)."""
    _refuse_swept(data, overrides, source)
    data = copy.deepcopy(data)
    for path, value in overrides.items():
        keys = path.split(".")
        shown = _shown(keys)
        node: Any = data
        for depth, key in enumerate(keys):
            where = _shown(keys[:depth]) or "the top level"
            if isinstance(node, list):
                if not key.isdigit() or int(key) >= len(node):
                    raise ConfigError(source, shown, f"{where} is a list of {len(node)}: "
                                      f"expected an index from 0 to {len(node) - 1}, got {key!r}")
                key = int(key)
            elif not isinstance(node, dict):
                raise ConfigError(source, shown, f"{where} is a value ({node!r}), not a mapping")
            if depth == len(keys) - 1:
                node[key] = value
            elif isinstance(node, list):
                node = node[key]
            else:
                node = node.setdefault(key, {})
    return data
