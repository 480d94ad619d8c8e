"""The 3-D pair of spheres (mortar, quarter model; issue 25): its Tresca dual from the stick start the Coulomb solve
seeds it with, and its Coulomb problem at 10⁴ DOFs by Newton's method with moving radii. The nodes on the symmetry
planes have the full model's normal and no friction along the planes' normals (exactly empty rows: fem/contact.py,
``symmetry_planes``), and W on the rows that carry is regular. The former trace's rows acting on almost nothing (W
singular) were what newton-cg's damping of far Newton points, inert sets, HELD and STEP_SPREAD were made on; those
mechanisms and their former-trace checks were removed (docs/performance.md, "newton-cg without its near-null-row
mechanisms")."""

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
    """One Newton step (6 products), and the least value of the dual that Clarabel finds
    (the values are compared, not the points: the empty rows' multipliers are any in their balls)."""
    program, solution = solve_from_the_stick_start()
    reference = cc.solvers.solve(program, "clarabel")
    assert solution.status == "solved" and solution.iterations <= 3
    assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-8)


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
    """Solved to newton-cg's tol in 2 Newton steps (7 products; 9 and 30 on the former trace), its Coulomb residual
    below 1e-13 (the law's tol is 1e-8); its displacement is Clarabel's answer of the Tresca
    problem under the slip bounds Newton reached (unique in u: K is positive definite), to Clarabel's accuracy."""
    model, solution = coulomb_newton_at_ten_thousand_dofs()
    assert solution.status == "solved" and solution.iterations <= 3
    assert coulomb_residual(model, solution) < 1e-13
    reference = cc.solvers.solve(replace(model.program, **model.bound_update(solution.info["radii"])), "clarabel")
    u, expected = model.recover(solution).u, model.recover(reference).u
    assert np.abs(u - expected).max() < 1e-6 * np.abs(expected).max()


def p2_spheres_program():
    return cc.prepare(two_spheres(4, law=cc.Tresca(slip_bound=0.0005), element="P2"), "dual").program


def test_newton_cg_solves_the_dense_dual_of_two_p2_spheres_with_tresca():
    """Two P2 spheres of 4 cells, Tresca s = 0.0005 (75 unknowns): solved in 4 Newton steps, 20 products, as Clarabel
    solves it (on the former trace its axis node's multipliers, W singular there, needed the damping after a
    projected-gradient step)."""
    program = p2_spheres_program()
    reference = cc.solvers.solve(program, "clarabel")
    solution = newton_cg.solve(program, max_iter=100)
    assert solution.status == "solved" and solution.iterations <= 6
    assert objective(program, solution.x) == pytest.approx(objective(program, reference.x), rel=1e-10)
