"""The 3-D grid of the field model (:mod:`estim.fields.fdtd`): points, spacing and the
sparse operators of :mod:`estim.fields.operators`, without the compiled time stepping (a
config check builds a grid without loading numba, and without scipy.sparse: the operators
are made on first use)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import scipy.sparse as sp


@dataclass
class Grid:
    """``n`` points per axis, spacing ``spacing``, centred on the dipole (``n`` even: no
    point sits on the source's centre)."""

    n: int
    spacing: float

    @cached_property
    def laplacian(self) -> sp.csr_matrix:
        from estim.fields import operators

        return operators.laplacian(self.n, self.spacing)

    @cached_property
    def grad(self) -> sp.csr_matrix:
        from estim.fields import operators

        return operators.gradient(self.n, self.spacing)

    @cached_property
    def curl(self) -> sp.csr_matrix:
        from estim.fields import operators

        return operators.curl(self.n, self.spacing)

    def __post_init__(self) -> None:
        x = (np.arange(self.n) - (self.n - 1) / 2) * self.spacing
        self.axis = x
        X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
        self.xyz = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=-1)
        self.r = np.linalg.norm(self.xyz, axis=-1)
        self.theta = np.arccos(np.clip(self.xyz[:, 2] / self.r, -1, 1))
        self.phi = np.arctan2(self.xyz[:, 1], self.xyz[:, 0])
        shape = (self.n,) * 3
        index = np.indices(shape)
        faces, inner = [], []
        for axis in range(3):
            for edge, neighbour in ((0, 1), (self.n - 1, self.n - 2)):
                on = index[axis] == edge
                faces.append(np.flatnonzero(on.ravel()))
                moved = [a[on] for a in index]
                moved[axis] = np.full(moved[axis].shape, neighbour)
                inner.append(np.ravel_multi_index(moved, shape))
        self.faces, self.inner = faces, inner

    @property
    def size(self) -> int:
        return self.n**3
