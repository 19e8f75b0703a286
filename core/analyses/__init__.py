"""The registered analyses: one line each (see :mod:`estim.analyses.base` for the protocol).

An analysis module is imported when a config first names it: ``estim validate`` of a
perturbation config does not load the field filter, the image filters or numba's kernels
that other analyses use.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from types import ModuleType

_MODULES = {
    "burden": "estim.analyses.burden",
    "differentiator": "estim.analyses.differentiator",
    "dipole": "estim.analyses.dipole",
    "dipole_field": "estim.analyses.dipole_field",
    "estimation": "estim.analyses.estimation",
    "field_study": "estim.analyses.field_study",
    "image_kalman": "estim.analyses.image_kalman",
    "kalman_derivative": "estim.analyses.kalman_derivative",
    "kronecker": "estim.analyses.kronecker",
    "passive_network": "estim.analyses.passive_network",
    "perturbation": "estim.analyses.perturbation",
}


class _Analyses(Mapping):
    """Analysis name -> its module, each imported on first access."""

    def __getitem__(self, name: str) -> ModuleType:
        if not isinstance(name, str) or name not in _MODULES:
            raise KeyError(name)                # a list or mapping from a damaged manifest too
        return importlib.import_module(_MODULES[name])

    def __iter__(self) -> Iterator[str]:
        return iter(_MODULES)

    def __len__(self) -> int:
        return len(_MODULES)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in _MODULES


ANALYSES: Mapping[str, ModuleType] = _Analyses()
