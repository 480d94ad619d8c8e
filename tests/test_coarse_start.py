"""A solve from no start with P an operator that carries an approximation first solves the program restricted to
aggregates of neighbouring sets, and starts from that answer (solvers/newton_cg.py, COARSE_SETS): the first step's faces
then move the fronts of the opening and slip zones within an aggregate instead of finding them a front at a time."""

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def solved(monkeypatch, scene, formulation):
    """The model's result and newton-cg's top-level solves (not the coarse program's)."""
    solves, depth = [], [0]
    solve = newton_cg.newton_cg

    def wrapped(*args, **kwargs):
        depth[0] += 1
        try:
            solution = solve(*args, **kwargs)
        finally:
            depth[0] -= 1
        if not depth[0]:
            solves.append(solution)
        return solution

    monkeypatch.setattr(newton_cg, "newton_cg", wrapped)
    model = cc.prepare(scene, formulation)
    return model.solve(), solves


@pytest.mark.parametrize("coarse", [True, False])
def test_the_pair_s_tresca_dual_from_the_coarse_answer(monkeypatch, coarse):
    """2·10⁴ DOFs, forced matrix-free (148 nodes; 52 of 148 bounds at 0 at the projected gradient's point): from no
    start 5 Newton steps, 97 products and 12 refactorizations of the preconditioner; from the answer restricted to 64 +
    64 aggregates 3 steps and 72 products (the coarse program's included), 5 refactorizations in all; 96 and 70 since
    W's known diagonal spares each newton-cg call its curvature probe, 95 and 68 since ∇f at x = 0 is q, 67 since the
    coarse program stops without a fresh sum, 90 and 63 since a step on the face the last one ended on starts from the
    gradient it ended with, 62 since ∇f at the coarse answer comes from the coarse solve's products
    (tests/test_products.py); 40 and 3 refactorizations in all since the coarse program starts from its approximation's
    answer (newton_cg._approximated: 45 → 20 coarse products), the same 3 fine steps; 39 and 89 since the last step's
    updates stand for a fresh ∇f at the answer (newton_cg._fresh_enough), 38 and 88 since they may start a step."""
    if not coarse:
        monkeypatch.setattr(newton_cg, "COARSE_SETS", 10**9)  # the sets too few: before
    result, [solution] = solved(monkeypatch, scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free")
    assert result.solved and result.certificate.worst <= 1e-10
    info = solution.info
    assert (info["coarse"] is not None) == coarse
    refactorized = info["factorizations"] + (info["coarse"] or {}).get("factorizations", 0)
    assert (solution.iterations, info["products"], refactorized) == ((3, 38, 3) if coarse else (5, 88, 12))


def test_no_coarse_program_where_the_loads_alone_open_no_aggregate(monkeypatch):
    """The clamped strip 20 : 1 (10⁵ DOFs, Tresca, auto: matrix-free, 1001 nodes) is all in contact: the projected
    gradient's point holds 2 bounds at 0 (by the clamps), fewer than an aggregate's 16, so no coarse program (it cost
    10 products there, 17 → 27, and left the fine path as it was; 16 since ∇f at x = 0 is q, 15 since the second step
    starts from the gradient the first ended with, tests/test_products.py; 14 since the second step's updates stand
    for a fresh ∇f at the answer, newton_cg._fresh_enough)."""
    result, [solution] = solved(monkeypatch, scene_of("strip-clamped-20", 2, "tresca", 1e5), "auto")
    assert result.solved and solution.info["coarse"] is None
    assert result.certificate.worst <= 1e-10 and solution.info["products"] == 14


def test_the_coarse_answer_is_feasible_and_constant_on_aggregates():
    """The restriction x = Q x_c copies each coarse set to its aggregate, with the least radius: the start lies in the
    fine program's sets (bounds ≥ 0, |λ_T| ≤ s for every point) and takes few distinct values."""
    model = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free")
    program = model.program
    form = newton_cg.bound_form_of(program)
    sets = newton_cg._bounds(program, form)
    radius = sets.radius * np.linspace(0.5, 1.5, sets.radius.size)  # radii that differ inside an aggregate
    b = program.b.copy()
    b[form.ball_radius_rows] = radius
    program = program.updated(b=b)
    sets = newton_cg._bounds(program, form)
    v = np.zeros(program.n_variables)  # every bound at 0: a zone to find
    start = newton_cg._coarse_start(program, sets, v, 100, False)
    assert start is not None
    x, info, _ = start
    assert info["steps"] < 100  # solved: not stopped at max_iter
    assert (x[form.bound_vars] >= 0).all()
    assert (np.abs(x[form.ball_vars[:, 0]]) <= radius * (1 + 1e-12)).all()
    assert np.unique(x[form.bound_vars]).size <= newton_cg.COARSE_SETS


def test_the_coarse_program_starts_from_its_approximation_s_answer(monkeypatch):
    """The coarse program is solved from the answer of the same program with P its dense approximation
    (newton_cg._approximated), which takes no product with W: the faces it would find from no start, each a product at
    least, are mostly found there. The 2-D pair at 2·10⁴ DOFs forced matrix-free, Tresca, every bound at 0: 20 products
    against 66 to COARSE_TOL (53 before its released faces kept the empty face's factors, REUSE; 67 before a step's
    later grown faces stopped where its first kept one did, KEPT_FORCING), the two answers within 1.6·10⁻⁴ of the
    largest entry (the natural residual's tolerance times the coarse program's conditioning)."""
    program = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free").program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    v = np.zeros(program.n_variables)
    x, info, _ = newton_cg._coarse_start(program, sets, v, 100, False)
    monkeypatch.setattr(newton_cg, "_approximated", lambda *_: None)  # from no start: before
    x_before, info_before, _ = newton_cg._coarse_start(program, sets, v, 100, False)
    assert (info["products"], info_before["products"]) == (20, 66)
    assert np.abs(x - x_before).max() <= 100 * newton_cg.COARSE_TOL * np.abs(x_before).max()  # 1.6e-4 of it


def test_no_coarse_program_where_the_rows_form_no_line(monkeypatch):
    """The 3-D pair of spheres at 10⁵ DOFs, forced matrix-free (511 bounds; 16 breadth-first levels against 200 of
    717 on the 2-D pair at 10⁵): its opening zone is a few nodes across, and the coarse program cost more than it saved
    (Tresca 72 → 95 products, the same 5 Newton steps), so newton_cg.LINE leaves the path of no coarse start (71
    products since ∇f at x = 0 is q, 70 since a step may start from the gradient the last ended with, 69 since the
    stopping test takes no fresh ∇f where it has one, tests/test_products.py)."""
    result, [solution] = solved(monkeypatch, scene_of("two-body", 3, "tresca", 1e5), "dual-matrix-free")
    assert result.solved and result.certificate.worst <= 1e-10
    assert solution.info["coarse"] is None and (solution.iterations, solution.info["products"]) == (5, 69)
    program = cc.prepare(scene_of("two-body", 2, "tresca", 1e5), "dual-matrix-free").program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    G = program.P.approximation.G.tocsr()
    assert newton_cg._aggregates(G[sets.bounds], newton_cg.COARSE_SETS) is not None  # the 2-D face: a line


@pytest.mark.parametrize("pardiso", [True, False])
def test_the_coarse_approximation_is_g_h_inverse_g_t_from_one_factorization(monkeypatch, pardiso):
    """The coarse start's A = G H⁻¹ Gᵀ (G: the approximation's rows summed over aggregates) from PARDISO's Schur
    complement of [H Gᵀ; G 0] (or, without PARDISO, H's factors and a solve) equals an independent sparse solve."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from convexcontact.fem import factorization

    if not pardiso:
        monkeypatch.setattr(factorization, "_pardiso", lambda: None)
    model = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free")
    approximation = model.program.P.approximation
    m = approximation.G.shape[0]
    summed = sp.csr_matrix((np.ones(m), (np.arange(m) * 64 // m, np.arange(m))), shape=(64, m)) @ approximation.G
    expected = summed @ spla.spsolve(sp.csc_matrix(approximation.H), summed.T.toarray())
    reduced = approximation.reduced(summed)
    assert np.array_equal(reduced, reduced.T)
    np.testing.assert_allclose(reduced, expected, rtol=0, atol=1e-9 * np.abs(expected).max())


def test_the_signorini_coarse_program_to_its_own_tolerance_with_its_approximation_s_step_lengths(monkeypatch):
    """Bounds alone (Signorini): the coarse program stops at COARSE_BOUNDS_TOL (1e-3, not COARSE_TOL's 1e-5) and takes
    its approximated start's step lengths (newton_cg._approximated), not Hutchinson's product. The pair at 5·10⁴ DOFs
    forced matrix-free: 3 Newton steps, 29 products (12 the coarse program's) before, 22 (7) now, the fine path the
    same; the coarse answer from every bound at 0 within 3.3e-3 of its largest entry of the exact one's, 12 → 7
    products."""
    result, [solution] = solved(monkeypatch, scene_of("two-body", 2, "signorini", 5e4), "dual-matrix-free")
    assert result.solved and result.certificate.worst <= 1e-10
    assert (solution.iterations, solution.info["products"], solution.info["coarse"]["products"]) == (3, 22, 7)
    program = cc.prepare(scene_of("two-body", 2, "signorini", 5e4), "dual-matrix-free").program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    v = np.zeros(program.n_variables)
    x, info, _ = newton_cg._coarse_start(program, sets, v, 100, False)
    monkeypatch.setattr(newton_cg, "COARSE_BOUNDS_TOL", 1e-12)
    exact, _, _ = newton_cg._coarse_start(program, sets, v, 100, False)
    assert info["products"] == 7 and np.abs(x - exact).max() <= 1e-2 * np.abs(exact).max()
