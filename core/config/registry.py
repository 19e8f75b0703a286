"""Names used in configs -> implementations, with no hand-kept list.

A model or an estimator registers itself by the class keyword ``name``::

    class DiodeRC(Model, name="diode_rc"): ...
    class IteratedEKF(ExtendedKalmanFilter, name="iekf"): ...

A class in estim's own packages lives in the module of its name (``estim/models/diode_rc.py``
registers ``diode_rc``): the registry lists those names from the package's files and imports a
module only when a config names it, so a command that does not use a model loads none. A
module outside estim registers its classes when imported: a config's ``plugins:`` list does
that (:func:`load_plugins`).

An analysis is a module (or a package) of :mod:`estim.experiments` named as configs name it
(``analysis: estimation`` is ``estim/experiments/estimation/``): :data:`ANALYSES` lists them
from the package's files, so adding one is adding its module.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import pkgutil
import sys
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

NOT_REGISTERED = ("base", "kalman_differentiator", "passive_network",
                  "wavelet_lms_compiled", "ekf_compiled", "kf_compiled", "ukf_compiled",
                  "compiled_steps", "ensemble", "breaks")
"""Modules of the model and estimator packages that hold no registered class: the base
classes, compiled kernels, and the estimators of the papers that their analyses call
directly (they take no config block)."""
PLUGIN_PREFIX = "estim_plugin_"
"""Modules imported from a config's ``plugins:`` are named with this prefix."""

_SCOPE: ContextVar[frozenset[str] | None] = ContextVar("estim_plugin_scope", default=None)
"""Inside :func:`plugin_scope`: the plugin modules whose classes are visible."""


@contextmanager
def plugin_scope(modules: Iterable[str]) -> Iterator[None]:
    """Within the block, a class a plugin registered is visible only if its module is one of
    ``modules`` (the config's own ``plugins:``, as :func:`load_plugins` names them), so a
    config never validates against a plugin another config of the same process loaded.
    Outside any scope (``import estim`` in a notebook) every registered class is visible."""
    token = _SCOPE.set(frozenset(modules))
    try:
        yield
    finally:
        _SCOPE.reset(token)


def _visible(cls: type) -> bool:
    scope = _SCOPE.get()
    return scope is None or not cls.__module__.startswith(PLUGIN_PREFIX) \
        or cls.__module__ in scope


class Registry(Mapping):
    """``{name: class}`` of one kind (models or estimators), filled lazily from ``package``
    and by the classes that register themselves."""

    def __init__(self, package: str, kind: str) -> None:
        self.package, self.kind = package, kind
        self._classes: dict[str, type] = {}

    def register(self, name: str, cls: type) -> None:
        """Register ``cls`` as ``name``. A plugin's class may replace another plugin's (a
        file edited and loaded again), never one of estim's own."""
        known = self._classes.get(name)
        if known is None and not cls.__module__.startswith(PLUGIN_PREFIX) \
                and name in self._builtin() and cls.__module__ != f"{self.package}.{name}":
            importlib.import_module(f"{self.package}.{name}")
            known = self._classes.get(name)
        if known is not None and known is not cls and (
                known.__module__, known.__qualname__) != (cls.__module__, cls.__qualname__) \
                and not known.__module__.startswith(PLUGIN_PREFIX):
            raise ValueError(f"{self.kind} name {name!r} is taken by {known.__module__}."
                             f"{known.__qualname__}")
        self._classes[name] = cls

    def _builtin(self) -> list[str]:
        spec = importlib.util.find_spec(self.package)
        paths = list(spec.submodule_search_locations or []) if spec else []
        return [m.name for m in pkgutil.iter_modules(paths)
                if not m.ispkg and not m.name.startswith("_") and m.name not in NOT_REGISTERED]

    def __getitem__(self, name: str) -> type:
        if name not in self._classes and isinstance(name, str) and name in self._builtin():
            importlib.import_module(f"{self.package}.{name}")
        try:
            cls = self._classes[name]
        except (KeyError, TypeError):
            raise KeyError(name) from None
        if not _visible(cls):
            raise KeyError(name)
        return cls

    def _names(self) -> set[str]:
        return set(self._builtin()) | {name for name, cls in self._classes.items()
                                       if _visible(cls)}

    def __contains__(self, name: object) -> bool:
        if not isinstance(name, str):
            return False
        cls = self._classes.get(name)
        return (cls is not None and _visible(cls)) or name in self._builtin()

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._names()))

    def __len__(self) -> int:
        return len(self._names())


MODELS = Registry("estim.models", "model")
ESTIMATORS = Registry("estim.estimators", "estimator")

NETLIST_MODELS = "estim.spice"
"""The package that builds a model from a config's ``model: {netlist: ...}`` block."""


def resolve_model_block(data: dict, source: str) -> None:
    """Register the model a config's model block builds from a netlist, as ``netlist:<stem>``,
    and name it in the block (:func:`estim.spice.resolve_model_block`, looked up by name as
    every registered implementation is: the config layer sits below the domain)."""
    importlib.import_module(NETLIST_MODELS).resolve_model_block(data, source)


def load_plugins(paths: list[Path]) -> list[str]:
    """Import each Python file of ``paths`` once per content (by its resolved path and its
    bytes: an edited file is imported again), so the models and estimators it defines
    register themselves; the modules' names (for :func:`plugin_scope`). Whatever the import
    raises propagates."""
    names = []
    for path in paths:
        path = Path(path).resolve()
        digest = hashlib.sha256(str(path).encode() + b"\0" + path.read_bytes())
        module = PLUGIN_PREFIX + digest.hexdigest()[:16]
        names.append(module)
        if module in sys.modules:
            continue
        spec = importlib.util.spec_from_file_location(module, path)
        if spec is None or spec.loader is None:
            raise ImportError(f"{path} is not a Python file")
        code = importlib.util.module_from_spec(spec)
        sys.modules[module] = code
        try:
            spec.loader.exec_module(code)
        except BaseException:
            del sys.modules[module]
            raise
    return names


class Analyses(Mapping):
    """Analysis name -> its module (``estim.experiments.<name>``), each imported on first
    access: ``estim validate`` of a perturbation config loads neither the field filter nor
    the image filters. ``base`` (the protocol) and ``shared`` (what several analyses use)
    are not analyses."""

    package = "estim.experiments"
    not_analyses = ("base", "shared")

    def _names(self) -> list[str]:
        spec = importlib.util.find_spec(self.package)
        paths = list(spec.submodule_search_locations or []) if spec else []
        return sorted(m.name for m in pkgutil.iter_modules(paths)
                      if not m.name.startswith("_") and m.name not in self.not_analyses)

    def __getitem__(self, name: str):
        if not isinstance(name, str) or name not in self._names():
            raise KeyError(name)                # a list or mapping from a damaged manifest too
        return importlib.import_module(f"{self.package}.{name}")

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._names()


ANALYSES: Mapping = Analyses()
