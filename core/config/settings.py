"""A setting is declared once: a field of a frozen dataclass with its type, check, default,
unit and one-line doc.

Every config block, estimator and model declares its settings this way. From that one
declaration come

* the schema that validates a config (:meth:`Settings.schema`, checked by
  :func:`estim.config.schema.validate`, whose errors name the file and the key path);
* the defaults, filled into the resolved config that the manifest records;
* the typed object the code uses (:meth:`Settings.build`);
* the listing of ``estim settings`` and docs/settings.md (:func:`describe`).

``setting(default, check, unit=..., doc=...)`` declares a value (``REQUIRED`` as default for a
mandatory one); ``block(Cls)`` a nested block of settings; ``blocks(Cls)`` a list of them.
Settings constructed directly (in a notebook) are checked too, in ``__post_init__``.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from estim.config.schema import REQUIRED, list_of, validate
from estim.errors import ConfigError, ConfigErrors, SettingError

_KIND = "estim_setting"


def setting(default: Any = REQUIRED, check=None, *, unit: str = "", doc: str = "") -> Any:
    """A setting: ``check`` is one of :mod:`estim.config.schema`'s checks (``None``: any value); a
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
        """``{key: (check or nested schema, default)}`` for :func:`estim.config.schema.validate`."""
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
            if value is REQUIRED:
                raise TypeError(f"{type(self).__name__}: missing required setting {f.name!r}")
            if kind == "value":
                check = f.metadata["check"]
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
    :func:`estim.config.schema.validate` against the same declarations): each value is
    checked once, where a config is read, not again when its object is made."""
    token = _CHECKED.set(True)
    try:
        yield
    finally:
        _CHECKED.reset(token)


def _check_value(check: Any, value: Any, name: str) -> None:
    """:class:`SettingError` (``name: expected ...``) unless ``value`` passes ``check`` (a
    check function or a :func:`estim.config.schema.list_of` spec)."""
    try:
        validate(value, check, "", name)
    except ConfigErrors as exc:
        first = exc.errors[0]
        raise SettingError(first.path, first.message) from None
    except ConfigError as exc:
        raise SettingError(exc.path, exc.message) from None


def _with_defaults(cls: type, mapping: dict) -> dict:
    from estim.config.schema import validate

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
