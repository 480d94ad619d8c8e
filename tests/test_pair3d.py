"""The 3-D pair of spheres (mortar, quarter model; issue 25): its Tresca dual from the stick start the Coulomb solve
seeds it with, and its Coulomb problem at 10⁴ DOFs by Newton's method with moving radii. The nodes on the symmetry
planes now have the full model's normal and no friction along the planes' normals (exactly empty rows:
fem/contact.py, ``symmetry_planes``), and W on the rows that carry is regular. On the former trace (the fixture
``no_symmetry_planes``: those rows acting on almost nothing, W singular) not one Newton point was taken in 100 steps
without the damping of far Newton points (newton_cg.FAR, DAMPING), and without the inert sets' metric and proximal
term from a stall on (newton_cg.INERT) the Coulomb solve stalled on the axis node's rounding: those checks run there."""

import functools
from dataclasses import replace

import numpy as np
import pytest
from former_trace import without_symmetry_planes

import convexcontact as cc
from convexcontact.drivers import picard
from convexcontact.formulations.dual import normal_multipliers
from convexcontact.scene.bodies_library import two_spheres
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


@functools.cache
def stick_start_program(planes: bool = True):
    """The pair's model at 2·10³ DOFs (dense W) and its Tresca program under the frictionless pressures' slip bounds
    (``planes``: False on the former trace, a cache of its own)."""
    with pytest.MonkeyPatch.context() as patched:
        if not planes:
            without_symmetry_planes(patched)
        model = cc.prepare(scene_of("two-body", 3, "coulomb", 2e3), "dual")
    bound = picard.pressure_map(model)[0](picard.initial_pressure(model, "newton-cg", {}))
    return model, replace(model.program, **model.bound_update(bound))


def solve_from_the_stick_start(planes: bool = True):
    model, program = stick_start_program(planes)
    session = newton_cg.Session(program)
    model.seed(session, "newton-cg", {}, start={"tol": picard.START_TOL})
    return program, session.solve()


def objective(program, x: np.ndarray) -> float:
    return 0.5 * x @ (program.P @ x) + program.q @ x


def test_the_pairs_tresca_dual_is_solved_from_the_stick_start_as_clarabel_solves_it():
    """One Newton step (6 products; 8 and 31 on the former trace), and the least value of the dual that Clarabel finds
    (the values are compared, not the points: the empty rows' multipliers are any in their balls)."""
    program, solution = solve_from_the_stick_start()
    reference = cc.solvers.solve(program, "clarabel")
    assert solution.status == "solved" and solution.iterations <= 3
    assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-8)


def test_the_check_catches_newton_cg_without_the_damping():
    """On the former trace, without the damping (neither after a far Newton point nor after a projected-gradient step)
    and with a step's faces only grown by the sets Newton's point leaves (newton_cg.GROW, before the face at Newton's
    point) the same solve takes no Newton point and fails. The face at Newton's point alone solves it too (6 steps,
    26 products; with the damping 6 and 28). With the symmetry planes' rows empty it needs neither (1 step)."""
    with pytest.MonkeyPatch.context() as patched:
        patched.setattr(newton_cg, "_damped", lambda damping, far, refused, residual: 0.0)
        patched.setattr(newton_cg, "_released", lambda y, newton, g, c, sets, released: (
            newton_cg._grown(y, newton, sets, sets.radius), False))
        _, solution = solve_from_the_stick_start(planes=False)
        assert solution.status != "solved" and solution.info["steps"]["residual"] == 0


def test_the_symmetry_planes_rows_are_empty_and_w_on_the_rest_is_regular():
    """The axis node (on both planes) has no tangential rows, each other node on a plane none along its normal: 10 of
    75 unknowns, their multipliers reported 0. W on the rows that carry is regular (least eigenvalue 1.5e-5, 1e-3 of
    the largest). On the former trace those rows were a tilt of the normal rows: W's two null vectors (eigenvalues
    1e-19 against 1.5e-2) lay on the axis node's three multipliers, one of them moving its pressure too
    (docs/performance.md, "The pair's Coulomb row at 10⁴ DOFs")."""
    model, program = stick_start_program()
    contact, m = model.fem.contact, model.fem.contact.m
    held = contact.symmetric.reshape(2, m)
    axis = int(np.argmin(np.linalg.norm(contact.coords[:, :2], axis=1)))
    assert held[:, axis].all() and held.sum() == 10 and held.any(axis=0).sum() == 9
    assert np.diff(contact.T.indptr)[contact.symmetric].max() == 0  # no entries, not stored zeros
    W = program.P.toarray()
    carries = np.r_[np.ones(m, bool), ~contact.symmetric]
    assert not W[~carries].any()
    values = np.linalg.eigvalsh(W[np.ix_(carries, carries)])
    assert values[0] > 1e-4 * values[-1]
    solution = solve_from_the_stick_start()[1]
    assert not model.recover(solution).friction[contact.symmetric].any()
    former = stick_start_program(planes=False)[1].P.toarray()
    assert np.linalg.eigvalsh(former)[1] < 1e-14 * abs(former).max()


def coulomb_newton_at_ten_thousand_dofs():
    """The pair at 10⁴ DOFs (291 unknowns, dense W) and Newton's solve of its Coulomb problem from the stick start,
    as the Coulomb driver makes it."""
    model = cc.prepare(scene_of("two-body", 3, "coulomb", 1e4), "dual")
    session = newton_cg.Session(model.program)
    model.seed(session, "newton-cg", {}, start={})
    pressure_bound = picard.pressure_map(model)[2] @ normal_multipliers(model.program, model.C, model.fem.contact)
    return model, session.coupled(pressure_bound)


def coulomb_residual(model, solution) -> float:
    return picard.residual(model, model.recover(solution), solution.info["radii"])


def test_the_pairs_coulomb_problem_at_ten_thousand_dofs_is_solved_as_clarabel_solves_its_tresca_problem():
    """Solved to newton-cg's tol and certified to the law's 1e-8; its displacement is Clarabel's answer of the Tresca
    problem under the slip bounds Newton reached (unique in u: K is positive definite), to Clarabel's accuracy."""
    model, solution = coulomb_newton_at_ten_thousand_dofs()
    assert solution.status == "solved"
    assert coulomb_residual(model, solution) < 1e-8
    reference = cc.solvers.solve(replace(model.program, **model.bound_update(solution.info["radii"])), "clarabel")
    u, expected = model.recover(solution).u, model.recover(reference).u
    assert np.abs(u - expected).max() < 1e-6 * np.abs(expected).max()


def test_the_pairs_coulomb_problem_needs_no_inert_sets_with_the_symmetry_planes_rows_empty(monkeypatch):
    """2 Newton steps, 7 products (9 and 30 on the former trace), the same with no set inert: the inert sets were the
    axis node's, whose rows are now empty."""
    monkeypatch.setattr(newton_cg, "_inert", lambda c, tol: None)
    model, solution = coulomb_newton_at_ten_thousand_dofs()
    assert solution.status == "solved" and solution.iterations <= 3 and coulomb_residual(model, solution) < 1e-13


def test_the_check_catches_newton_cg_without_the_inert_sets(monkeypatch, no_symmetry_planes):
    """On the former trace, without them (no set inert) the same solve stalls at the axis node's rounding, short of
    the law's 1e-8. With
    the faces grown where Newton's point is refused (newton_cg.GROW, moving radii) this path no longer stalls (11
    steps, 1e-13, the inert sets unused), so they are checked on the path without grown faces, the one they were
    made on; and without the fixed-point map's steps (FIXED_STEPS), which carry the stalled path on to max_iter, still
    short of 1e-8."""
    monkeypatch.setattr(newton_cg, "GROW", 0)
    monkeypatch.setattr(newton_cg, "FIXED_STEPS", 0)
    model, solution = coulomb_newton_at_ten_thousand_dofs()
    assert solution.status == "solved" and coulomb_residual(model, solution) < 1e-8
    monkeypatch.setattr(newton_cg, "_inert", lambda c, tol: None)
    model, solution = coulomb_newton_at_ten_thousand_dofs()
    assert solution.status != "solved" and solution.solver_status == "stalled"
    assert coulomb_residual(model, solution) > 1e-8


def p2_spheres_program():
    return cc.prepare(two_spheres(4, law=cc.Tresca(slip_bound=0.0005), element="P2"), "dual").program


def test_newton_cg_solves_the_dense_dual_of_two_p2_spheres_with_tresca():
    """Two P2 spheres of 4 cells, Tresca s = 0.0005 (75 unknowns): solved in 4 Newton steps, 20 products, as Clarabel
    solves it; the same with the damping after far points only, the full step spread and HELD off (the former trace's
    control below fails so)."""
    program = p2_spheres_program()
    reference = cc.solvers.solve(program, "clarabel")
    for damped in (newton_cg._damped, functools.partial(far_only, newton_cg._damped)):
        with pytest.MonkeyPatch.context() as patched:
            patched.setattr(newton_cg, "_damped", damped)
            patched.setattr(newton_cg, "STEP_SPREAD", np.inf if damped is not newton_cg._damped else newton_cg.STEP_SPREAD)
            patched.setattr(newton_cg, "HELD", 0.0 if damped is not newton_cg._damped else newton_cg.HELD)
            solution = newton_cg.solve(program, max_iter=100)
        assert solution.status == "solved" and solution.iterations <= 6
        assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-10)


def far_only(damped, damping, far, refused, residual):
    return damped(damping, far, False, residual)


def test_the_check_catches_newton_cg_without_the_damping_on_the_former_p2_trace(monkeypatch, no_symmetry_planes):
    """The former trace (W singular on the axis node's multipliers, its least diagonal 4e-7 of the largest): damped
    after far points only, it took one Newton point and then crawled along W's null directions by gradient steps,
    natural residual 1e-6 after 100 (f 1.2e-10 above the optimum); with the damping after a projected-gradient step
    (newton_cg.DAMPING) it is solved (4 steps, 24 products)."""
    program = p2_spheres_program()
    assert newton_cg.solve(program, max_iter=100).status == "solved"
    monkeypatch.setattr(newton_cg, "_damped", functools.partial(far_only, newton_cg._damped))
    monkeypatch.setattr(newton_cg, "STEP_SPREAD", np.inf)  # the axis node's full step length, as it was made on
    monkeypatch.setattr(newton_cg, "HELD", 0.0)  # its Schur complement's step length (HELD) rescues it too
    assert newton_cg.solve(program, max_iter=100).status == "failed"
