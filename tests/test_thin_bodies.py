"""Thin bodies (issue 25, docs/performance.md "Thin bodies"): the cheaper pieces of the matrix-free dual give what the
costlier ones gave."""

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.fem.local_delassus import local_diagonal
from convexcontact.scene.library import whole_face
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def contact_rows(dim: int, nodes: int, dofs: float):
    """K and B of a whole face's Tresca dual, applied matrix-free."""
    model = cc.prepare(whole_face(dim, nodes, dofs, cc.Tresca(slip_bound=0.002)), "dual-matrix-free")
    return sp.csr_matrix(model.fem.K), sp.csr_matrix(model.program.P.B)


def row_by_row(K: sp.csr_matrix, B: sp.csr_matrix, layers: int) -> np.ndarray:
    """b_jᵀ K_Ω⁻¹ b_j, Ω the row's own support grown ``layers`` times through K's stored entries, one dense solve per
    row."""
    graph = sp.csr_matrix((np.ones(K.nnz, dtype=int), K.indices, K.indptr), shape=K.shape)
    diagonal = np.zeros(B.shape[0])
    for j in range(B.shape[0]):
        inside = np.zeros(K.shape[0], dtype=int)
        inside[B[j].indices] = 1
        for _ in range(layers):
            inside = (graph @ inside > 0).astype(int)
        patch = np.flatnonzero(inside)
        b = B[j].toarray().ravel()[patch]
        diagonal[j] = b @ np.linalg.solve(K[patch][:, patch].toarray(), b)
    return diagonal


@pytest.mark.parametrize("dim, nodes, dofs, layers", [(2, 9, 200, 2), (3, 25, 700, 1), (3, 25, 700, 2)])
def test_a_node_s_rows_share_a_patch_and_keep_their_own_diagonal(dim, nodes, dofs, layers):
    """The rows of a node (normal and tangential: a component each) are solved on one patch, a third of the
    factorizations in 3-D; each row's d_j is still b_jᵀ K_Ω⁻¹ b_j on its own support's patch."""
    K, B = contact_rows(dim, nodes, dofs)
    np.testing.assert_allclose(local_diagonal(K, B, layers), row_by_row(K, B, layers), rtol=1e-10)


def test_grown_faces_solved_loosely_give_the_same_answer_for_fewer_products(monkeypatch):
    """CG on a grown face stops at GROWN_FORCING × its first residual (its point is a trial that finds the face):
    on a strip 100 : 1 clamped at its ends (Tresca, matrix-free) the same answer as with every grown face solved to
    the step's target, and fewer products with W (60 against 73 measured)."""
    model = cc.prepare(scene_of("strip-clamped-100", 2, "tresca", 2e3), "dual-matrix-free")
    loose = newton_cg.solve(model.program)
    monkeypatch.setattr(newton_cg, "GROWN_FORCING", 0.0)
    tight = newton_cg.solve(model.program)
    assert loose.status == tight.status == "solved" and loose.info["grown"] > 0
    assert np.abs(loose.x - tight.x).max() <= 1e-10 * np.abs(tight.x).max()
    assert loose.info["products"] < tight.info["products"]
