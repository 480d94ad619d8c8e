"""Thin bodies (issue 25, docs/performance.md "Thin bodies"): the cheaper pieces of the matrix-free dual give what the
costlier ones gave."""

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.fem import local_delassus
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


@pytest.mark.parametrize("dim, nodes, dofs, layers", [(2, 9, 200, 2), (3, 25, 700, 0), (3, 25, 700, 1),
                                                      (3, 25, 700, 2)])
def test_a_node_s_rows_share_a_patch_and_keep_their_own_diagonal(dim, nodes, dofs, layers):
    """The rows of a node (normal and tangential: a component each) are solved on one patch, a third of the
    factorizations in 3-D; each row's d_j is still b_jᵀ K_Ω⁻¹ b_j on its own support's patch."""
    K, B = contact_rows(dim, nodes, dofs)
    np.testing.assert_allclose(local_diagonal(K, B, layers), row_by_row(K, B, layers), rtol=1e-10)


@pytest.mark.parametrize("dim, dofs", [(2, 300), (3, 700)])
def test_the_patches_grow_on_k_s_nodes(dim, dofs):
    """_twins groups K's rows into its nodes (a vector field's ``dim`` DOFs, numbered together, one pattern): every
    group's rows store the same columns, and each group is a node, so a patch grown on nodes is the one grown on
    DOFs (the diagonal, checked above against one solve per row)."""
    K, _ = contact_rows(dim, 9 if dim == 2 else 25, dofs)
    twins = local_delassus._twins(K)
    node = twins.indices
    assert twins.shape[1] == K.shape[0] // dim and np.all(np.bincount(node) == dim)
    patterns = [tuple(K[i].indices) for i in range(K.shape[0])]
    assert all(patterns[i] == patterns[i - 1] for i in range(1, K.shape[0]) if node[i] == node[i - 1])
    assert all(patterns[i] != patterns[i - 1] for i in range(1, K.shape[0]) if node[i] != node[i - 1])


def test_grown_faces_solved_loosely_give_the_same_answer_for_fewer_products(monkeypatch):
    """CG on a grown face stops at GROWN_FORCING × its first residual (its point is a trial that finds the face):
    on a strip 100 : 1 clamped at its ends (Tresca, matrix-free) the same answer as with every grown face solved to
    the step's target, and fewer products with W (76 against 104 measured). From x = 0, a start given: from none the
    first Newton point is the empty face's (FIRST_FORCING), this strip's answer, and no face grows much."""
    model = cc.prepare(scene_of("strip-clamped-100", 2, "tresca", 2e3), "dual-matrix-free")
    program, start = model.program, np.zeros(model.program.n_variables)
    form = newton_cg.bound_form_of(program)
    loose = newton_cg.newton_cg(program, form, start, newton_cg.TOL, 100)
    monkeypatch.setattr(newton_cg, "GROWN_FORCING", 0.0)
    tight = newton_cg.newton_cg(program, form, start, newton_cg.TOL, 100)
    assert loose.status == tight.status == "solved" and loose.info["grown"] > 0
    assert np.abs(loose.x - tight.x).max() <= 1e-10 * np.abs(tight.x).max()
    assert loose.info["products"] < tight.info["products"]


def patch_sizes(K: sp.csr_matrix, B: sp.csr_matrix, layers: int) -> dict:
    """The DOFs of each patch: the rows' supports grown once (the rows of a node share it), then ``layers`` − 1 more
    times."""
    graph = sp.csr_matrix((np.ones(K.nnz, dtype=int), K.indices, K.indptr), shape=K.shape)
    sizes = {}
    for j in range(B.shape[0]):
        inside = np.zeros(K.shape[0], dtype=int)
        inside[B[j].indices] = 1
        inside = (graph @ inside > 0).astype(int)
        key = np.flatnonzero(inside).tobytes()
        for _ in range(layers - 1):
            inside = (graph @ inside > 0).astype(int)
        sizes[key] = inside.sum()
    return sizes


@pytest.mark.parametrize("shape, most", [("plate-free-20", 0.1), ("two-body", 1.0)])
def test_patches_alike_are_solved_once_for_the_same_diagonal(shape, most, monkeypatch):
    """A patch equal to one solved before (a regular plate's, translated) takes its d_j: each row's d_j is still
    b_jᵀ K_Ω⁻¹ b_j on its own patch (two layers), on a plate 20 : 20 : 1 (most patches alike: a tenth of their DOFs
    factorized, 9 % measured) and on the pair of spheres' slab (mortar rows, a curved face: every patch factorized)."""
    model = cc.prepare(scene_of(shape, 3, "tresca", 2e3), "dual-matrix-free")
    approximation = model.program.P.approximation
    K, B = approximation.H[:approximation.slab, :approximation.slab], approximation.G[:, :approximation.slab]
    factorized, solved = [], local_delassus._solved
    monkeypatch.setattr(local_delassus, "_solved", lambda K, *rest: factorized.append(K.shape[0]) or solved(K, *rest))
    np.testing.assert_allclose(local_diagonal(K, B, 2), row_by_row(K, B, 2), rtol=1e-10)
    patches = sum(patch_sizes(K, B, 2).values())
    assert sum(factorized) <= most * patches and (most < 1 or sum(factorized) == patches)
