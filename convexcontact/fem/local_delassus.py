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
"""Layers of cells around a row's support (patches of ~24 DOFs on a 2-D P1 face, ~220 on a 3-D Q1 face). One layer
on 3-D faces made the diagonal of a plate 20 : 20 : 1 five times cheaper (3.3·10⁴ DOFs: 6.5 → 1.3 s) for the same
Newton steps there, but its cruder step lengths c_j = 0.1 / d_j on the near-null rows of the 3-D pair of spheres
(tangential multipliers of the nodes on its symmetry planes) left its Tresca row at 10⁵ DOFs `inaccurate` after 100
Newton steps (6 steps with two layers) and its Coulomb row matrix-free stalled (docs/performance.md, "Thin bodies")."""


def local_diagonal(K: sp.spmatrix, B: sp.spmatrix, layers: int = LAYERS) -> np.ndarray:
    """d_j = b_jᵀ K_Ω⁻¹ b_j for each row b_j of B, Ω_j its support grown through K's graph ``layers`` times. Rows
    whose supports grown once are alike (a node's normal and tangential rows, whose own supports are a component
    each) share their patch: the patches are coloured, and each colour is one factorization with a right-hand side
    per row of a patch (3-D: a third of the factorizations of a colouring by the rows' own supports)."""
    K, B = sp.csr_matrix(K), sp.csr_matrix(B)
    graph = sp.csr_matrix((np.ones(K.nnz, dtype=np.int32), K.indices, K.indptr), shape=K.shape)
    reach = _pattern(graph @ B.T).T.tocsr() if layers else B  # each row's support grown once
    support, slot = supports(reach)
    first = np.flatnonzero(slot == 0)  # a row of each patch, in the order of the patches
    patch = _pattern(reach[first].T)  # n × patches
    for _ in range(layers - 1):
        patch = _pattern(graph @ patch)
    conflict = _pattern(patch.T @ _pattern(graph @ patch))  # patches that overlap or touch
    diagonal = np.zeros(B.shape[0])
    colours = colouring(conflict)
    for colour in range(colours.max(initial=-1) + 1):
        members = np.flatnonzero(colours == colour)
        region = np.flatnonzero(np.asarray(patch[:, members].sum(axis=1)).ravel())
        rows = np.flatnonzero(np.isin(support, members))
        load = B[rows][:, region]
        by_slot = sp.csr_matrix((np.ones(rows.size), (slot[rows], np.arange(rows.size))))
        response = spla.splu(sp.csc_matrix(K[region][:, region])).solve((by_slot @ load).T.toarray())
        # b_j · (the response of row j's slot): other rows of a slot act on other blocks of K_region. Picked from
        # the rows × slots products; the rows × region array of each row's slot's response this replaces was
        # the contact solve's peak on thin bodies (strip 400 : 1 clamped, 3.4·10⁴ DOFs: 67 of 97 MB)
        diagonal[rows] = (load @ response)[np.arange(rows.size), slot[rows]]
    return diagonal


def supports(B: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """For each row of ``B``: the index of its support (the set of its stored columns, numbered in order of first
    appearance) and its rank among the rows of that support."""
    numbers: dict = {}
    support = np.array([numbers.setdefault(B.indices[B.indptr[j]:B.indptr[j + 1]].tobytes(), len(numbers))
                        for j in range(B.shape[0])], dtype=int)
    order = np.argsort(support, kind="stable")
    starts = np.searchsorted(support[order], support[order])  # each row's support's first place in the order
    slot = np.empty_like(support)
    slot[order] = np.arange(support.size) - starts
    return support, slot


def colouring(conflict: sp.csr_matrix) -> np.ndarray:
    """Colours of the rows of a symmetric ``conflict`` pattern such that no two conflicting rows share one: greedy
    first fit, each row the least colour none of its coloured neighbours has (at most its degree + 1 colours).

    A loop over the rows (scipy has no graph colouring), O(nnz) in all: the rounds of Luby's rule it replaces each
    scanned the whole pattern, one round per colour and more, and on 3-D faces (~250 neighbours a row) took 31 of
    the 38 s of a Tresca solve on a 1.3·10³-DOF plate and 80 of 117 s at 10⁴ DOFs."""
    conflict = sp.csr_matrix(_pattern(conflict))
    m, indptr, indices = conflict.shape[0], conflict.indptr, conflict.indices
    colours = np.full(m, -1)
    taken = np.zeros(int(np.diff(indptr).max(initial=0)) + 2, dtype=bool)  # the colours of one row's neighbours
    for row in range(m):
        around = colours[indices[indptr[row]:indptr[row + 1]]]
        around = around[around >= 0]
        taken[around] = True
        colours[row] = np.argmin(taken)
        taken[around] = False
    return colours


def _pattern(A: sp.spmatrix) -> sp.csc_matrix:
    """The stored entries of A as ones (a new matrix)."""
    A = sp.csc_matrix(A)
    return sp.csc_matrix((np.ones(A.nnz, dtype=np.int32), A.indices, A.indptr), shape=A.shape)
