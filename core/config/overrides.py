"""Overrides: ``key.path=value`` from a command line or :func:`estim.run`'s keywords, set
into a config mapping before it is validated."""

from __future__ import annotations

import copy
import re
from typing import Any

import yaml

from estim.config.yaml_reader import ConfigLoader, Refused
from estim.errors import ConfigError, UsageError

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
        parsed = yaml.load(value, Loader=ConfigLoader) if value.strip() else ""  # noqa: S506
    except (yaml.YAMLError, Refused) as exc:
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
    sweep = overrides.get("sweep")                  # a sweep given on the command line too
    if not isinstance(sweep, dict):
        sweep = data.get("sweep") if isinstance(data, dict) else None
    if not isinstance(sweep, dict):
        return
    for key in sweep:
        swept = key_path(str(key))
        for given in overrides:
            if given == "sweep":
                continue
            if given == swept or swept.startswith(given + ".") or given.startswith(swept + "."):
                where = "sweep=... given here" if "sweep" in overrides else \
                    "the config's sweep block"
                raise ConfigError(source, given, f"{where} sets {key} in every cell; give "
                                  f"the whole block instead, e.g. 'sweep={{{key}: [...]}}'")


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
