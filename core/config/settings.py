"""A setting is declared once: a field of a frozen dataclass with its type, check, default,
unit and one-line doc. Every config block, estimator and model declares its settings this
way. From that one declaration come

* the schema that validates a config (:meth:`Settings.schema`, checked by :func:`validate`,
  whose errors name the file and the key path);
* the defaults, filled into the resolved config that the manifest records;
* the typed object the code uses (:meth:`Settings.build`);
* the listing of ``estim settings`` and docs/settings.md (:func:`describe`).

``setting(default, check, unit=..., doc=...)`` declares a value (``REQUIRED`` as default for a
mandatory one); ``block(Cls)`` a nested block of settings; ``blocks(Cls)`` a list of them.
Settings constructed directly (in a notebook) are checked too, in ``__post_init__``.

The checks a declaration names are the small factories below (:func:`number`,
:func:`integer`, :func:`text`, :func:`list_of`, ...): each returns ``None`` for a good value
or what was expected. A schema is a mapping ``key -> (spec, default)`` where ``spec`` is a
check, a nested schema or a :func:`list_of` spec; every error is a :class:`ConfigError`
naming the file and the key path.
"""
from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import re
import reprlib
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from estim.errors import ConfigError, ConfigErrors, SettingError

REQUIRED = object()


PARAM_RANGE = 1e6
"""A model parameter may be at most this many times its default in magnitude (a parameter
with default 0 at most ``MAX_VOLTS``): beyond, no circuit the models describe exists."""


MAX_VOLTS = 1e3
"""Bound on every voltage and noise level of a config: far above any circuit here, far below
what overflows the device laws."""


def parameter_problem(default: Any, value: Any) -> str | None:
    """What is wrong with ``value`` for a model parameter whose default is ``default`` (None
    when nothing): a float parameter is a finite number within :data:`PARAM_RANGE` times its
    default (:data:`MAX_VOLTS` for a default of 0), a text parameter text. One check for a
    config's ``model.params`` and a model made in code."""
    if isinstance(value, np.generic):
        value = value.item()
    if type(default) is float:
        limit = PARAM_RANGE * abs(default) if default else MAX_VOLTS
        problem = number(minimum=-limit, maximum=limit)(value)
        if problem:
            return (f"expected {problem} (at most {PARAM_RANGE:g} times the default "
                    f"{default:g}), got {shown(value)}")
    if type(default) is str and not isinstance(value, str):
        return f"expected a string, got {shown(value)}"
    return None


MIN_NOISE = 1e-12
"""The smallest measurement noise level (a standard deviation) a config accepts: with none,
every ratio to the raw measurement is infinite and a filter's ``R`` is singular (a level whose
square underflows is the same); 1e-12 is far below any level of the thesis or a circuit."""


def number(positive: bool = False, minimum: float | None = None, below: float | None = None,
           maximum: float | None = None):
    """A finite number (not a boolean), optionally positive, ``>= minimum``, ``< below``,
    ``<= maximum``."""
    def check(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return "a finite number"
        if positive and not v > 0:
            return "a positive number"
        if minimum is not None and v < minimum:
            return f"a number >= {minimum:g}"
        if below is not None and not v < below:
            return f"a number < {below:g}"
        if maximum is not None and v > maximum:
            return f"a number <= {maximum:g}"
        return None
    return check


def integer(minimum: int = 1, maximum: int = 10**9):
    def check(v):
        if isinstance(v, bool) or not isinstance(v, int) or not minimum <= v <= maximum:
            return f"an integer from {minimum} to {maximum}"
        return None
    return check


_SHOWN = reprlib.Repr()


_SHOWN.maxstring, _SHOWN.maxother, _SHOWN.maxlist, _SHOWN.maxdict = 80, 80, 8, 8


_SHOWN.maxlevel = 3


def shown(value) -> str:
    """A bounded ``repr`` of a value from the user's input, for a message: a long string or
    an alias-expanded structure is quoted as an excerpt, without building its whole repr."""
    return _SHOWN.repr(value)


def text(choices=None, max_length: int = 200):
    """A non-empty string of at most ``max_length`` characters, optionally one of
    ``choices``."""
    def check(v):
        if not isinstance(v, str) or not v:
            return "a non-empty string"
        if len(v) > max_length:
            return f"a string of at most {max_length} characters"
        if choices is not None and v not in choices:
            return f"one of {sorted(choices)}{did_you_mean(v, choices)}"
        return None
    return check


def did_you_mean(word: str, choices) -> str:
    """``"; did you mean 'x'?"`` for the nearest of ``choices`` to a misspelled ``word``."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def boolean(v):
    return None if isinstance(v, bool) else "true or false"


def mapping(v):
    return None if isinstance(v, dict) else "a mapping"


MAX_NAME = 100


def file_name(v):
    """Names that become files or folders: no path separators, not only dots, bounded."""
    if not isinstance(v, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", v) or v.strip(".") == "" \
            or len(v) > MAX_NAME:
        return (f"letters, digits, '_', '-' or '.' only, at most {MAX_NAME} characters "
                "(it names a file)")
    return None


def matrix(v):
    """A covariance or system matrix: a number, a list of numbers (the diagonal) or a list of
    rows, all finite, at most 64 x 64."""
    ok = number()
    if ok(v) is None:
        return None
    if isinstance(v, list) and 0 < len(v) <= 64:
        if all(ok(x) is None for x in v):
            return None
        if all(isinstance(r, list) and len(r) == len(v[0]) and 0 < len(r) <= 64
               and all(ok(x) is None for x in r) for r in v):
            return None
    return "a finite number, a list of finite numbers or a list of equal-length rows"


def covariance(definite: bool = False, by_name: bool = False):
    """A :func:`matrix` that is a covariance: symmetric and positive semidefinite (positive
    definite with ``definite``): a number ``>= 0`` (``> 0``), a diagonal of such numbers, or
    a symmetric matrix whose smallest eigenvalue is so (to rounding); with ``by_name`` also
    ``{state name: variance}`` (the filter checks the names against its model)."""
    kind = "positive definite" if definite else "positive semidefinite"

    def check(v):
        if by_name and isinstance(v, dict):
            ok = 0 < len(v) <= 256 and all(isinstance(k, str) and number(minimum=0.0)(x) is None
                                           for k, x in v.items())
            return None if ok else "a mapping of state names to variances (numbers >= 0)"
        problem = matrix(v)
        if problem:
            return problem
        a = np.asarray(v, float)
        if a.ndim == 2 and (a.shape[0] != a.shape[1] or not np.allclose(a, a.T, rtol=1e-12,
                                                                         atol=0.0)):
            return f"a symmetric {kind} matrix"
        lowest = float(np.min(a) if a.ndim < 2 else np.linalg.eigvalsh(a)[0])
        scale = float(np.max(np.abs(a), initial=0.0))
        if lowest < -1e-12 * scale or (definite and not lowest > 0):
            return f"a {kind} covariance (" + ("a number > 0" if definite else
                                              "a number >= 0") + " or such a matrix)"
        return None
    return check


def vector(max_length: int = 256):
    """A number (every entry alike) or a list of at most ``max_length`` finite numbers."""
    ok = number()

    def check(v):
        if ok(v) is None:
            return None
        if isinstance(v, list) and 0 < len(v) <= max_length and all(ok(x) is None for x in v):
            return None
        return f"a finite number or a list of at most {max_length} finite numbers"
    return check


def list_of(item, nonempty: bool = True, max_length: int = 100, unique: bool = False):
    """A list of ``item``; at most ``max_length`` entries; with ``unique``, no repeats."""
    return ("list", item, nonempty, max_length, unique)


def validate(value: Any, spec: Any, source: str, path: str) -> Any:
    """``value`` checked against ``spec``, with every default of a nested schema filled in.

    Every problem is found before raising: one ``ConfigError`` for one, a
    :class:`~estim.errors.ConfigErrors` listing all of them (one per line) for several."""
    errors: list[ConfigError] = []
    out = _validate(value, spec, source, path, errors)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise ConfigErrors(errors)
    return out


def _validate(value: Any, spec: Any, source: str, path: str, errors: list) -> Any:
    try:
        return _check(value, spec, source, path, errors)
    except ConfigError as exc:
        errors.append(exc)
        return None


def _check(value: Any, spec: Any, source: str, path: str, errors: list) -> Any:
    if isinstance(spec, dict):
        if not isinstance(value, dict):
            raise ConfigError(source, path, f"expected a mapping, got {type(value).__name__}")
        odd = [k for k in value if not isinstance(k, str)]
        if odd:
            raise ConfigError(source, path or "(top level)",
                              f"key {odd[0]!r} is not a string; expected one of {sorted(spec)}")
        for name in sorted(k for k in value if k not in spec):
            key = f"{path}.{name}" if path else str(name)
            errors.append(ConfigError(source, key, f"unknown key{did_you_mean(name, spec)}; "
                                      f"expected one of {sorted(spec)}"))
        out = {}
        for key, (sub, default) in spec.items():
            sub_path = f"{path}.{key}" if path else key
            if key not in value or value[key] is None:
                if default is REQUIRED:
                    errors.append(ConfigError(source, sub_path, "missing required key"))
                    continue
                out[key] = _validate(default, sub, source, sub_path, errors) if isinstance(
                    sub, dict) and default is not None else copy.deepcopy(default)  # own copy
                continue
            out[key] = _validate(value[key], sub, source, sub_path, errors)
        return out
    if isinstance(spec, tuple) and spec[0] == "list":
        _, item, nonempty, max_length, unique = spec
        if not isinstance(value, list):
            raise ConfigError(source, path, f"expected a list, got {type(value).__name__}")
        if nonempty and not value:
            raise ConfigError(source, path, "expected a non-empty list")
        if len(value) > max_length:
            raise ConfigError(source, path, f"expected at most {max_length} entries, got "
                              f"{len(value)}")
        before = len(errors)
        out = [_validate(v, item, source, f"{path}[{i}]", errors) for i, v in enumerate(value)]
        if unique and len(errors) == before:
            for i, v in enumerate(out):
                if v in out[:i]:
                    raise ConfigError(source, f"{path}[{i}]", f"repeats {v!r}")
        return out
    problem = spec(value)
    if problem:
        raise ConfigError(source, path, f"expected {problem}, got {shown(value)}")
    return value


# ----- declarations -------------------------------------------------------------------------------

_KIND = "estim_setting"


def setting(default: Any = REQUIRED, check=None, *, unit: str = "", doc: str = "") -> Any:
    """A setting: ``check`` is one of the checks above (``None``: any value); a
    list or mapping default is copied for every instance."""
    metadata = {_KIND: "value", "check": check, "unit": unit, "doc": doc, "default": default}
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: copy.deepcopy(default), metadata=metadata)
    return field(default=default, metadata=metadata)


def block(cls: type, *, required: bool = False, optional: bool = False, doc: str = "") -> Any:
    """A nested block of settings of class ``cls``: filled with its defaults when absent
    (``required``: the config must give it; ``optional``: absent means ``None``)."""
    default = REQUIRED if required else None
    return field(default=default, metadata={_KIND: "block", "cls": cls, "required": required,
                                            "optional": optional, "doc": doc})


def blocks(cls: type, *, default: Any = REQUIRED, max_length: int = 100, nonempty: bool = True,
           doc: str = "") -> Any:
    """A list of blocks of class ``cls`` (``default``: ``REQUIRED`` or a list of mappings)."""
    return field(default=default if default is REQUIRED else tuple(default),
                 metadata={_KIND: "blocks", "cls": cls, "max_length": max_length,
                           "nonempty": nonempty, "doc": doc})


def _declared(cls: type) -> list[dataclasses.Field]:
    return [f for f in fields(cls) if _KIND in f.metadata]


def plain(value: Any) -> Any:
    """A value as a config holds it: arrays and tuples as lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return [plain(v) for v in value]
    if isinstance(value, list):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


class Settings:
    """Mixin of the frozen dataclasses that declare settings (see the module docstring)."""

    @classmethod
    def schema(cls) -> dict:
        """``{key: (check or nested schema, default)}`` for :func:`validate`."""
        out = {}
        for f in _declared(cls):
            kind = f.metadata[_KIND]
            if kind == "value":
                default = f.metadata["default"]
                out[f.name] = (f.metadata["check"] or _anything,
                               copy.deepcopy(default) if isinstance(default, (list, dict))
                               else default)
            elif kind == "block":
                sub = f.metadata["cls"].schema()
                default = REQUIRED if f.metadata["required"] else (
                    None if f.metadata["optional"] else {})
                out[f.name] = (sub, default)
            else:
                item = list_of(f.metadata["cls"].schema(), nonempty=f.metadata["nonempty"],
                               max_length=f.metadata["max_length"])
                default = f.default if f.default is REQUIRED else [dict(d) for d in f.default]
                out[f.name] = (item, default)
        return out

    @classmethod
    def build(cls, spec: dict) -> Settings:
        """The typed settings of a validated mapping (every key present, nested blocks too)."""
        values = {}
        for f in _declared(cls):
            if f.name not in spec:
                continue
            value = spec[f.name]
            kind = f.metadata[_KIND]
            if kind == "block" and value is not None:
                value = f.metadata["cls"].build(value)
            elif kind == "blocks" and value is not None:
                value = tuple(f.metadata["cls"].build(v) for v in value)
            values[f.name] = value
        return cls(**values)

    def to_spec(self) -> dict:
        """The settings as a config mapping: every value, defaults included."""
        out = {}
        for f in _declared(type(self)):
            value = getattr(self, f.name)
            kind = f.metadata[_KIND]
            if kind == "block" and value is not None:
                value = value.to_spec()
            elif kind == "blocks" and value is not None:
                value = [v.to_spec() if isinstance(v, Settings) else plain(v) for v in value]
            else:
                value = plain(value)
            out[f.name] = value
        return out

    def items(self) -> list[tuple[str, Any]]:
        """``(name, value)`` of every declared setting, in the order declared (a block whose
        settings are alike, such as an analysis' ``tables``, read as pairs)."""
        return [(f.name, getattr(self, f.name)) for f in _declared(type(self))]

    def __post_init__(self) -> None:
        """Settings made in code are checked as a config's would be (``ValueError`` naming
        the setting), and nested mappings become their blocks."""
        for f in _declared(type(self)):
            value = getattr(self, f.name)
            kind = f.metadata[_KIND]
            if value is REQUIRED or (value is None and kind == "value"
                                     and f.metadata["default"] is REQUIRED):
                raise TypeError(f"{type(self).__name__}: missing required setting {f.name!r}"
                                + (" (None given)" if value is None else ""))
            if kind == "value":
                check = f.metadata["check"]
                if isinstance(value, (np.ndarray, np.generic)):   # numpy's numbers as plain
                    value = plain(value)
                    object.__setattr__(self, f.name, value)
                if check is not None and value is not None and not _CHECKED.get():
                    _check_value(check, plain(value), f.name)
            elif kind == "block" and isinstance(value, dict):
                object.__setattr__(self, f.name, f.metadata["cls"].build(
                    _with_defaults(f.metadata["cls"], value)))
            elif kind == "blocks" and value is not None:
                object.__setattr__(self, f.name, tuple(
                    f.metadata["cls"].build(_with_defaults(f.metadata["cls"], v))
                    if isinstance(v, dict) else v for v in value))


def _anything(value: Any) -> None:
    return None


_CHECKED: ContextVar[bool] = ContextVar("estim_settings_checked", default=False)
"""Inside :func:`checked`: the values given were validated against these declarations."""


@contextmanager
def checked() -> Iterator[None]:
    """Settings made inside take their values as already validated (by
    :func:`validate` against the same declarations): each value is
    checked once, where a config is read, not again when its object is made."""
    token = _CHECKED.set(True)
    try:
        yield
    finally:
        _CHECKED.reset(token)


def _check_value(check: Any, value: Any, name: str) -> None:
    """:class:`SettingError` (``name: expected ...``) unless ``value`` passes ``check`` (a
    check function or a :func:`list_of` spec)."""
    try:
        validate(value, check, "", name)
    except ConfigErrors as exc:
        first = exc.errors[0]
        raise SettingError(first.path, first.message) from None
    except ConfigError as exc:
        raise SettingError(exc.path, exc.message) from None


def _with_defaults(cls: type, mapping: dict) -> dict:
    return validate(mapping, cls.schema(), "", "")


def _type_name(f: dataclasses.Field) -> str:
    kind = f.metadata[_KIND]
    if kind == "block":
        return "block"
    if kind == "blocks":
        return "list of blocks"
    return str(f.type).replace("typing.", "")


def _shown_default(f: dataclasses.Field) -> str:
    kind = f.metadata[_KIND]
    default = f.metadata["default"] if kind == "value" else f.default
    if default is REQUIRED:
        return "required"
    if kind == "block":
        return "-" if f.metadata["optional"] else "(its defaults)"
    if default is None:
        return "none"
    return repr(plain(default))


def describe(cls: type, prefix: str = "") -> list[tuple[str, str, str, str, str]]:
    """Rows ``(key path, type, default, unit, doc)`` of every setting of ``cls``, nested
    blocks expanded (``key.sub``, list items as ``key[].sub``)."""
    rows = []
    for f in _declared(cls):
        path = f"{prefix}{f.name}"
        rows.append((path, _type_name(f), _shown_default(f), f.metadata.get("unit", ""),
                     f.metadata.get("doc", "")))
        kind = f.metadata[_KIND]
        if kind == "block":
            rows += describe(f.metadata["cls"], f"{path}.")
        elif kind == "blocks":
            rows += describe(f.metadata["cls"], f"{path}[].")
    return rows


def settings_class(cls: type) -> type:
    """``@dataclass(frozen=True, eq=False)`` for a :class:`Settings` subclass."""
    return dataclass(frozen=True, eq=False)(cls)
