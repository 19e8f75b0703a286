"""Multiplication counts taken from the code path itself (Tables 4.3, 4.4).

The filters that report a cost do their arithmetic through :func:`matmul`, :func:`mul` and
:func:`solve`. Outside :func:`counting` these are the plain numpy operations; inside, each
call also adds the real multiplications it performs, per Monte Carlo run (the leading batch
axes are divided out), to the active tally. A count is therefore what the code does, not
what a formula says it should do.

Conventions: a product of an ``(m, k)`` and a ``(k, n)`` matrix costs ``m k n``; an
element-wise product costs one per element; a solve ``S^-1 B`` with ``S`` of order ``m`` and
``B`` with ``k`` columns costs ``m^3/3 + m^2 k`` (LU factorisation and substitutions,
rounded up). Additions are not counted, as in the thesis.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from estim.numerics import linalg

_tally: list[dict] = []


@contextmanager
def counting(runs: int = 1) -> Iterator[dict]:
    """Count multiplications per run inside the block: yields ``{label: count}``, with the
    label of each counted operation (``"total"`` holds the sum)."""
    tally = {"total": 0.0, "_runs": float(runs)}
    _tally.append(tally)
    try:
        yield tally
    finally:
        _tally.pop()
        tally.pop("_runs")


def counting_active() -> bool:
    """Whether a :func:`counting` block is open (a compiled path adds its counts then)."""
    return bool(_tally)


def _add(label: str, total: float) -> None:
    if _tally:
        tally = _tally[-1]
        per_run = total / tally["_runs"]
        tally[label] = tally.get(label, 0.0) + per_run
        tally["total"] += per_run


def matmul(a: np.ndarray, b: np.ndarray, label: str = "other") -> np.ndarray:
    """``a @ b`` (batched); counts ``m k n`` per matrix product."""
    out = a @ b
    if _tally:
        k = a.shape[-1] if a.ndim > 1 else a.shape[0]
        _add(label, out.size * k)
    return out


def mul(a: np.ndarray, b: np.ndarray, label: str = "other") -> np.ndarray:
    """Element-wise ``a * b``; counts one per element of the result."""
    out = a * b
    _add(label, np.size(out))
    return out


def solve(S: np.ndarray, B: np.ndarray, label: str = "other") -> np.ndarray:
    """``S^-1 B`` (batched, :func:`estim.numerics.linalg.solve`); counts ``m^3/3 + m^2 k`` per
    system."""
    out = linalg.solve(S, B)
    if _tally:
        m, k = S.shape[-1], B.shape[-1]
        systems = math.prod(S.shape[:-2]) if S.ndim > 2 else 1
        _add(label, systems * (math.ceil(m**3 / 3) + m * m * k))
    return out
