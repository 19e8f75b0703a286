"""Config text read as YAML, safely and within bounds: YAML 1.2 floats (``1e-6``), no
duplicate keys, merge keys, and limits on aliases, depth and the number of values."""

from __future__ import annotations

import re
import stat
from pathlib import Path
from typing import Any

import yaml

from estim.errors import ConfigError

MAX_ALIASES = 64


MAX_DEPTH = 32


MAX_VALUES = 100_000
"""Bounds on a YAML config: anchors/aliases, nesting depth, values after alias expansion."""


class _UniqueKeys:
    """A constructor mix-in that refuses a mapping with a duplicate key."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":      # `<<: *base`: merged below,
                continue                                      # its keys yield to explicit ones
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:
                raise Refused(key_node.start_mark, "a key that is not a plain value") from None
            if duplicate:
                raise Refused(key_node.start_mark, f"duplicate key {key!r}")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


class ConfigLoader(_UniqueKeys, yaml.SafeLoader):
    """PyYAML's safe loader that refuses duplicate keys and bounds aliases and depth."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._aliases = 0
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise Refused(self.peek_event().start_mark,
                               f"more than {MAX_ALIASES} YAML aliases")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise Refused(self.peek_event().start_mark,
                               f"nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


YAML12_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")
"""YAML 1.2 floats without a dot (1e-6, 2E3), which YAML 1.1 reads as text."""
ConfigLoader.add_implicit_resolver("tag:yaml.org,2002:float", YAML12_FLOAT,
                                   list("-+.0123456789"))


class FastConfigLoader(_UniqueKeys, getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """The same reading through libyaml's parser (PyYAML's C extension), several times
    faster: the constructor and the resolver are :class:`ConfigLoader`'s (duplicate keys
    refused, YAML 1.2 floats), but the C composer neither counts aliases nor bounds the
    depth, so :func:`load_yaml` takes it only for a text that :func:`_plain` shows has
    neither."""


FastConfigLoader.add_implicit_resolver("tag:yaml.org,2002:float", YAML12_FLOAT,
                                       list("-+.0123456789"))


def _plain(text_: str) -> bool:
    """Whether ``text_`` surely has no YAML alias or anchor and nests less than
    ``MAX_DEPTH`` levels: no ``&``, ``*`` or tab anywhere, every flow collection closed on its
    own line, and on every line the indentation plus the brackets open at once below
    ``MAX_DEPTH`` (on a line with quotes every opening bracket counts, so a bracket inside
    quotes can only send a text to the slower reader)."""
    if "&" in text_ or "*" in text_ or "\t" in text_:
        return False
    for line in text_.splitlines():
        indent = len(line) - len(line.lstrip(" "))
        depth = deepest = 0
        for ch in line:
            if ch in "[{":
                depth += 1
                deepest = max(deepest, depth)
            elif ch in "]}":
                depth -= 1
        if "'" in line or '"' in line:
            deepest = line.count("[") + line.count("{")
        elif depth != 0:
            return False
        if indent + deepest >= MAX_DEPTH:
            return False
    return True


class Refused(Exception):
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
        loader = FastConfigLoader if hasattr(yaml, "CSafeLoader") and _plain(text_) \
            else ConfigLoader
        data = yaml.load(text_, Loader=loader)  # noqa: S506 - SafeLoader subclasses
    except Refused as exc:
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


MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read."""


def read_config(path: Path) -> str:
    """The text of the config file ``path``: a regular file of at most
    :data:`MAX_CONFIG_BYTES` of UTF-8, every problem a one-line :class:`ConfigError`."""
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(str(path), "", "not a regular file")
        if info.st_size > MAX_CONFIG_BYTES:
            raise ConfigError(str(path), "", f"larger than {MAX_CONFIG_BYTES // 1024} KiB")
        with path.open("rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(str(path), "", "no such file") from None
    except OSError as exc:
        raise ConfigError(str(path), "", f"cannot read ({exc.strerror or exc})") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(str(path), "", f"larger than {MAX_CONFIG_BYTES // 1024} KiB")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(str(path), "", "not a UTF-8 text file") from None
