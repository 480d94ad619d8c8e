"""The coarse grid beyond the slab fitted to the body (issue 25, docs/performance.md "Thin bodies: the clamped strip's
bending on the coarse grid"): its far sides on grid nodes, so the grid holds the linear fields there and the clamped
strip's bending; and the dense independence check only where a sparse one finds a small pivot."""

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.fem import coarse, factorization
from convexcontact.studies.benchmarks.bench import scene_of

DOFS = 3e3
"""A strip 20 : 1 clamped at its ends, 3.6·10³ DOFs: its top lies 0.47 of a grid cell past the last node row of the
unfitted grid, whose hats there KEEP dropped."""


@pytest.fixture(scope="module")
def strip():
    """The clamped strip's matrix-free Signorini dual, its W formed, and the slab approximation with the grid as it
    was (not fitted) and as it is."""
    model = cc.prepare(scene_of("strip-clamped-20", 2, "signorini", DOFS), "dual-matrix-free")
    K, B = model.fem.K, model.program.P.B
    unfitted = pytest.MonkeyPatch()
    unfitted.setattr(coarse, "fitted_spacing", lambda points, spacing: spacing)
    old = factorization.slab(K, B, coarse.body_far_functions(model.fem))
    unfitted.undo()
    new = factorization.slab(K, B, coarse.body_far_functions(model.fem))
    return model, factorization.factorize(K).schur(B), old, new


def spectrum(approximation, W):
    """The generalized eigenvalues of W against G H⁻¹ Gᵀ on W's nonzero rows (the clamped corners have none)."""
    keep = np.diag(W) > 1e-14 * np.diag(W).max()
    G = approximation.G.toarray()[keep]
    M = G @ factorization.factorize(approximation.H).solve(G.T)
    return la.eigh(W[np.ix_(keep, keep)], 0.5 * (M + M.T), eigvals_only=True)


def test_fitted_grid_puts_the_far_sides_on_nodes():
    """Per axis a whole number of cells across the points' bounding box, none wider than the spacing asked nor
    narrower than half of it (a box thinner than the spacing: one cell)."""
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, [20.0, 1.0, 0.1], (200, 3)).T
    spacing = 0.3
    fitted = coarse.fitted_spacing(points, spacing)
    cells = np.ptp(points, axis=1) / fitted
    np.testing.assert_allclose(cells, np.round(cells), atol=1e-9)
    assert (fitted <= spacing).all() and (fitted[:2] > spacing / 2).all() and np.isclose(cells[2], 1.0)


def test_clamped_strip_bending_is_on_the_fitted_grid(strip):
    """W against the approximation: ≥ 1 (Galerkin) both ways; the unfitted grid misses the beam's bending (largest
    eigenvalue 534 measured), the fitted one holds it (1.06)."""
    _, W, old, new = strip
    before, after = spectrum(old, W), spectrum(new, W)
    assert min(before.min(), after.min()) > 1 - 1e-9
    assert before.max() > 100.0
    assert after.max() < 1.2


def test_fitted_grid_interpolates_linear_fields_beyond_the_slab(strip):
    """The grid's functions outside the slab reproduce x and y in each component (least squares, exact to
    rounding); the unfitted ones did not at the top (the dropped hats)."""
    model, _, _, _ = strip
    fem, K, B = model.fem, model.fem.K, model.program.P.B
    far, captured = coarse.body_far_functions(fem), []
    factorization.slab(K, B, lambda inside, contact: captured.append(far(inside, contact)) or captured[-1])
    functions = sp.csc_matrix(captured[0].nodes @ captured[0].combination)
    beyond = np.asarray(abs(functions).sum(axis=1)).ravel() > 0
    points = fem.basis.doflocs[:, fem.free]
    for field in points:
        target = np.where(beyond, field, 0.0)
        fit = functions @ spla.lsqr(functions, target, atol=1e-15, btol=1e-15, iter_lim=10_000)[0]
        assert np.abs(fit - target)[beyond].max() <= 1e-8 * np.abs(field).max()


def test_dependent_functions_still_go_through_the_dense_check():
    """A function given twice leaves a zero pivot in the sparse LDLᵀ: the dense pivoted Cholesky then keeps one of
    each pair; functions of a one-body grid are all kept without it."""
    model = cc.prepare(scene_of("strip-clamped-20", 2, "signorini", 2e3), "primal")
    K = sp.csr_matrix(model.fem.K)
    points = model.fem.basis.doflocs[:, model.fem.free]
    components = np.zeros(model.fem.basis.N, dtype=int)
    for component, dofs in enumerate(model.fem.basis.split_indices()):
        components[dofs] = component
    functions = coarse.grid_functions(points, components[model.fem.free], 0.2).tocsc()
    functions = functions[:, np.flatnonzero(np.asarray(abs(functions).sum(axis=0)).ravel() > 0.5)]
    assert coarse.independent(functions.T @ K @ functions).size == functions.shape[1]
    twice = sp.hstack([functions, functions], format="csc")
    assert coarse.independent(twice.T @ K @ twice).size == functions.shape[1]
