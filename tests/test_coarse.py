"""The matrix-free dual's preconditioner: coarse functions beyond the slab, numeric refactorization, and the exact
inverse of the approximation restricted to each Newton system."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

import convexcontact as cc
from convexcontact import solvers
from convexcontact.fem import factorization
from convexcontact.fem.coarse import (
    Functions,
    bodies,
    body_far_functions,
    graded_functions,
    graded_grids,
    grid_functions,
)
from convexcontact.fem.factorization import Approximation, Delassus, factorize
from convexcontact.formulations import contact_weights
from convexcontact.scene.description import Signorini, Tresca
from convexcontact.scene.library import whole_face
from convexcontact.solvers import newton_cg


@pytest.mark.parametrize("dim", [2, 3])
def test_grid_functions_reproduce_linear_fields(dim):
    """Bilinear (trilinear) hats sum to one in each component and interpolate any linear field exactly."""
    rng = np.random.default_rng(dim)
    points = rng.uniform(-1.0, 2.0, (dim, 500))
    components = rng.integers(0, dim, 500)
    functions = grid_functions(points, components, spacing=0.37)
    assert (functions.getnnz(axis=1) == 2**dim).all()
    # the grid nodes' positions, recovered from the hats' weights on the points (least squares, exact here)
    slope, offset = rng.standard_normal(dim), 0.3
    field = slope @ points + offset
    node_values, *_ = np.linalg.lstsq(functions.toarray(), field, rcond=None)
    np.testing.assert_allclose(functions @ node_values, field, atol=1e-10)
    np.testing.assert_allclose(functions @ np.ones(functions.shape[1]), 1.0, atol=1e-12)
    for component in range(dim):  # each column holds one component
        rows = functions[components == component]
        assert not (abs(functions[components != component]).sum(axis=0).A1 * abs(rows).sum(axis=0).A1).any()


@pytest.mark.parametrize("dim", [2, 3])
def test_graded_functions_are_the_kept_hats_through_one_grid_a_point(dim):
    """On cells graded over two decades, the graded functions F = nodes · combination are every grid's kept hats
    evaluated at every point (F built directly, as before), with one grid's 2^dim hats a point in ``nodes``."""
    rng = np.random.default_rng(dim)
    points = rng.uniform(0.0, 1.0, (dim, 4000))
    components = rng.integers(0, dim, 4000)
    sizes = 0.01 * 100.0 ** points[0]
    _, spacings, keeps = graded_grids(points, components, sizes, 0.03)
    functions = graded_functions(points, components, sizes, 0.03)
    direct = sp.hstack([grid_functions(points, components, spacing)[:, keep] for spacing, keep in zip(spacings, keeps)])
    assert len(spacings) >= 4 and functions.shape == direct.shape
    assert (functions.nodes.getnnz(axis=1) <= 2**dim).all() and direct.getnnz(axis=1).max() > 3 * 2**dim
    np.testing.assert_allclose((functions.nodes @ functions.combination).toarray(), direct.toarray(), atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_localized_functions_are_the_nodal_basis_of_the_kept_span(dim):
    """The graded functions localized (all of them, and 9 in 10 kept) are their span's nodal basis ψ = F A⁻¹, A the
    functions' values at their own nodes: each hat evaluated here from its node's position and its grid's spacing,
    not through any grid's numbering. ψ_j is 1 at its node and 0 at the other functions', no wider than F_j, and
    the basis is local: under half of F's nonzeros (the hierarchical F: a coarse hat over every finer one)."""
    rng = np.random.default_rng(dim)
    points = rng.uniform(0.0, 1.0, (dim, 4000))
    components = rng.integers(0, dim, 4000)
    sizes = 0.01 * 100.0 ** points[0]
    (low, high), spacings, keeps = graded_grids(points, components, sizes, 0.03)
    nodes, spacing, component = [], [], []
    for grid, keep in zip(spacings, keeps):
        grid = np.broadcast_to(np.reshape(grid, (-1, 1)), (dim, 1))
        shape = np.floor((high - low) / grid).astype(int).ravel() + 2
        kept = np.flatnonzero(keep)
        nodes.append(low + np.stack(np.unravel_index(kept // dim, tuple(shape))) * grid)
        spacing.append(np.broadcast_to(grid, (dim, kept.size)))
        component.append(kept % dim)
    nodes, spacing, component = np.hstack(nodes), np.hstack(spacing), np.concatenate(component)

    def hats(at, at_components):
        reach = np.clip(1.0 - np.abs(at[:, :, None] - nodes[:, None, :]) / spacing[:, None, :], 0.0, None)
        return reach.prod(axis=0) * (at_components[:, None] == component[None, :])

    functions = graded_functions(points, components, sizes, 0.03)
    F, A = hats(points, components), hats(nodes, component)
    np.testing.assert_allclose((functions.nodes @ functions.combination).toarray(), F, atol=1e-14)
    for columns in (np.arange(F.shape[1]), np.sort(rng.permutation(F.shape[1])[:F.shape[1] * 9 // 10])):
        local = functions.kept(columns).localized()
        psi = (local.nodes @ local.combination).toarray()
        np.testing.assert_allclose(psi, F[:, columns] @ np.linalg.inv(A[np.ix_(columns, columns)]), atol=1e-12)
        assert not (psi[F[:, columns] == 0]).any()
        assert np.count_nonzero(psi) < np.count_nonzero(F[:, columns]) / 2


def test_bodies_are_the_connected_components_numbered_by_their_first_dofs():
    """Three bodies' DOFs interleaved: the bodies are K's connected components, numbered in the order of their first
    DOFs (as scipy's undirected search numbers them)."""
    rng = np.random.default_rng(5)
    blocks = [sp.random(n, n, density=0.3, random_state=rng) for n in (7, 11, 5)]
    K = sp.block_diag([block + block.T + sp.eye(block.shape[0]) for block in blocks]).tocsr()
    order = rng.permutation(K.shape[0])
    K = K[order][:, order]
    expected = connected_components(K, directed=False)[1]
    np.testing.assert_array_equal(bodies(K), expected)
    assert set(expected) == {0, 1, 2}


def strip(nodes=61, height=24):
    """A 2-D whole-face strip tall enough that the slab of LAYERS clamps most of it."""
    fem = cc.prepare(whole_face(2, nodes, 2 * nodes * (height + 1)), "primal").fem
    B = (contact_weights(fem.contact, "nodal") @ fem.contact.N).tocsr()
    return fem, B


def delassus_eigenvalues(approximation: Approximation, W: np.ndarray) -> np.ndarray:
    """The generalized eigenvalues of W against the approximation G H⁻¹ Gᵀ."""
    G = approximation.G.toarray()
    M = G @ factorize(approximation.H).solve(G.T)
    return la.eigh(W, 0.5 * (M + M.T), eigvals_only=True)


def test_coarse_functions_give_the_slab_the_long_waves():
    """K on slab + grid functions is a Galerkin approximation (the eigenvalues of W against it are ≥ 1, as for
    the clamped slab), and it has the long waves the clamped slab has too stiff: the largest eigenvalue falls
    from several to near one."""
    fem, B = strip()
    W = factorize(fem.K).schur(B)
    clamped = delassus_eigenvalues(factorization.slab(fem.K, B), W)
    coarse = delassus_eigenvalues(factorization.slab(fem.K, B, body_far_functions(fem)), W)
    assert clamped.min() > 1 - 1e-9 and coarse.min() > 1 - 1e-9
    assert clamped.max() > 2.0
    assert coarse.max() < 1.3


def twice_each(far):
    """``far``'s coarse functions, each given twice."""

    def coarse(inside, contact):
        functions = far(inside, contact)
        return Functions(functions.nodes, sp.hstack([functions.combination] * 2, format="csr"))

    return coarse


def test_dependent_coarse_functions_are_dropped_by_the_slab():
    """Functions that would make K on slab + functions singular (here each function given twice) are dropped by the
    slab's own check, one of each pair: the approximation of W is the one with each function once (the copies kept
    may be either of a pair, so H is the same up to the order of its last columns)."""
    fem, B = strip(31, 12)
    far = body_far_functions(fem)
    twice = factorization.slab(fem.K, B, twice_each(far))
    once = factorization.slab(fem.K, B, far)
    clamped = factorization.slab(fem.K, B)
    assert once.H.shape[0] > clamped.H.shape[0]
    assert twice.H.shape == once.H.shape

    def delassus(approximation):
        return approximation.G @ spla.spsolve(approximation.H.tocsc(), approximation.G.T.toarray())

    assert np.abs(delassus(twice) - delassus(once)).max() <= 1e-10 * np.abs(delassus(once)).max()


def test_the_slab_factorizes_no_block_of_functions(monkeypatch):
    """The functions kept are definite in K's energy by :func:`independent`'s own factorization (every pivot above
    INDEPENDENT; the functions given twice too): the slab factorizes nothing more (before, the kept block once
    again), and K on slab + functions is definite."""
    fem, B = strip(31, 12)
    far = body_far_functions(fem)
    factorized = []
    monkeypatch.setattr(factorization, "factorize", lambda *args, **kwargs: factorized.append(args))
    for coarse in (far, twice_each(far)):
        approximation = factorization.slab(fem.K, B, coarse)
        assert approximation.H.shape[0] > approximation.slab
        eigenvalues = la.eigvalsh(approximation.H.toarray())
        assert eigenvalues.min() > 1e-12 * eigenvalues.max()
    assert not factorized


@pytest.mark.parametrize("backend", ["pardiso", "superlu"])
def test_refactorize_solves_with_the_new_values(backend):
    """New values on the first matrix's pattern (part of it): the same answers as a fresh factorization; an entry
    outside the pattern is refused."""
    if backend == "pardiso" and factorization._pardiso() is None:
        pytest.skip("PARDISO does not load here")
    rng = np.random.default_rng(1)
    fem, _ = strip(21, 6)
    K = fem.K.tocsr()
    factors = factorize(K, backend)
    scaled = sp.diags(rng.uniform(0.5, 2.0, K.shape[0]))
    changed = (scaled @ K @ scaled).tocsr()
    changed.setdiag(changed.diagonal() * 1.5)
    factors.refactorize(changed)
    b = rng.standard_normal(K.shape[0])
    np.testing.assert_allclose(changed @ factors.solve(b), b, atol=1e-9 * np.abs(b).max())
    outside = changed + sp.csr_matrix(([1.0, 1.0], ([0, K.shape[0] - 1], [K.shape[0] - 1, 0])), shape=K.shape)
    with pytest.raises(ValueError, match="outside the pattern"):
        factors.refactorize(outside)


@pytest.mark.parametrize("dim, nodes, dofs, law", [
    (2, 41, 2e3, Signorini()),
    (2, 41, 2e3, Tresca(slip_bound=0.002)),
    (3, 36, 8e2, Tresca(slip_bound=0.002)),
])
def test_exact_approximation_leaves_each_newton_system_a_few_iterations(dim, nodes, dofs, law):
    """With the approximation W itself (slab = the body), a friction dual's Newton systems get the exact inverse
    of that system up to the shift δ (a Signorini dual's the restriction of W's, near it on a whole face): a few
    Krylov iterations a Newton system (a step's and its grown faces', GROW; the first solved to FIRST_FORCING), where
    a wrong restriction of the approximation to the step's variables (and curvature) would leave many; the answer is
    the operator's."""
    model = cc.prepare(whole_face(dim, nodes, dofs, law), "dual-matrix-free")
    P = model.program.P
    exact = Delassus(P.B, P._solve, Approximation(P.B, model.fem.K.tocsr(), factorization.factorize_sum))
    answer = solvers.solve(replace(model.program, P=exact), "newton-cg")
    reference = solvers.solve(model.program, "newton-cg")
    assert answer.status == "solved" and reference.status == "solved"
    assert answer.info["cg_iterations"] <= 4 * (answer.iterations + answer.info["grown"])
    assert np.abs(answer.x - reference.x).max() < 1e-9 * np.abs(reference.x).max()


def test_preconditioner_pattern_holds_every_newton_system():
    """The pattern ordered once holds H + Gᵣᵀ D⁻¹ Gᵣ for any free set and sphere: refactorized on random ones."""
    rng = np.random.default_rng(3)
    model = cc.prepare(whole_face(3, 25, 6e2, Tresca(slip_bound=0.002)), "dual-matrix-free")
    program = model.program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    preconditioner = newton_cg._Preconditioner(program.P.approximation, sets.scale, sets.balls, 1e-3)
    n = program.n_variables
    for _ in range(3):
        held = rng.random(n) < 0.4
        sphere = rng.random(sets.balls.shape[0]) < 0.5
        held[sets.balls[sphere].ravel()] = True
        bases = newton_cg.tangent_bases(rng.standard_normal((sphere.sum(), sets.balls.shape[1])))
        R = newton_cg._expansion(n, np.flatnonzero(~held), sets.balls[sphere], bases)
        curvature = np.concatenate([np.zeros((~held).sum()), rng.uniform(0, 1, R.shape[1] - (~held).sum())])
        apply = preconditioner.system(R, curvature)
        G = (sp.diags(sets.scale) @ program.P.approximation.G).toarray()
        M = R.T @ G @ np.linalg.solve(program.P.approximation.H.toarray(), G.T @ R.toarray())
        xi = rng.standard_normal(R.shape[1])
        expected = np.linalg.solve(M + np.diag(1e-3 + curvature), xi)
        np.testing.assert_allclose(apply(xi), expected, rtol=1e-8, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("dim, nodes, dofs", [(2, 41, 2e3), (3, 36, 8e2)])
def test_newton_cg_preconditioner_on_superlu(monkeypatch, dim, nodes, dofs):
    """Without PARDISO the slab's factors are SuperLU's, factorized anew each Newton step (no numeric-only
    refactorization): the same answer as with the default backend."""
    scene = whole_face(dim, nodes, dofs, Tresca(slip_bound=0.002))
    reference = cc.prepare(scene, "dual-matrix-free").solve("newton-cg")
    monkeypatch.setattr(factorization, "_pardiso", lambda: None)
    answer = cc.prepare(scene, "dual-matrix-free").solve("newton-cg")
    assert answer.status == "solved" and answer.certificate.worst < 1e-10
    scale = np.abs(reference.contact.pressure).max()
    np.testing.assert_allclose(answer.contact.pressure, reference.contact.pressure, atol=1e-9 * scale)
    np.testing.assert_allclose(answer.contact.friction, reference.contact.friction, atol=1e-9 * scale)


def test_thin_body_is_its_own_approximation():
    """A body so thin that one layer beyond its face is over a third of it gets no coarse functions: it is its own
    approximation (a clamped slab misses a thin strip's bending), whose eigenvalues against W are all 1."""
    fem, B = strip(61, 2)
    called = []
    thin = factorization.slab(fem.K, B, lambda inside, contact: called.append(1))
    assert not called and thin.H.shape[0] == fem.n_free
    W = B @ factorize(fem.K).solve(B.T.toarray())
    np.testing.assert_allclose(delassus_eigenvalues(thin, 0.5 * (W + W.T)), 1.0, rtol=1e-8)


def test_the_frictionless_start_and_a_sweep_reuse_the_friction_slab(monkeypatch):
    """Coulomb's frictionless start solves the leading rows of the friction program's B = [C N; R T]: its operator
    and slab approximation are those of the friction program with G's first rows, so one slab is built per solve,
    and none for a sweep's next coefficient; the answers are certified and equal to those with a slab of their own."""
    built = []
    slab = factorization.slab
    monkeypatch.setattr(factorization, "slab", lambda K, B, *more: built.append(B.shape) or slab(K, B, *more))
    model = cc.prepare(whole_face(2, 201, 2e4, law=cc.Coulomb(friction=0.3)), "dual-matrix-free")
    result = model.solve()
    assert result.status == "solved" and result.certificate.worst < 1e-10 and len(built) == 1
    swept = model.with_law(cc.Coulomb(friction=0.4)).solve()
    assert swept.status == "solved" and swept.certificate.worst < 1e-10 and len(built) == 1
    fresh = cc.prepare(whole_face(2, 201, 2e4, law=cc.Coulomb(friction=0.4)), "dual-matrix-free").solve()
    assert np.abs(swept.contact.pressure - fresh.contact.pressure).max() < 1e-8 * fresh.max_pressure
