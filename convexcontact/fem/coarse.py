"""Coarse functions of the body away from its contact face, for the preconditioner of the matrix-free dual.

The slab preconditioner (:func:`~convexcontact.fem.factorization.slab`) clamps the body a few layers from the
contact face, so it has the face's long waves too stiff: on a 2-D strip 124 cells high with a 16-layer slab the
generalized eigenvalues of W against the slab's W spread over [1, 10]. Adding, outside the slab, the bilinear
(trilinear) hat functions of a regular grid whose spacing is the slab's thickness brings them to [1, 1.07]
(1001 bottom nodes, 1024 extra unknowns on 3.4·10⁴). A grid needs only the DOFs' positions; the functions are
FE functions (the grid's hats interpolated at the DOFs), so K on slab + grid is a Galerkin approximation of K.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

CELLS = 2
"""Least grid spacing, in the body's largest cells."""
KEEP = 0.25
"""A grid function is kept where it reaches this value at some DOF outside the slab: a hat that only grazes the
rest (a corner of its support) adds a nearly dependent column."""


def grid_functions(points: np.ndarray, components: np.ndarray, spacing: float) -> sp.csr_matrix:
    """The hats of a regular grid of ``spacing`` over the points (dim × n), one column per grid node and
    component, at each point in its own component (``components``, n): n × grid columns, 2^dim entries a row."""
    dim, n = points.shape
    low = points.min(axis=1, keepdims=True)
    cell = np.floor((points - low) / spacing).astype(np.int64)
    local = (points - low) / spacing - cell
    shape = cell.max(axis=1) + 2
    columns, values = [], []
    for corner in itertools.product((0, 1), repeat=dim):
        weight, node = np.ones(n), np.zeros(n, dtype=np.int64)
        for axis, side in enumerate(corner):
            weight = weight * (local[axis] if side else 1.0 - local[axis])
            node = node * shape[axis] + cell[axis] + side
        columns.append(node * dim + components)
        values.append(weight)
    return sp.csr_matrix((np.stack(values, axis=1).ravel(), np.stack(columns, axis=1).ravel(),
                          np.arange(0, (n + 1) * 2**dim, 2**dim)), shape=(n, int(shape.prod()) * dim))


def far_functions(points: np.ndarray, components: np.ndarray, cell_size: float) -> Callable:
    """``coarse(inside, contact)`` for :func:`~convexcontact.fem.factorization.slab`: grid functions on the DOFs
    outside the slab (``inside``, a mask), zero on it, the grid's spacing the slab's thickness (the farthest slab
    DOF from the contact DOFs ``contact``) and at least two cells (``cell_size``: the largest), so each grid cell
    holds DOFs; the functions that reach KEEP somewhere."""

    def coarse(inside: np.ndarray, contact: np.ndarray) -> sp.csr_matrix:
        thickness = cKDTree(points[:, contact].T).query(points[:, inside].T)[0].max(initial=0.0)
        rest = np.flatnonzero(~inside)
        functions = grid_functions(points[:, rest], components[rest], max(thickness, CELLS * cell_size))
        peak = np.zeros(functions.shape[1])
        np.maximum.at(peak, functions.indices, functions.data)
        kept = np.flatnonzero(peak >= KEEP)
        number = np.full(functions.shape[1], -1)
        number[kept] = np.arange(kept.size)
        entries = number[functions.indices] >= 0  # rows keep their kept entries, in the DOFs' numbering
        counts = np.add.reduceat(entries, functions.indptr[:-1])  # rest is not empty (see slab)
        indptr = np.zeros(inside.size + 1, dtype=np.int64)
        indptr[rest + 1] = counts
        return sp.csr_matrix((functions.data[entries], number[functions.indices[entries]], np.cumsum(indptr)),
                             shape=(inside.size, kept.size))

    return coarse


def body_far_functions(fem) -> Callable:
    """:func:`far_functions` of an assembled model (its free DOFs, their components, its largest cell)."""
    components = np.zeros(fem.basis.N, dtype=np.int64)
    for component, dofs in enumerate(fem.basis.split_indices()):
        components[dofs] = component
    corners = fem.mesh.p[:, fem.mesh.t]  # dim × corners × cells
    cell_size = np.linalg.norm(corners.max(axis=1) - corners.min(axis=1), axis=0).max()
    return far_functions(fem.basis.doflocs[:, fem.free], components[fem.free], cell_size)
