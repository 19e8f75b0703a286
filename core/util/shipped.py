"""Where the data shipped with estim lies: its configs and its netlists."""

from __future__ import annotations

import importlib.util
from pathlib import Path

PACKAGES = {"configs": "estim.cli.configs", "circuits": "estim.circuits"}
"""Each shipped folder of the source tree and the package it installs as."""


def shipped_folder(name: str) -> Path:
    """The shipped folder ``name`` (``"configs"`` or ``"circuits"``): the installed package
    of :data:`PACKAGES`; in an editable install, which maps no such package, the folder of
    that name in the source tree."""
    try:
        spec = importlib.util.find_spec(PACKAGES[name])
    except ModuleNotFoundError:
        spec = None
    if spec is not None and spec.submodule_search_locations:
        return Path(list(spec.submodule_search_locations)[0])
    return Path(__file__).resolve().parents[2] / name
