"""The diagonal of the Delassus operator W = B K⁻¹ Bᵀ from the body near each row, without forming W.

W_jj is mostly local: a row's multiplier loads a few nodes, and the displacement it makes there is set by the cells
around them. So d_j = b_jᵀ K_Ω⁻¹ b_j, Ω the DOFs within LAYERS layers of b_j's support (the body clamped beyond),
has W_jj's scale: it follows the cell size of a graded mesh and the stiffness of the body (each side of a pair), which
one step length for all rows cannot (two bodies on graded meshes: W_jj over [2e-5, 4e-2]). d_j ≤ W_jj (a clamped
patch is stiffer); the ratio varies slowly along the face. Rows whose patches neither overlap nor touch have a block
diagonal K on the union of their patches: one solve per colour of a colouring of the rows gives every d_j exactly.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

LAYERS = 2
"""Layers of cells around a row's support (patches of ~30 DOFs in 2-D, ~200 in 3-D)."""


def local_diagonal(K: sp.spmatrix, B: sp.spmatrix, layers: int = LAYERS) -> np.ndarray:
    """d_j = b_jᵀ K_Ω⁻¹ b_j for each row b_j of B, Ω_j its support grown ``layers`` times through K's graph."""
    K, B = sp.csr_matrix(K), sp.csr_matrix(B)
    graph = sp.csr_matrix((np.ones(K.nnz, dtype=np.int32), K.indices, K.indptr), shape=K.shape)
    patch = sp.csc_matrix((np.ones(B.nnz, dtype=np.int32), B.indices, B.indptr), shape=B.shape[::-1])  # n × m
    for _ in range(layers):
        patch = _pattern(graph @ patch)
    conflict = _pattern(patch.T @ _pattern(graph @ patch))  # patches that overlap or touch
    diagonal = np.zeros(B.shape[0])
    colours = colouring(conflict)
    for colour in range(colours.max(initial=-1) + 1):
        rows = np.flatnonzero(colours == colour)
        region = np.flatnonzero(np.asarray(patch[:, rows].sum(axis=1)).ravel())
        load = B[rows][:, region]
        response = spla.splu(sp.csc_matrix(K[region][:, region])).solve(np.asarray(load.sum(axis=0)).ravel())
        diagonal[rows] = load @ response  # the other rows' loads act on other blocks of K_region
    return diagonal


def colouring(conflict: sp.csr_matrix) -> np.ndarray:
    """Colours of the rows of a symmetric ``conflict`` pattern such that no two conflicting rows share one: each
    colour a maximal independent set of the rows left, grown by rounds in which the rows whose random priority is the
    largest among their free neighbours join (Luby's rule; scipy has no graph colouring)."""
    m = conflict.shape[0]
    conflict = sp.csr_matrix(_pattern(conflict), dtype=float)  # its entries, whatever their values, as ones
    conflict.setdiag(0.0)
    conflict.eliminate_zeros()
    priority = np.random.default_rng(0).permutation(m) + 1.0
    colours = np.full(m, -1)
    colour = 0
    while (colours < 0).any():
        free = colours < 0
        while free.any():
            neighbours = conflict.multiply(np.where(free, priority, 0.0)[None, :]).max(axis=1).toarray().ravel()
            joined = free & (priority > neighbours)
            colours[joined] = colour
            free &= ~joined
            free[conflict[joined].indices] = False  # the neighbours of the colour's rows wait for the next one
        colour += 1
    return colours


def _pattern(A: sp.spmatrix) -> sp.csc_matrix:
    """The stored entries of A as ones (a new matrix)."""
    A = sp.csc_matrix(A)
    return sp.csc_matrix((np.ones(A.nnz, dtype=np.int32), A.indices, A.indptr), shape=A.shape)
