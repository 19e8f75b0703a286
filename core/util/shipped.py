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


def find_beside(name: str, source: str, shipped: str = "configs") -> Path | None:
    """The file ``name`` as given (absolute); else relative to the config ``source``'s folder,
    a folder above it or the working folder; else in the shipped folder ``shipped`` (the
    data of a shipped config, found wherever the config was copied)."""
    p = Path(name)
    if p.is_absolute():
        return p if p.is_file() else None
    here = Path(source).resolve().parent
    for folder in (here, *here.parents, Path.cwd(), shipped_folder(shipped)):
        if (folder / p).is_file():
            return folder / p
    return None
