"""Sparse finite-difference operators on an N x N x N grid, built with Kronecker products
(thesis eqs 5.14-5.19, the discrete Laplacian D0 of eq 5.19, and 5.24-5.29, the gradient and
curl).

A scalar field is a vector of ``N^3`` values in C order (``x`` slowest, ``z`` fastest: the
value at ``(i, j, k)`` is entry ``(i N + j) N + k``); a vector field stacks its ``x``, ``y``
and ``z`` components, ``3 N^3`` values. The 1-D operators act on the grid points inside the
box, with the field taken as zero beyond its faces (homogeneous Dirichlet): the second
difference ``(u_{i-1} - 2 u_i + u_{i+1}) / Delta^2`` (eq 5.19 along each axis) and the
centred first difference ``(u_{i+1} - u_{i-1}) / (2 Delta)``. Along axis ``a`` the 3-D
operator is ``I (x) .. (x) D (x) .. (x) I`` with ``D`` in position ``a``; operators on
different axes commute, so ``div curl = 0`` and ``curl grad = 0`` hold to rounding.

The thesis' ``D0`` carries an extra ``I3 (x)`` (eq 5.19) and its state ``xi`` is said to
have ``N^3`` entries where ``[A, V, Phi, Psi]`` on the grid has ``8 N^3`` (docs/deviations.md).
"""

from __future__ import annotations

import scipy.sparse as sp


def second_difference(n: int, spacing: float) -> sp.csr_matrix:
    """1-D ``d^2/dx^2``, zero beyond both ends: ``(n, n)``."""
    return sp.diags([1.0, -2.0, 1.0], [-1, 0, 1], shape=(n, n), format="csr") / spacing**2


def centred_difference(n: int, spacing: float) -> sp.csr_matrix:
    """1-D ``d/dx`` by centred differences, zero beyond both ends: ``(n, n)``."""
    return sp.diags([-1.0, 1.0], [-1, 1], shape=(n, n), format="csr") / (2 * spacing)


def along(axis: int, op: sp.spmatrix, n: int) -> sp.csr_matrix:
    """The 1-D operator ``op`` applied along ``axis`` (0 = x, 1 = y, 2 = z) of an
    ``n x n x n`` grid: ``I (x) op (x) I`` in that position."""
    eye = sp.identity(n, format="csr")
    factors = [eye, eye, eye]
    factors[axis] = op
    return sp.kron(sp.kron(factors[0], factors[1]), factors[2], format="csr")


def laplacian(n: int, spacing: float) -> sp.csr_matrix:
    """The 7-point Laplacian (eq 5.19 without its extra ``I3 (x)``): ``(n^3, n^3)``."""
    d2 = second_difference(n, spacing)
    return (along(0, d2, n) + along(1, d2, n) + along(2, d2, n)).tocsr()


def partials(n: int, spacing: float) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """``d/dx``, ``d/dy``, ``d/dz`` by centred differences."""
    d1 = centred_difference(n, spacing)
    return along(0, d1, n), along(1, d1, n), along(2, d1, n)


def gradient(n: int, spacing: float) -> sp.csr_matrix:
    """Scalar field -> vector field: ``(3 n^3, n^3)``."""
    return sp.vstack(partials(n, spacing), format="csr")


def divergence(n: int, spacing: float) -> sp.csr_matrix:
    """Vector field -> scalar field: ``(n^3, 3 n^3)``."""
    return sp.hstack(partials(n, spacing), format="csr")


def curl(n: int, spacing: float) -> sp.csr_matrix:
    """Vector field -> vector field: ``(3 n^3, 3 n^3)``."""
    dx, dy, dz = partials(n, spacing)
    return sp.bmat([[None, -dz, dy], [dz, None, -dx], [-dy, dx, None]], format="csr")
