"""The matrix-free dual of two bodies: coarse functions per body, graded with the cells, keep the slab
preconditioner's spectrum bounded, and the answer is the dense dual's."""

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

import convexcontact as cc
from convexcontact.fem import factorization
from convexcontact.fem.coarse import Functions, body_far_functions, dof_cell_sizes, far_functions
from convexcontact.scene.bodies_library import punch_on_foundation
from convexcontact.scene.description import Tresca

H = 0.005
"""Cell size at the contact of the bench's pair (graded meshes): 1.6·10⁴ DOFs, 105 mortar rows."""


@pytest.fixture(scope="module")
def pair():
    """The matrix-free Tresca dual of the punch on a foundation, and W formed."""
    model = cc.prepare(punch_on_foundation(H, law=Tresca(slip_bound=0.002)), "dual-matrix-free")
    B = model.program.P.B
    return model, B, factorization.factorize(model.fem.K).schur(B)


def spectrum(approximation, W):
    """The generalized eigenvalues of W against the approximation G H⁻¹ Gᵀ."""
    G = approximation.G.toarray()
    M = G @ factorization.factorize(approximation.H).solve(G.T)
    return la.eigh(W, 0.5 * (M + M.T), eigvals_only=True)


def test_the_approximation_s_h_is_structurally_symmetric(pair):
    """H stores (j, i) wherever it stores (i, j), as an SPD matrix's pattern should (a factorization of it whole, an LU
    on the pattern of its Cholesky, read an entry outside it): the functions' energy Cᵀ(Nᵀ K N)C stored one of −1.2e-16
    and not its mirror (scipy's products drop sums that cancel), until it was symmetrized."""
    H = pair[0].program.P.approximation.H.tocsr()
    stored = sp.csr_matrix((np.ones(H.nnz), H.indices, H.indptr), shape=H.shape)
    assert (stored != stored.T).nnz == 0


def test_h_holds_the_coarse_span_in_its_nodal_basis(pair):
    """H's block of coarse functions is their span's nodal basis (:meth:`~convexcontact.fem.coarse.Functions.localized`),
    not the hierarchical one (each grid's hats at the nodes the next coarser grid lacks, a coarse hat over every
    finer one, as before): G H⁻¹ Gᵀ the same to round-off, and each function coupled to at most 64 others, where
    a hierarchical one reaches 176 (on the pair at 1.4·10⁶ DOFs: 76 against 3,550, H's fill 1.54·10⁷ → 1.13·10⁷)."""
    model, B, _ = pair
    far = body_far_functions(model.fem)

    def hierarchical(inside, contact):
        functions = far(inside, contact)
        return Functions(functions.nodes, functions.combination)

    approximations = [factorization.slab(model.fem.K, B, coarse) for coarse in (far, hierarchical)]
    local, before = [approximation.H[approximation.slab:, approximation.slab:].getnnz(axis=0).max()
                     for approximation in approximations]
    assert approximations[0].H.shape == approximations[1].H.shape
    assert local <= 64 and before > 150
    local, before = [a.G @ factorization.factorize(a.H).solve(a.G.T.toarray()) for a in approximations]
    assert np.abs(local - before).max() <= 1e-11 * np.abs(before).max()


def test_coarse_functions_stay_on_one_body(pair):
    """Each coarse function lives on one body's DOFs outside the slab (K's graph joins no two bodies), and both
    bodies have some."""
    model, B, _ = pair
    K = model.fem.K
    bodies = connected_components(K, directed=False)[1]
    contact = np.unique(B.indices)
    inside = np.zeros(K.shape[0], dtype=bool)
    inside[contact] = True
    inside = (abs(K) @ (abs(K) @ inside)) > 0  # two layers
    far = body_far_functions(model.fem)(inside, contact)
    functions = (far.nodes @ far.combination).tocsc()
    assert not abs(functions[inside]).sum()
    owners = [np.unique(bodies[functions.indices[functions.indptr[j]:functions.indptr[j + 1]]])
              for j in range(functions.shape[1])]
    assert all(owner.size == 1 for owner in owners)
    assert {int(owner[0]) for owner in owners} == {0, 1}


def test_per_body_graded_functions_bound_the_pair_spectrum(pair):
    """K on slab + functions is a Galerkin approximation (W's eigenvalues against it ≥ 1); with the functions per
    body the largest is below 2, where the clamped slab leaves 47 and one grid over both bodies (tying them
    together) 12 (22 before the finest grid was fitted to the points' box, :func:`~convexcontact.fem.coarse.fitted_spacing`)."""
    model, B, W = pair
    fem, K = model.fem, model.fem.K
    per_body = spectrum(factorization.slab(K, B, body_far_functions(fem)), W)
    clamped = spectrum(factorization.slab(K, B), W)
    components = np.zeros(fem.basis.N, dtype=np.int64)
    for component, dofs in enumerate(fem.basis.split_indices()):
        components[dofs] = component
    points = fem.basis.doflocs[:, fem.free]
    joined = far_functions(points, components[fem.free], dof_cell_sizes(fem), np.zeros(K.shape[0], int))
    one_grid = spectrum(factorization.slab(K, B, joined), W)
    assert min(per_body.min(), clamped.min(), one_grid.min()) > 1 - 1e-9
    assert per_body.max() < 2.0
    assert clamped.max() > 40.0 and one_grid.max() > 10.0


def test_matrix_free_pair_is_the_dense_dual(pair):
    """The matrix-free Tresca dual (newton-cg, the per-body preconditioner) is certified and its displacement is the
    dense dual's by Clarabel."""
    model, _, _ = pair
    matrix_free = model.solve("newton-cg")
    dense = cc.prepare(punch_on_foundation(H, law=Tresca(slip_bound=0.002)), "dual").solve("clarabel")
    assert matrix_free.status == "solved" and dense.status == "solved"
    assert matrix_free.certificate.worst <= 1e-10
    scale = np.abs(dense.displacement).max()
    assert np.abs(matrix_free.displacement - dense.displacement).max() <= 1e-6 * scale



def test_a_body_past_the_budget_gets_a_coarser_grid_all_of_it_checked(pair, monkeypatch):
    """A body whose grids would pass DENSE_COLUMNS functions gets coarser grids instead (unchecked beyond it, the pair
    at 1.4·10⁶ DOFs kept 1,764 dependent functions, and the slab then dropped them all): with a budget of 150 a body,
    the slab keeps the functions (they are independent), at most 150 a body, and W against the approximation stays
    far below the clamped slab's 47 (below 2 with the full budget)."""
    from convexcontact.fem import coarse

    model, B, W = pair
    monkeypatch.setattr(coarse, "DENSE_COLUMNS", 150)
    approximation = factorization.slab(model.fem.K, B, body_far_functions(model.fem))
    functions = approximation.H.shape[0] - approximation.slab
    assert 150 < functions <= 2 * 150
    assert spectrum(approximation, W).max() < 10.0
