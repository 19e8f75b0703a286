"""Models and estimators built from a validated config, each mistake a ``ConfigError`` naming
its key path; every model built is recorded for the manifest."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from estim.config.settings import checked, parameter_problem, shown, validate
from estim.errors import ConfigError, ParameterError, SettingError

_BUILT: ContextVar[dict | None] = ContextVar("estim_models_built", default=None)


@contextmanager
def recording_models() -> Iterator[dict]:
    """Collect every model :func:`build_model` makes inside: ``{key path: {"name", "variant",
    "params"}}`` with every parameter resolved (defaults and the variant's values), for the
    manifest."""
    token = _BUILT.set({})
    try:
        yield _BUILT.get()
    finally:
        _BUILT.reset(token)


def build_model(model_cls, variant, params: dict, source: str, path: str):
    """``model_cls(variant, **params)``, with each bad parameter named at ``path``; recorded
    with every resolved parameter where :func:`recording_models` listens."""
    fields = {f.name: f for f in dataclasses.fields(model_cls.Params)}
    for key, value in params.items():
        if key not in fields:
            where = (" (a netlist model's parameters are its .param names)"
                     if getattr(model_cls, "from_netlist", False) else "")
            raise ConfigError(source, f"{path}.{key}",
                              f"unknown parameter of {model_cls.name}; expected one of "
                              f"{sorted(fields)}{where}")
        problem = parameter_problem(fields[key].default, value)
        if problem:
            raise ConfigError(source, f"{path}.{key}", problem)
    try:
        model = model_cls(variant, **params)
    except (ParameterError, ValueError, TypeError) as exc:
        raise ConfigError(source, path, str(exc)) from None
    built = _BUILT.get()
    if built is not None:
        entry = {"name": model_cls.name, "variant": model.variant,
                 "params": dataclasses.asdict(model.params)}
        key, n = path, 1
        while key in built and built[key] != entry:      # the same path, another model
            n += 1
            key = f"{path} ({n})"
        built[key] = entry
    return model


def operating_point(model, bias, source: str, path: str):
    """The DC operating point of ``model`` with its sources held at ``bias``; a model whose
    parameters give none is a config error at ``path``."""
    held = np.broadcast_to(np.asarray(bias, float), (1, 2, model.n_inputs))
    try:
        with np.errstate(all="ignore"):
            x = model.operating_point(u=model.source_to_input(held, 1.0)[0, 0])
    except (RuntimeError, ValueError, ArithmeticError) as exc:
        message = str(exc).splitlines()[0]
        if not message.startswith(f"{model.name}:"):
            message = f"{model.name}: {message}"
        raise ConfigError(source, path, message) from None
    if not np.all(np.isfinite(x)):
        raise ConfigError(source, path, f"{model.name}: no finite DC operating point")
    return x


def build_estimator(est_cls, settings: dict, model, source: str, path: str):
    """``est_cls`` with ``settings`` checked against its declared settings
    (:mod:`estim.config.settings`: every default filled in) and against ``model``; a problem is a
    ``ConfigError`` at the setting's key path (``estimators[0].settings.Q``)."""
    values = validate(settings, est_cls.schema(), source, path)
    try:
        with checked():
            est = est_cls(**values)
        est.validate(model)
    except SettingError as exc:                         # "Q: not symmetric" -> settings.Q
        where = f"{path}.{exc.key}" if exc.key.split(".")[0].split("[")[0] in values else path
        raise ConfigError(source, where, exc.reason) from None
    except (ValueError, TypeError, OverflowError) as exc:
        raise ConfigError(source, path, str(exc)) from None
    return est


def check_interval(values: list, source: str, path: str) -> None:
    """A ``[low, high]`` pair with ``low < high``."""
    if len(values) != 2 or not values[0] < values[1]:
        raise ConfigError(source, path,
                          f"expected [low, high] with low < high, got {shown(values)}")


def check_input_vector(values: list, model_cls, source: str, path: str) -> None:
    """One value per model input."""
    if len(values) != len(model_cls.input_names):
        raise ConfigError(source, path, f"expected {len(model_cls.input_names)} values, one per "
                          f"model input {list(model_cls.input_names)}")
