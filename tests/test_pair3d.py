"""The 3-D pair of spheres (mortar, quarter model; issue 25): its Tresca dual from the stick start the Coulomb solve
seeds it with. W is singular there (the tangential multipliers of nodes on the symmetry planes act on almost
nothing), and without the damping of far Newton points (newton_cg.FAR, DAMPING) not one Newton point was taken in
100 steps. Its Coulomb problem at 10⁴ DOFs, by Newton's method with moving radii: without the inert sets' metric and
proximal term from a stall on (newton_cg.INERT) it stalled on the axis node's rounding."""

import functools
from dataclasses import replace

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.drivers import picard
from convexcontact.formulations.dual import normal_multipliers
from convexcontact.scene.bodies_library import two_spheres
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


@functools.cache
def stick_start_program():
    """The pair's model at 2·10³ DOFs (dense W) and its Tresca program under the frictionless pressures' slip bounds."""
    model = cc.prepare(scene_of("two-body", 3, "coulomb", 2e3), "dual")
    bound = picard.pressure_map(model)[0](picard.initial_pressure(model, "newton-cg", {}))
    return model, replace(model.program, **model.bound_update(bound))


def solve_from_the_stick_start():
    model, program = stick_start_program()
    session = newton_cg.Session(program)
    model.seed(session, "newton-cg", {}, start={"tol": picard.START_TOL})
    return program, session.solve()


def objective(program, x: np.ndarray) -> float:
    return 0.5 * x @ (program.P @ x) + program.q @ x


def test_the_pairs_tresca_dual_is_solved_from_the_stick_start_as_clarabel_solves_it():
    """A few Newton steps, and the least value of the dual that Clarabel finds (the multipliers are not unique: W is
    singular, so the values are compared, not the points)."""
    program, solution = solve_from_the_stick_start()
    reference = cc.solvers.solve(program, "clarabel")
    assert solution.status == "solved" and solution.iterations <= 10
    assert np.linalg.eigvalsh(program.P.toarray())[0] < 1e-15 * abs(program.P).max()  # the case this is about
    assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-8)


def test_the_check_catches_newton_cg_without_the_damping(monkeypatch):
    """Without the damping (neither after a far Newton point nor after a projected-gradient step) and with a step's
    faces only grown by the sets Newton's point leaves (newton_cg.GROW, before the face at Newton's point) the same
    solve takes no Newton point and fails. The face at Newton's point alone solves it too (6 steps, 26 products; with
    the damping 6 and 28)."""
    monkeypatch.setattr(newton_cg, "_damped", lambda damping, far, refused, residual: 0.0)
    monkeypatch.setattr(newton_cg, "_released", lambda y, newton, g, c, sets, released: (
        newton_cg._grown(y, newton, sets, sets.radius), False))
    _, solution = solve_from_the_stick_start()
    assert solution.status != "solved" and solution.info["steps"]["residual"] == 0


def test_the_axis_nodes_tangential_rows_are_its_normal_row_on_the_free_dofs():
    """The node on both symmetry planes: the planes hold its tangential motion, so on the free DOFs its two
    tangential rows and its normal row are one direction (the mortar normal's tilt). W's two null vectors lie on
    these three multipliers, and one of them moves the normal multiplier too: the tangential multipliers there are
    no inert rows to hold at 0 or leave out; a change of them is a change of the node's pressure, so of its slip
    bound (docs/performance.md, "The pair's Coulomb row at 10⁴ DOFs")."""
    model, program = stick_start_program()
    W, m = program.P.toarray(), model.fem.contact.m
    tangential = np.diag(W)[m:].reshape(-1, m).max(axis=0)
    axis = int(np.argmin(tangential))
    assert tangential[axis] < 1e-6 * np.diag(W).max()  # the rows this is about
    values, vectors = np.linalg.eigh(W)
    null = vectors[:, :2]
    assert abs(values[:2]).max() < 1e-14 * abs(values).max() < values[2]
    assert np.linalg.norm(null[[axis, m + axis, 2 * m + axis]], axis=0) == pytest.approx(1.0, abs=1e-6)
    assert abs(null[axis]).max() > 1e-3


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


def test_the_check_catches_newton_cg_without_the_inert_sets(monkeypatch):
    """Without them (no set inert) the same solve stalls at the axis node's rounding, short of the law's 1e-8. With
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


def test_newton_cg_solves_the_dense_dual_of_two_p2_spheres_with_tresca(monkeypatch):
    """Two P2 spheres of 4 cells, Tresca s = 0.0005 (75 unknowns, W singular on the axis node's multipliers, its
    least diagonal 4e-7 of the largest): solved in 7 Newton steps, the Newton systems damped after a projected-gradient
    step (newton_cg.DAMPING). Damped after far points only, it took one Newton point and then crawled along W's null
    directions by gradient steps, natural residual 1e-6 after 100 (f 1.2e-10 above the optimum): checked below."""
    program = cc.prepare(two_spheres(4, law=cc.Tresca(slip_bound=0.0005), element="P2"), "dual").program
    solution = newton_cg.solve(program, max_iter=100)
    reference = cc.solvers.solve(program, "clarabel")
    assert solution.status == "solved" and solution.iterations <= 10
    assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-10)
    far_only = newton_cg._damped
    monkeypatch.setattr(newton_cg, "_damped", lambda damping, far, refused, residual: far_only(damping, far, False,
                                                                                              residual))
    monkeypatch.setattr(newton_cg, "STEP_SPREAD", np.inf)  # the axis node's full step length, as it was made on
    monkeypatch.setattr(newton_cg, "HELD", 0.0)  # its Schur complement's step length (HELD) rescues it too
    assert newton_cg.solve(program, max_iter=100).status == "failed"
