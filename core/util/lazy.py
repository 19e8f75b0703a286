"""Modules imported on first use, so a command loads only what it runs (``estim validate``
does not import matplotlib, pandas or numba; tests/test_startup.py).

:func:`load` is ``lazy_loader.load`` (the Scientific Python lazy-loading library) that also
binds the module to its parent package, as an ``import`` does: without that,
``import estim.numerics.kernels; estim.numerics.kernels.X`` fails after another module has
registered
``estim.numerics.kernels`` lazily."""

from __future__ import annotations

import importlib
import sys
from types import ModuleType

import lazy_loader

from estim.util.interrupt import raise_if_interrupted

_registered: list[ModuleType] = []
_eager = False


def load(name: str) -> ModuleType:
    """The module ``name``, imported when one of its attributes is first read (at once after
    :func:`import_all_now`)."""
    if _eager:
        module = importlib.import_module(name)
    else:
        module = lazy_loader.load(name, suppress_warning=True)
        _registered.append(module)
    parent, _, child = name.rpartition(".")
    if parent and child not in vars(sys.modules[parent]):
        setattr(sys.modules[parent], child, module)
    return module


def import_all_now() -> None:
    """Import every module :func:`load` has registered, and from now on import at once.

    Python's lazy modules are not thread-safe before 3.12.3 (cpython gh-114763): two threads
    reading a lazy module's first attribute together can each see it half-imported
    (``ImportError: cannot import name 'scoreatpercentile' from 'scipy.stats'`` with two
    configs at once). So :mod:`estim.engine.scheduler`'s callers import them in their own thread
    before any driver thread starts. A module that cannot be imported is left to fail where
    it is used, as it would have. An interrupt that landed while a module loaded is raised
    here (Python's import statement may have swallowed it, :mod:`estim.util.interrupt`)."""
    global _eager
    _eager = True
    for module in _registered:
        try:
            _ = module.__name__                 # the first read imports it
        except ImportError:
            pass
    raise_if_interrupted()
