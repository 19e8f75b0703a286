"""The registered analyses: one line each (see :mod:`core.analyses.base` for the protocol)."""

from __future__ import annotations

from core.analyses import estimation, kronecker, perturbation

ANALYSES = {
    "estimation": estimation,
    "kronecker": kronecker,
    "perturbation": perturbation,
}
