"""Config validation: checks of single values and nested schemas (the Experiment a config
becomes is in :mod:`.experiment`, the models and estimators built from it in :mod:`.builders`).

A schema is a mapping ``key -> (spec, default)`` where ``spec`` is a check function (returns
``None`` or what was expected), a nested schema, or :func:`list_of` an item spec; ``REQUIRED``
as default marks a mandatory key. Every error is a :class:`ConfigError` naming the file and
the key path. Each analysis module declares its own schema with these pieces.
"""

from __future__ import annotations

import difflib
import math
import re
import reprlib
from typing import Any

from estim.errors import ConfigError, ConfigErrors

REQUIRED = object()


PARAM_RANGE = 1e6
"""A model parameter may be at most this many times its default in magnitude (a parameter
with default 0 at most ``MAX_VOLTS``): beyond, no circuit the models describe exists."""


MAX_VOLTS = 1e3
"""Bound on every voltage and noise level of a config: far above any circuit here, far below
what overflows the device laws."""


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
                    sub, dict) and default is not None else default
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
