"""Large contact zones: the matrix-free dual (W = B K⁻¹ Bᵀ through K's factors) and newton-cg, against
Clarabel on the dense program, judged by the certificate."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact import cli, solvers
from convexcontact.conic import ConicProgram, nonnegative, soc, zero
from convexcontact.drivers import rules
from convexcontact.fem import factorization
from convexcontact.fem.factorization import factorize
from convexcontact.formulations import contact_weights
from convexcontact.scene.description import Coulomb, Signorini, Tresca
from convexcontact.scene.library import hertz_punch, punch_3d, tresca_punch, whole_face


def random_program(rng, bounds: int, balls: int, size: int, operator: bool = False) -> ConicProgram:
    """min ½xᵀPx + qᵀx over x_j ≥ lower_j (rows −x_j ≤ −lower_j) and ‖c_k − x_k‖ ≤ ρ_k, P random SPD."""
    n = bounds + balls * size
    G = rng.standard_normal((n, n))
    P = G @ G.T / n + 0.05 * np.eye(n)
    rows, b, cones = [-sp.eye(bounds, n)], [rng.uniform(-0.5, 0.5, bounds)], [nonnegative(bounds)]
    for k in range(balls):
        start = bounds + k * size
        rows.append(sp.vstack([sp.csr_matrix((1, n)), sp.eye(size, n, start)]))
        b.append(np.concatenate([[rng.uniform(0.1, 1.0)], rng.uniform(-0.2, 0.2, size)]))
        cones.append(soc(1 + size))
    return ConicProgram(spla.aslinearoperator(P) if operator else sp.csc_matrix(P), rng.standard_normal(n),
                        sp.vstack(rows).tocsc(), np.concatenate(b), tuple(cones))


def kkt_residual(program: ConicProgram, solution) -> float:
    """Stationarity P x + q + Aᵀz = 0, with P applied as given."""
    gradient = spla.aslinearoperator(program.P).matvec(solution.x) + program.q + program.A.T @ solution.z
    return np.abs(gradient).max()


@pytest.mark.parametrize("bounds, balls, size", [(30, 0, 1), (15, 15, 1), (10, 12, 2)])
def test_newton_cg_agrees_with_clarabel_on_random_programs(bounds, balls, size):
    """Bounds, intervals (2-D friction) and discs (3-D friction): the same optimum as Clarabel, P as a matrix
    or as an operator, and a KKT point (stationary, z in the dual cone)."""
    rng = np.random.default_rng(bounds + 7 * balls + size)
    dense = random_program(rng, bounds, balls, size)
    reference = solvers.solve(dense, "clarabel")
    for program in (dense, ConicProgram(spla.aslinearoperator(dense.P.toarray()), dense.q, dense.A, dense.b,
                                        dense.cones)):
        answer = solvers.solve(program, "auto" if solvers.matrix_free(program) else "newton-cg")
        assert answer.solver == "newton-cg" and answer.status == "solved"
        assert np.abs(answer.x - reference.x).max() < 1e-8
        assert kkt_residual(program, answer) < 1e-10
        assert answer.z[:bounds].min() > -1e-12
        radius = answer.z[bounds::1 + size]
        assert (radius >= np.linalg.norm(answer.z[bounds:].reshape(-1, 1 + size)[:, 1:], axis=1) - 1e-12).all()


@pytest.mark.parametrize("law, most_steps", [(Signorini(), 8), (Tresca(0.002), 100)])
def test_newton_cg_steps_scale_with_the_rows_of_a_dense_w(law, most_steps):
    """The dense W of a mortar pair on graded meshes (rows differ in scale): with a step length per variable
    newton-cg agrees with Clarabel, Signorini in a few Newton steps (29 with one length), Tresca at all (it
    failed after 100)."""
    model = cc.prepare(cc.bodies_library.punch_on_foundation(0.01, law=law), "dual")
    newton, interior = model.solve("newton-cg"), model.solve("clarabel")
    assert newton.status == "solved" and newton.iterations <= most_steps and newton.certificate.worst < 1e-10
    p = interior.contact.pressure.max()
    np.testing.assert_allclose(newton.contact.pressure, interior.contact.pressure, atol=1e-8 * p)
    if law != Signorini():
        np.testing.assert_allclose(newton.contact.friction, interior.contact.friction, atol=1e-8 * p)


def test_delassus_operator_is_the_dense_w():
    """W r and W R through K's factors equal the dense W = B K⁻¹ Bᵀ; the slab approximation over the whole body
    is W itself."""
    fem = cc.prepare(whole_face(2, 41, 2e3), "primal").fem
    B = (contact_weights(fem.contact, "nodal") @ fem.contact.N).tocsr()
    factors = factorize(fem.K)
    W, operator = factors.schur(B), factors.delassus(B, fem.K)
    R = np.random.default_rng(0).standard_normal((B.shape[0], 3))
    assert np.abs(operator @ R[:, 0] - W @ R[:, 0]).max() < 1e-12 * np.abs(W).max()
    assert np.abs(operator @ R - W @ R).max() < 1e-12 * np.abs(W).max()
    assert operator.approximation.H.shape[0] < fem.n_free  # a slab, not the body


def test_whole_slab_approximation_is_exact(monkeypatch):
    monkeypatch.setattr(factorization, "SLAB", 1.0)
    monkeypatch.setattr(factorization, "LAYERS", 10**6)
    fem = cc.prepare(whole_face(2, 21, 6e2), "primal").fem
    B = (contact_weights(fem.contact, "nodal") @ fem.contact.N).tocsr()
    slab = factorization.slab(fem.K, B)
    assert slab.H.shape == fem.K.shape
    approximate = slab.G @ slab.factorize(slab.H).solve(slab.G.T.toarray())
    W = factorize(fem.K).schur(B)
    assert np.abs(approximate - W).max() < 1e-12 * np.abs(W).max()


@pytest.mark.parametrize("dim, nodes, dofs, law", [
    (2, 81, 3e3, Signorini()),
    (2, 81, 3e3, Tresca(slip_bound=0.002)),
    (3, 49, 6e2, Tresca(slip_bound=0.002)),
])
def test_matrix_free_dual_agrees_with_the_dense_dual(dim, nodes, dofs, law):
    """The same contact dual, dense with Clarabel and matrix-free with newton-cg: the same pressures and
    friction, both certified to 1e-10 from the recovered fields."""
    scene = whole_face(dim, nodes, dofs, law)
    dense = cc.prepare(scene, "dual").solve("clarabel")
    model = cc.prepare(scene, "dual-matrix-free")
    assert solvers.matrix_free(model.program) and model.formulation == "dual"
    scalable = model.solve()
    assert scalable.solver == "newton-cg" and scalable.status == "solved"
    assert scalable.certificate.worst <= 1e-10 and dense.certificate.worst <= 1e-10
    scale = np.abs(dense.contact.pressure).max()
    assert np.abs(scalable.contact.pressure - dense.contact.pressure).max() < 1e-8 * scale
    if isinstance(law, Tresca):
        friction = dense.contact.friction
        assert np.abs(scalable.contact.friction - friction).max() < 1e-8 * scale
        assert 0 < np.mean(np.abs(friction).max(axis=-1) if friction.ndim > 1 else np.abs(friction)) < np.inf


def test_coulomb_picard_over_newton_cg():
    """Coulomb by Picard over matrix-free Tresca programs: the dense answer."""
    scene = whole_face(2, 61, 2e3, Coulomb(friction=0.3))
    dense = cc.prepare(scene, "dual").solve("clarabel")
    scalable = cc.prepare(scene, "dual-matrix-free").solve()
    assert scalable.solver == "newton-cg" and scalable.status == "solved"
    scale = np.abs(dense.contact.pressure).max()
    assert np.abs(scalable.contact.pressure - dense.contact.pressure).max() < 1e-6 * scale


def test_programs_not_in_bound_form_are_refused():
    rng = np.random.default_rng(3)
    program = random_program(rng, 6, 0, 1)
    coupled = ConicProgram(program.P, program.q, sp.csc_matrix(np.ones((1, 6))), np.ones(1), (nonnegative(1),))
    with pytest.raises(ValueError, match="bound form"):
        solvers.solve(coupled, "newton-cg")
    equality = ConicProgram(program.P, program.q, sp.vstack([sp.csr_matrix(np.ones((1, 6))), program.A]).tocsc(),
                            np.concatenate([[1.0], program.b]), (zero(1), *program.cones))
    with pytest.raises(ValueError, match="equality"):
        solvers.solve(equality, "newton-cg")
    with pytest.raises(ValueError, match="no such setting"):
        solvers.solve(program, "newton-cg", max_threads=1)
    operator = ConicProgram(spla.aslinearoperator(program.P), program.q, program.A, program.b, program.cones)
    with pytest.raises(ValueError, match="operator"):
        solvers.solve(operator, "clarabel")


def test_auto_condenses_densely_only_onto_columns_that_fit(monkeypatch):
    """A pair condenses onto slave and master DOFs: few unknowns can mean many columns (the two-body bench at
    1.4e6 DOFs ran out of memory with 9816 unknowns, 34,762 columns). Beyond COLUMN_LIMIT, no dense W."""
    scene = cc.bodies_library.punch_on_foundation(0.05)
    assert cc.prepare(scene).formulation == "dual"
    columns = rules.contact_columns(cc.prepare(scene, "primal").fem).size
    monkeypatch.setattr(rules, "COLUMN_LIMIT", columns - 1)
    model = cc.prepare(scene)
    assert model.formulation == "dual" and solvers.matrix_free(model.program)
    assert f"the {columns} DOFs to condense onto exceed {columns - 1}" in model.reason
    forced = cc.prepare(cc.scene.library.hertz_punch(20))  # a force-controlled obstacle: no bound form
    monkeypatch.setattr(rules, "COLUMN_LIMIT", 1)
    assert cc.prepare(cc.scene.library.hertz_punch(20)).formulation == "primal" != forced.formulation


def test_auto_applies_w_matrix_free_beyond_matrix_free_columns(monkeypatch):
    """Where the matrix-free dual applies, a dense W is formed only onto MATRIX_FREE_COLUMNS columns (the 2-D pair at
    2.8e5 DOFs, 7,084 columns, was slower and 3× the memory densely); a force-controlled obstacle, which has no bound
    form, keeps its dense W up to COLUMN_LIMIT."""
    scene = cc.bodies_library.punch_on_foundation(0.05)
    columns = rules.contact_columns(cc.prepare(scene, "primal").fem).size
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", columns)
    assert not solvers.matrix_free(cc.prepare(scene).program)
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", columns - 1)
    model = cc.prepare(scene)
    assert solvers.matrix_free(model.program) and f"exceed {columns - 1}" in model.reason
    result = model.solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-10
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", 1)
    forced = cc.prepare(cc.scene.library.hertz_punch(20))
    assert forced.formulation == "dual" and not solvers.matrix_free(forced.program)


def test_auto_goes_matrix_free_for_large_closed_zones(monkeypatch):
    """The rule, not the timing: beyond CLOSED_LIMIT unknowns at closed nodes (or DENSE_LIMIT in all) auto applies
    W through K's factors and says why; a punch closing few nodes keeps the dense W; a force-controlled obstacle
    (an equality) is not in newton-cg's bound form and keeps the primal beyond DENSE_LIMIT."""
    scene = whole_face(2, 41, 1e3, Tresca(slip_bound=0.002))
    assert cc.prepare(scene).formulation == "dual" and not solvers.matrix_free(cc.prepare(scene).program)
    monkeypatch.setattr(rules, "CLOSED_LIMIT", 50)
    model = cc.prepare(scene)
    assert solvers.matrix_free(model.program) and "closed nodes exceed 50" in model.reason
    result = model.solve()
    assert result.solver == "newton-cg" and "never formed" in result.extra["formulation_reason"]
    punch = cc.prepare(cc.library.tresca_punch(nx=80))  # 81 contact nodes, 162 unknowns, a few closed
    assert punch.formulation == "dual" and not solvers.matrix_free(punch.program)
    monkeypatch.setattr(rules, "DENSE_LIMIT", 100)
    assert solvers.matrix_free(cc.prepare(cc.library.tresca_punch(nx=80)).program)
    forced = cc.prepare(cc.library.hertz_punch(nx=120))
    assert forced.formulation == "primal" and "force-controlled" in forced.reason


def test_auto_goes_matrix_free_for_large_3d_bodies_with_many_contact_dofs(monkeypatch):
    """The rule, not the timing: a 3-D body over DENSE_DOFS_3D DOFs whose contact DOFs are over MATRIX_FREE_COLUMNS is
    not condensed (in 3-D the Schur complement costs more than a factorization), even where the saddle would form W by
    its fewer rows, but solved matrix-free, with the reason said, to the dense dual's answer. With as few contact DOFs
    as its dense dual costs less for (the tall block at 10⁵ DOFs, Coulomb: 5.16 → 1.42 end to end) it keeps its dense
    W; a 2-D body of as many DOFs keeps it too, and so does a force-controlled 3-D obstacle (no bound form)."""
    scene = punch_3d(cells=6, law=Signorini())
    dense = cc.prepare(scene)
    columns, rows = rules.contact_columns(dense.fem).size, dense.program.P.shape[0]
    assert dense.formulation == "dual" and not solvers.matrix_free(dense.program) and rows < columns
    monkeypatch.setattr(rules, "DENSE_DOFS_3D", dense.fem.n_free - 1)
    assert not solvers.matrix_free(cc.prepare(scene).program)  # contact DOFs under MATRIX_FREE_COLUMNS
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)  # W would come from the saddle: its cost its rows'
    limit = rules.MATRIX_FREE_COLUMNS
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", columns - 1)
    model = cc.prepare(scene)
    assert solvers.matrix_free(model.program) and "costs more to condense onto its" in model.reason
    result, expected = model.solve(), dense.solve("clarabel")
    assert result.solver == "newton-cg" and result.status == "solved" and result.certificate.worst < 1e-10
    assert np.abs(result.contact.pressure - expected.contact.pressure).max() < 1e-8 * expected.max_pressure
    pushed = cc.Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0), force=0.01)
    forced = cc.prepare(dataclasses.replace(scene, contact=dataclasses.replace(scene.contact, obstacle=pushed)))
    assert not solvers.matrix_free(forced.program)
    monkeypatch.setattr(rules, "DENSE_DOFS_3D", 10)
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", limit)
    assert not solvers.matrix_free(cc.prepare(tresca_punch(nx=30)).program)


def test_whole_face_bench_row_says_what_auto_chose(tmp_path, monkeypatch):
    from convexcontact.cli import main
    from convexcontact.studies.benchmarks import bench

    row = bench.measure(2, "tresca", 2000, "dual-matrix-free", "auto", "whole-face", 41)
    assert (row["scenario"], row["formulation"], row["solver"], row["status"]) == (
        "whole-face", "dual-matrix-free", "newton-cg", "solved")
    assert row["contact_nodes"] == 41 and row["certificate"] <= 1e-10 and row["ratio"] > 0
    # the assembly on both sides pulls the end-to-end ratio towards 1 from the contact-only ratio's side
    assert min(1.0, row["ratio"]) <= row["end_to_end"] <= max(1.0, row["ratio"])
    assert main(["bench", "--scenario", "whole-face", "--sizes", "2000", "--nodes", "41", "--laws", "signorini",
                 "--out", str(tmp_path)]) == 0
    assert (tmp_path / "bench_2d_whole-face.csv").read_text().count("\n") == 2


def test_auto_seeds_the_dense_friction_dual_only():
    """solver 'auto' keeps the frictionless seed of the dense dual (Clarabel), not of the matrix-free one."""
    dense = cc.prepare(whole_face(2, 41, 1e3, Tresca(slip_bound=0.002)), "dual").program
    operator = cc.prepare(whole_face(2, 41, 1e3, Tresca(slip_bound=0.002)), "dual-matrix-free").program
    assert solvers.seedable("auto", {}, dense) and solvers.seedable("clarabel", {})
    assert not solvers.seedable("auto", {}, operator) and not solvers.seedable("newton-cg", {})


def test_a_failed_matrix_free_solve_that_auto_chose_gives_way_to_the_primal(monkeypatch):
    """newton-cg converges but may stop at max_iter (a slow rate): when it fails on the dual auto chose, the sparse primal answers
    (the same answer as a direct primal solve) and the reason says so; a formulation the user named is kept."""
    from convexcontact.conic import ConicSolution
    from convexcontact.solvers import newton_cg

    scene = whole_face(2, 41, 1e3, Tresca(slip_bound=0.002))
    monkeypatch.setattr(rules, "CLOSED_LIMIT", 50)

    def fails(self):
        n, m = self.program.n_variables, self.program.n_constraints
        return ConicSolution(x=np.zeros(n), z=np.zeros(m), s=np.zeros(m), status="failed",
                             solver_status="MaxIterations", iterations=100, solve_time=0.0, solver="newton-cg")

    monkeypatch.setattr(newton_cg.Session, "solve", fails)
    result = cc.solve(scene)
    primal = cc.prepare(scene, "primal").solve()
    assert result.status == "solved" and result.formulation == "primal" and result.solver == "clarabel"
    assert "newton-cg failed (MaxIterations)" in result.extra["formulation_reason"]
    assert np.abs(result.displacement - primal.displacement).max() < 1e-9 * np.abs(primal.displacement).max()
    assert cc.prepare(scene, "dual-matrix-free").solve().status == "failed"


@pytest.mark.parametrize("scene", [
    tresca_punch(nx=30), tresca_punch(nx=30).with_law(Signorini()),
    punch_3d(cells=6, law=Tresca(slip_bound=0.002)),
])
def test_auto_answers_a_dense_dual_by_newton_cg_as_clarabel_does(scene):
    """auto tries newton-cg first on a dense dual in its bound form: its answer is Clarabel's (an interior point on
    the same program) and certified, and the result says which solver answered and why."""
    model = cc.prepare(scene, "dual")
    auto, clarabel = model.solve(), model.solve("clarabel")
    assert auto.solver == "newton-cg" and auto.extra["solver_reason"] == rules.DENSE_NEWTON
    assert rules.DENSE_NEWTON in cli.table(auto) and "solver choice" not in cli.table(clarabel)
    assert auto.status == clarabel.status == "solved" and auto.certificate.worst < 1e-10
    assert np.abs(auto.displacement - clarabel.displacement).max() < 1e-8 * np.abs(clarabel.displacement).max()
    assert np.abs(auto.contact.pressure - clarabel.contact.pressure).max() < 1e-8 * clarabel.max_pressure


def test_a_failed_dense_newton_gives_way_to_clarabel(monkeypatch):
    """Where newton-cg fails on the dense dual, Clarabel answers the same program and the result says why; a
    force-controlled obstacle (an equality, no bound form) and a user's options go to Clarabel at once."""
    from convexcontact.conic import ConicSolution
    from convexcontact.solvers import newton_cg

    model = cc.prepare(tresca_punch(nx=30), "dual")
    expected = model.solve("clarabel")

    def fails(self):
        n, m = self.program.n_variables, self.program.n_constraints
        return ConicSolution(x=np.zeros(n), z=np.zeros(m), s=np.zeros(m), status="failed",
                             solver_status="max_iter", iterations=100, solve_time=0.0, solver="newton-cg")

    monkeypatch.setattr(newton_cg.Session, "solve", fails)
    result = model.solve()
    assert result.status == "solved" and result.solver == "clarabel"
    assert result.extra["solver_reason"] == "newton-cg max_iter after 100 Newton steps on the dense dual, so Clarabel"
    assert np.abs(result.displacement - expected.displacement).max() <= 1e-12 * np.abs(expected.displacement).max()
    monkeypatch.undo()
    forced = cc.prepare(hertz_punch(30, law=Tresca(slip_bound=0.002)), "dual").solve()
    assert forced.solver == "clarabel" and "solver_reason" not in forced.extra
    assert model.solve(tol=1e-9).solver == "clarabel"


def test_auto_gives_newton_cg_a_bounded_number_of_steps_on_a_dense_dual(monkeypatch):
    """newton-cg has DENSE_NEWTON_STEPS Newton steps on a dense dual before Clarabel answers (a wandering Newton
    costs at most those): held to 1, the pair's Tresca dual at 10⁴ DOFs (3 steps) goes to Clarabel, whose answer is
    certified (the punch's, used before, takes 1 step since a step's faces are the natural map's at Newton's point,
    newton_cg.GROW)."""
    from convexcontact.studies.benchmarks.bench import two_body_scene

    monkeypatch.setattr(rules, "DENSE_NEWTON_STEPS", 1)
    result = cc.prepare(two_body_scene("tresca", 1e4), "dual").solve()
    assert result.status == "solved" and result.solver == "clarabel" and result.certificate.worst < 1e-10
    assert result.extra["solver_reason"] == "newton-cg max_iter after 1 Newton steps on the dense dual, so Clarabel"


def test_newton_cg_on_a_sparse_p_agrees_with_clarabel():
    """A P that is mostly zeros (banded SPD) keeps its Newton systems formed sparse, not as an n² array, and
    newton-cg reaches Clarabel's optimum, with discs (Cholesky steps on the spheres' tangents)."""
    from dataclasses import replace

    from convexcontact.solvers import newton_cg

    program = random_program(np.random.default_rng(5), 20, 10, 2)
    n = program.n_variables
    banded = sp.diags([np.full(n - 1, -1.0), np.full(n, 4.0), np.full(n - 1, -1.0)], [-1, 0, 1], format="csc")
    program = replace(program, P=banded)
    assert sp.issparse(newton_cg._scaled(banded, np.ones(n)))
    reference, answer = solvers.solve(program, "clarabel"), solvers.solve(program, "newton-cg")
    assert answer.status == "solved" and np.abs(answer.x - reference.x).max() < 1e-8
    assert kkt_residual(program, answer) < 1e-10


def test_newton_cg_solves_the_dense_two_body_tresca_dual_by_the_projection_arc(monkeypatch):
    """The bench's two-body Tresca dual (a mortar pair on graded meshes; at 10⁵ DOFs 1434 unknowns): the least f on
    the segment to Newton's point left the residual wandering for 100 steps, and auto paid them before Clarabel. With
    the projection arc newton-cg converges well within auto's DENSE_NEWTON_STEPS, to Clarabel's answer, certified;
    without it (ARC = 0) it does not — from 7·10⁴ DOFs (below, the plain segment converged: 25–32 steps at 1–4·10⁴),
    the size taken here (10⁵ took 50 s of the suite, 7·10⁴ a tenth). Newton's points on grown faces (GROW) converge
    here in 9 steps, 8 without the arc; without them the arc is what converges (38 steps), and without both the face
    step (newton_cg.FACE), as checked."""
    from convexcontact.solvers import newton_cg
    from convexcontact.studies.benchmarks.bench import two_body_scene

    model = cc.prepare(two_body_scene("tresca", 7e4), "dual")
    auto, clarabel = model.solve(), model.solve("clarabel")
    assert auto.solver == "newton-cg" and auto.iterations < rules.DENSE_NEWTON_STEPS
    assert auto.status == clarabel.status == "solved" and auto.certificate.worst < 1e-10
    assert np.abs(auto.displacement - clarabel.displacement).max() < 1e-8 * np.abs(clarabel.displacement).max()
    assert np.abs(auto.contact.pressure - clarabel.contact.pressure).max() < 1e-8 * clarabel.max_pressure
    monkeypatch.setattr(newton_cg, "GROW", 0)
    assert model.solve("newton-cg", max_iter=rules.DENSE_NEWTON_STEPS).status == "solved"
    monkeypatch.setattr(newton_cg, "ARC", 0)
    assert model.solve("newton-cg", max_iter=rules.DENSE_NEWTON_STEPS).status == "solved"  # the face step (FACE)
    monkeypatch.setattr(newton_cg, "FACE", False)
    assert model.solve("newton-cg", max_iter=rules.DENSE_NEWTON_STEPS).status != "solved"
