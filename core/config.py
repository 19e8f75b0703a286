"""YAML text -> common keys -> the analysis' own schema and checks -> a frozen Experiment.

Every error is a :class:`core.errors.ConfigError` naming the file, the key path and what was
expected, raised before any work starts. The common keys are declared here; everything else
belongs to the analysis (``ANALYSES[name].SCHEMA`` and ``.prepare``).
"""

from __future__ import annotations

import copy
import hashlib
import json
import re
from typing import Any

import yaml

from core import registry
from core.analyses import ANALYSES
from core.errors import ConfigError
from core.schema import Experiment, integer, list_of, mapping, model_block, number, text, validate

TOLERANCE: dict = {
    "rtol": (number(minimum=0.0), 0.0),
    "atol": (number(minimum=0.0), 0.0),
    "se": (number(positive=True), None),
    "se_column": (text(), None),
    "binomial": (number(positive=True), None),
    "trials": (list_of(text()), None),
    "skip": (text(), None),
}
"""How ``estim check`` compares one column (see :func:`core.io.compare_tables`)."""

COMMON: dict = {
    "name": (text(), None),
    "title": (text(), ""),
    "analysis": (text(ANALYSES), "estimation"),
    "reproduces": (list_of(text()), []),
    "model": (model_block(registry.MODELS)[0], None),
    "monte_carlo": ({
        "runs": (integer(1), 1),
        "seed": (integer(0), 0),
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


def load_yaml(text_: str, source: str) -> dict:
    try:
        data = yaml.safe_load(text_)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else ""
        raise ConfigError(source, where, f"not valid YAML ({getattr(exc, 'problem', exc)})") \
            from None
    if data is None:
        raise ConfigError(source, "", "the file is empty")
    if not isinstance(data, dict):
        raise ConfigError(source, "", f"expected a mapping, got {type(data).__name__}")
    return data


def parse(text_: str, source: str, default_name: str) -> Experiment:
    """Validate YAML ``text_`` read from ``source`` (a path shown in messages)."""
    return parse_data(load_yaml(text_, source), source, default_name)


def parse_data(data: dict, source: str, default_name: str) -> Experiment:
    """Validate an already loaded config mapping."""
    data = copy.deepcopy(data)
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
    plan = ANALYSES[analysis].prepare(spec, source)
    tolerances = spec["check"]["tolerances"]
    for column, tol in tolerances.items():
        tolerances[column] = validate(tol, TOLERANCE, source, f"check.tolerances.{column}")
    return Experiment(name=spec["name"], source=source, spec=spec, plan=plan)


def apply_overrides(data: dict, overrides: dict[str, Any]) -> dict:
    """``data`` with each dotted key path of ``overrides`` set (list items by index)."""
    data = copy.deepcopy(data)
    for path, value in overrides.items():
        *parents, last = path.split(".")
        node = data
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
        if isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value
    return data
