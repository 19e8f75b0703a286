"""YAML experiment configs -> a validated, frozen :class:`Experiment`.

Every error names the file, the key path and what was expected, and is raised before any
work starts. The schemas below (one per analysis) are the single description of what a
config may contain.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from dataclasses import dataclass
from typing import Any

import yaml

from core import registry, tables
from core.models.base import ParameterError


class ConfigError(ValueError):
    """A config is malformed; the message is one line for the user."""

    def __init__(self, source: str, path: str, message: str) -> None:
        self.source, self.path, self.message = source, path, message
        where = f"{source}: {path}: " if path else f"{source}: "
        super().__init__(where + message)


def _num(positive: bool = False, minimum: float | None = None, below: float | None = None):
    def check(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return "a finite number"
        if positive and not v > 0:
            return "a positive number"
        if minimum is not None and v < minimum:
            return f"a number >= {minimum}"
        if below is not None and not v < below:
            return f"a number < {below}"
        return None
    return check


def _file_name(v):
    """Names that become files or folders: no path separators, not only dots."""
    if not isinstance(v, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", v) or v.strip(".") == "":
        return "letters, digits, '_', '-' or '.' only (it names a file)"
    return None


def _int(minimum: int = 1):
    def check(v):
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            return f"an integer >= {minimum}"
        return None
    return check


def _str(choices=None):
    def check(v):
        if not isinstance(v, str) or not v:
            return "a non-empty string"
        if choices is not None and v not in choices:
            return f"one of {sorted(choices)}"
        return None
    return check


def _mapping(v):
    return None if isinstance(v, dict) else "a mapping"


def _list(item, nonempty: bool = True):
    return ("list", item, nonempty)


REQUIRED = object()

FIGURE_KINDS = ("noiseless", "noisy", "rmse", "residual")

_SIMULATION = ({
    "solver": (_str({"batched_radau", "scipy"}), "batched_radau"),
    "rtol": (_num(positive=True, below=0.1), 1e-6),
    "atol": (_num(positive=True), 1e-7),
}, {})

_CHECK = ({
    "tolerances": (_mapping, {}),
}, {})

_MODEL = ({
    "name": (_str(registry.MODELS), REQUIRED),
    "variant": (_str(), None),
    "params": (_mapping, {}),
}, REQUIRED)

# key -> (check or nested schema or list spec, default). REQUIRED marks mandatory keys.
ESTIMATION_SCHEMA: dict[str, Any] = {
    "name": (_str(), None),
    "title": (_str(), ""),
    "analysis": (_str(registry.ANALYSES), "estimation"),
    "reproduces": (_list(_str()), REQUIRED),
    "model": _MODEL,
    "input": ({
        "waveform": (_str({"sine"}), "sine"),
        "amplitude_v": (_num(minimum=0.0), REQUIRED),
        "frequencies_hz": (_list(_num(positive=True)), REQUIRED),
        "samples_per_period": (_int(2), 10),
        "sample_time_s": (_num(positive=True), None),
        "periods": (_int(1), None),
        "duration_s": (_num(positive=True), None),
        "bias_v": (_list(_num()), [0.0]),
        "mix": (_list(_num()), [1.0]),
    }, REQUIRED),
    "noise": ({
        "input_levels": (_list(_num(positive=True)), REQUIRED),
        "readings": (_list(_str({"sigma", "variance"})), ["sigma"]),
        "measurement_sigma": (_num(minimum=0.0), REQUIRED),
        "filters_see": (_str({"nominal", "noisy"}), "nominal"),
        "pairs": (lambda v: None if isinstance(v, bool) else "true or false", False),
    }, REQUIRED),
    "simulation": _SIMULATION,
    "estimators": (_list({
        "label": (_str(), REQUIRED),
        "type": (_str(registry.ESTIMATORS), REQUIRED),
        "model_params": (_mapping, {}),
        "settings": (_mapping, {}),
    }), REQUIRED),
    "monte_carlo": ({
        "runs": (_int(1), REQUIRED),
        "seed": (_int(0), REQUIRED),
    }, REQUIRED),
    "tables": ({
        "rmse": (_str(), None),
        "residual": (_str(), None),
    }, REQUIRED),
    "figures": ({
        "frequency_hz": (_num(positive=True), None),
        "noise_level": (_num(positive=True), None),
        "reading": (_str({"sigma", "variance"}), None),
        "names": (_mapping, {}),
        "extra_noisy": (_list({
            "noise_level": (_num(positive=True), REQUIRED),
            "reading": (_str({"sigma", "variance"}), "sigma"),
            "name": (_file_name, REQUIRED),
        }, nonempty=False), []),
    }, {}),
    "check": _CHECK,
}

PERTURBATION_SCHEMA: dict[str, Any] = {
    "name": (_str(), None),
    "title": (_str(), ""),
    "analysis": (_str(registry.ANALYSES), REQUIRED),
    "reproduces": (_list(_str()), REQUIRED),
    "model": _MODEL,
    "excitation": ({
        "waveform": (_str({"sine", "step"}), REQUIRED),
        "bias_v": (_list(_num()), REQUIRED),
        "mix": (_list(_num()), REQUIRED),
        "samples_per_period": (_int(8), 200),
        "samples": (_int(8), 2000),
    }, REQUIRED),
    "rows": (_list({
        "s_no": (_int(1), REQUIRED),
        "amplitude_v": (_num(positive=True), REQUIRED),
        "frequency_hz": (_num(positive=True), None),
        "duration_s": (_num(positive=True), None),
        "params": (_mapping, {}),
    }), REQUIRED),
    "simulation": ({
        "solver": (_str({"batched_radau", "scipy"}), "batched_radau"),
        "rtol": (_num(positive=True, below=0.1), 1e-8),
        "atol": (_num(positive=True), 1e-10),
    }, {}),
    "tables": ({
        "distortion": (_str(), REQUIRED),
    }, REQUIRED),
    "figures": ({
        "row": (_int(1), None),
        "name": (_file_name, "perturbation"),
    }, {}),
    "check": _CHECK,
}

SCHEMAS = {"estimation": ESTIMATION_SCHEMA, "perturbation": PERTURBATION_SCHEMA}


def _validate(value: Any, spec: Any, source: str, path: str) -> Any:
    if isinstance(spec, dict):
        if not isinstance(value, dict):
            raise ConfigError(source, path, f"expected a mapping, got {type(value).__name__}")
        unknown = sorted(set(value) - set(spec))
        if unknown:
            key = f"{path}.{unknown[0]}" if path else str(unknown[0])
            raise ConfigError(source, key, f"unknown key; expected one of {sorted(spec)}")
        out = {}
        for key, (sub, default) in spec.items():
            sub_path = f"{path}.{key}" if path else key
            if key not in value or value[key] is None:
                if default is REQUIRED:
                    raise ConfigError(source, sub_path, "missing required key")
                out[key] = _validate(default, sub, source, sub_path) if isinstance(
                    sub, dict) else default
                continue
            out[key] = _validate(value[key], sub, source, sub_path)
        return out
    if isinstance(spec, tuple) and spec[0] == "list":
        _, item, nonempty = spec
        if not isinstance(value, list):
            raise ConfigError(source, path, f"expected a list, got {type(value).__name__}")
        if nonempty and not value:
            raise ConfigError(source, path, "expected a non-empty list")
        return [_validate(v, item, source, f"{path}[{i}]") for i, v in enumerate(value)]
    problem = spec(value)
    if problem:
        raise ConfigError(source, path, f"expected {problem}, got {value!r}")
    return value


def _check_model_params(model_cls, variant, params: dict, source: str, path: str) -> None:
    fields = {f.name: f for f in dataclasses.fields(model_cls.Params)}
    for key, value in params.items():
        if key not in fields:
            raise ConfigError(source, f"{path}.{key}",
                              f"unknown parameter of {model_cls.name}; expected one of "
                              f"{sorted(fields)}")
        expected = type(fields[key].default)
        if expected is float and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ConfigError(source, f"{path}.{key}", f"expected a number, got {value!r}")
        if expected is str and not isinstance(value, str):
            raise ConfigError(source, f"{path}.{key}", f"expected a string, got {value!r}")
    try:
        model_cls(variant, **params)
    except (ParameterError, ValueError, TypeError) as exc:
        raise ConfigError(source, path, str(exc)) from None


def _check_settings(est_cls, settings: dict, model, source: str, path: str) -> None:
    signature = inspect.signature(est_cls.__init__)
    allowed = [p for p in signature.parameters if p != "self"]
    for key in settings:
        if key not in allowed:
            raise ConfigError(source, f"{path}.{key}",
                              f"unknown setting; expected one of {sorted(allowed)}")
    missing = [p.name for p in signature.parameters.values()
               if p.name != "self" and p.default is inspect.Parameter.empty
               and p.name not in settings]
    if missing:
        raise ConfigError(source, f"{path}.{missing[0]}", "missing required setting")
    try:
        est_cls(**settings).validate(model)
    except (ValueError, TypeError) as exc:
        raise ConfigError(source, path, str(exc)) from None


def _check_estimation(spec: dict, model_cls, variant, source: str) -> None:
    inp, noise = spec["input"], spec["noise"]
    if (inp["periods"] is None) == (inp["duration_s"] is None):
        raise ConfigError(source, "input.periods",
                          "give exactly one of input.periods and input.duration_s")
    for key in ("bias_v", "mix"):
        if len(inp[key]) != len(model_cls.input_names):
            raise ConfigError(source, f"input.{key}",
                              f"expected {len(model_cls.input_names)} values, one per model "
                              f"input {list(model_cls.input_names)}")
    if noise["pairs"] and len(noise["input_levels"]) != len(inp["frequencies_hz"]):
        raise ConfigError(source, "noise.pairs", "with pairs: true, noise.input_levels and "
                          "input.frequencies_hz must have the same length")
    labels = set()
    for i, est in enumerate(spec["estimators"]):
        path = f"estimators[{i}]"
        if est["label"] in labels:
            raise ConfigError(source, f"{path}.label", f"duplicate label {est['label']!r}")
        labels.add(est["label"])
        params = {**spec["model"]["params"], **est["model_params"]}
        _check_model_params(model_cls, variant, params, source, f"{path}.model_params")
        _check_settings(registry.ESTIMATORS[est["type"]], est["settings"],
                        model_cls(variant, **params), source, f"{path}.settings")
    for metric, table_id in spec["tables"].items():
        if table_id is not None and not tables.has_thesis_table(table_id):
            raise ConfigError(source, f"tables.{metric}",
                              f"no thesis Table {table_id} ships with estim")
    for kind, name in spec["figures"]["names"].items():
        if kind not in FIGURE_KINDS:
            raise ConfigError(source, f"figures.names.{kind}",
                              f"unknown figure kind; expected one of {list(FIGURE_KINDS)}")
        _validate(name, _file_name, source, f"figures.names.{kind}")


def _check_perturbation(spec: dict, model_cls, variant, source: str) -> None:
    exc = spec["excitation"]
    for key in ("bias_v", "mix"):
        if len(exc[key]) != len(model_cls.input_names):
            raise ConfigError(source, f"excitation.{key}",
                              f"expected {len(model_cls.input_names)} values, one per model "
                              f"input {list(model_cls.input_names)}")
    if not any(exc["mix"]):
        raise ConfigError(source, "excitation.mix", "expected at least one non-zero entry")
    needed, unused = ("frequency_hz", "duration_s") if exc["waveform"] == "sine" else (
        "duration_s", "frequency_hz")
    seen = set()
    for i, row in enumerate(spec["rows"]):
        path = f"rows[{i}]"
        if row[needed] is None:
            raise ConfigError(source, f"{path}.{needed}",
                              f"missing required key (excitation.waveform is {exc['waveform']})")
        if row[unused] is not None:
            raise ConfigError(source, f"{path}.{unused}",
                              f"not used with excitation.waveform {exc['waveform']}; remove it")
        if row["s_no"] in seen:
            raise ConfigError(source, f"{path}.s_no", f"duplicate row number {row['s_no']}")
        seen.add(row["s_no"])
        params = {**spec["model"]["params"], **row["params"]}
        _check_model_params(model_cls, variant, params, source, f"{path}.params")
    table_id = spec["tables"]["distortion"]
    if not tables.has_thesis_table(table_id):
        raise ConfigError(source, "tables.distortion",
                          f"no thesis Table {table_id} ships with estim")
    row = spec["figures"]["row"]
    if row is not None and row not in seen:
        raise ConfigError(source, "figures.row",
                          f"expected the s_no of a row ({sorted(seen)}), got {row}")


@dataclass(frozen=True)
class Experiment:
    """A validated experiment: ``spec`` is the resolved config with every default filled."""

    name: str
    source: str
    spec: dict

    def __hash__(self) -> int:
        return hash((self.name, self.source))


def parse(text: str, source: str, default_name: str) -> Experiment:
    """Validate YAML ``text`` read from ``source`` (a path shown in messages)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else ""
        raise ConfigError(source, where, f"not valid YAML ({getattr(exc, 'problem', exc)})") \
            from None
    if data is None:
        raise ConfigError(source, "", "the file is empty")
    if not isinstance(data, dict):
        raise ConfigError(source, "", f"expected a mapping, got {type(data).__name__}")
    analysis = data.get("analysis") or "estimation"
    _validate(analysis, _str(registry.ANALYSES), source, "analysis")
    spec = _validate(data, SCHEMAS[analysis], source, "")
    spec["name"] = spec["name"] or default_name
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", spec["name"]) or spec["name"].strip(".") == "":
        raise ConfigError(source, "name", "expected letters, digits, '_', '-' or '.' only "
                          f"(it names the results folder), got {spec['name']!r}")
    model_cls = registry.MODELS[spec["model"]["name"]]
    variant = spec["model"]["variant"]
    if model_cls.variants and variant is not None and variant not in model_cls.variants:
        raise ConfigError(source, "model.variant",
                          f"expected one of {sorted(model_cls.variants)}, got {variant!r}")
    _check_model_params(model_cls, variant, spec["model"]["params"], source, "model.params")
    if spec["analysis"] == "estimation":
        _check_estimation(spec, model_cls, variant, source)
    else:
        _check_perturbation(spec, model_cls, variant, source)
    tolerances = spec["check"]["tolerances"]
    for column, tol in tolerances.items():
        tolerances[column] = _validate(
            tol, {"rtol": (_num(minimum=0.0), 0.0), "atol": (_num(minimum=0.0), 0.0)},
            source, f"check.tolerances.{column}")
    return Experiment(name=spec["name"], source=source, spec=spec)
