"""Modules imported on first use, so a command loads only what it runs (``estim validate``
does not import matplotlib, pandas or numba; tests/test_startup.py).

:func:`load` is ``lazy_loader.load`` (the Scientific Python lazy-loading library) that also
binds the module to its parent package, as an ``import`` does: without that,
``import estim.kernels; estim.kernels.X`` fails after another module has registered
``estim.kernels`` lazily."""

from __future__ import annotations

import sys
from types import ModuleType

import lazy_loader


def load(name: str) -> ModuleType:
    """The module ``name``, imported when one of its attributes is first read."""
    module = lazy_loader.load(name, suppress_warning=True)
    parent, _, child = name.rpartition(".")
    if parent and child not in vars(sys.modules[parent]):
        setattr(sys.modules[parent], child, module)
    return module
