"""The adaptive Picard driver (issue 10, part 2): defaults that converge, attempts on record, honest failures."""

import dataclasses
import json

import numpy as np
import pytest
from test_friction_hild import LENGTH, NU, E, matches_one_of, triangle_scene

import convexcontact as cc
from convexcontact.analytic import hild_critical_friction, hild_one_triangle_solutions
from convexcontact.cli import table
from convexcontact.drivers.picard import NOISE, UNFINISHED, paths
from convexcontact.scene.description import Box, Coulomb
from convexcontact.scene.library import HERTZ_FORCE, frictional_punch, hertz_punch, punch_mesh

MU = 0.3


def dragged_block(friction: float = MU) -> cc.Scene:
    """A box pressed on a rigid plane by a pressure on its top and dragged by it (u_x prescribed): every
    closed node slides. The single-run driver stagnated there: 17 steps at a relative change of 9.9e-8."""
    return cc.Scene(
        name="dragged_block",
        body=cc.Body(Box(size=(1.0, 1.0, 0.5), cells=(8, 8, 4)), "P1"),
        materials=cc.Material(1.0, 0.3),
        dirichlet=(cc.Dirichlet("top", ux=0.1, uy=0.0),),
        tractions=(cc.Traction("top", pressure=0.01),),
        contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), Coulomb(friction=friction)),
    )


def test_dragged_block_slides_at_the_friction_coefficient():
    """Total tangential / normal reaction = μ exactly; the map stops at the inner solver's attainable change."""
    result = cc.solve(dragged_block())
    assert result.status == "solved", result.message
    assert result.certificate.passes(1e-6)
    normals, forces = result.fem.contact.normals, result.contact.forces
    normal = -np.einsum("ij,ij->i", forces, normals)
    tangential = np.linalg.norm(forces + normal[:, None] * normals, axis=1)
    assert set(result.contact.status) == {"open", "slip"}
    assert tangential.sum() / normal.sum() == pytest.approx(MU, rel=1e-8)
    picard, last = result.extra["picard"], result.extra["history"][-1]
    assert picard["stop_change"] == max(picard["tol"], NOISE * last["inner_residual"])


# unique right-slip solutions beyond F_c = 3 − 4ν = 1.8: ω = 1 cycles on every one of them
BEYOND_CRITICAL = [(hild_critical_friction(NU), 3.0, -1.0), (2.5, 3.0, 0.3), (4.0, 10.0, -1.0)]


@pytest.mark.parametrize(("friction", "F1", "F2"), BEYOND_CRITICAL)
def test_anderson_mixing_converges_where_the_plain_map_cycles(friction, F1, F2):
    """The default map (Anderson mixing) reaches Prop. 4.1's solution; up to F = 2.5 at ω = 1, where the plain map
    cycles (at F = 4 it oscillates too, and ω = ½ then converges in 3 steps)."""
    (solution,) = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
    result = cc.solve(triangle_scene(F1, F2, Coulomb(friction=friction)))
    assert result.status == "solved" and result.certificate.passes(1e-6), result.message
    close, distance = matches_one_of(result, [solution], tol=1e-7)
    assert close, distance
    first = result.extra["picard"]["attempts"][0]
    assert first["relaxation"] == 1.0 and (first["outcome"] == "converged") == (friction < 4)


@pytest.mark.parametrize(("friction", "F1", "F2"), BEYOND_CRITICAL)
def test_hild_unique_solution_beyond_critical_friction(friction, F1, F2):
    """The plain map cycles; it is run again at ω = ½ and converges to Prop. 4.1's solution."""
    (solution,) = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
    result = cc.solve(triangle_scene(F1, F2, Coulomb(friction=friction, acceleration=0)))
    assert result.status == "solved", result.message
    assert result.certificate.passes(1e-6)
    close, distance = matches_one_of(result, [solution], tol=1e-7)
    assert close, distance
    first, last = result.extra["picard"]["attempts"]
    assert first["relaxation"] == 1.0 and first["outcome"].startswith(("oscillating", "cycling"))
    assert last["relaxation"] == 0.5 and last["outcome"] == "converged"


def test_attempts_are_in_the_summary_and_the_table():
    friction, F1, F2 = BEYOND_CRITICAL[0]
    result = cc.solve(triangle_scene(F1, F2, Coulomb(friction=friction, acceleration=0)))
    summary = json.loads(json.dumps(result.summary()))
    attempts = summary["picard"]["attempts"]
    assert [a["relaxation"] for a in attempts] == [1.0, 0.5]
    for attempt in attempts:
        assert {"formulation", "solver", "relaxation", "outcome", "iterations", "best_residual"} <= set(attempt)
    assert sum(a["iterations"] for a in attempts) == summary["picard"]["iterations"] == len(summary["picard_history"])
    assert "primal/clarabel ω=0.5: converged" in table(result)


def test_a_map_that_cannot_converge_is_reported_not_converged():
    """Beyond uniqueness, within a budget the map cannot meet: not converged, with attempts and history."""
    result = cc.solve(triangle_scene(10.0, -1.0, Coulomb(friction=4.0, max_iterations=10, acceleration=0)))
    assert result.status == "not converged"
    picard = result.extra["picard"]
    assert picard["outcome"] == UNFINISHED and len(result.extra["history"]) == 10
    assert [a["relaxation"] for a in picard["attempts"]] == [1.0, 0.5]
    assert not result.certificate.passes(1e-6)
    assert "best iterate" in result.message and "ω=0.5" in result.message


def test_the_driver_changes_only_what_the_user_left_to_it():
    """Named formulation and solver options are kept (a study's row is what it says); "auto" and the
    solver's defaults may give way to the other formulation and solvers."""
    scene = hertz_punch(nx=8, law=Coulomb(friction=0.3))
    pinned = cc.prepare(scene, "dual")
    assert [(m.formulation, s) for m, s, _ in paths(pinned, "clarabel", {"tol": 1e-6}, {})] == [("dual", "clarabel")]
    free = [(m.formulation, s) for m, s, _ in paths(cc.prepare(scene), "clarabel", {}, {})]
    assert free == [("dual", "clarabel"), ("primal", "clarabel"), ("dual", "osqp"), ("primal", "osqp")]


def test_cattaneo_mindlin_nearly_incompressible_dual_map_is_certified():
    """ν = 0.499, Q2: the dual's inner solves stay accurate although W's condition is 1e9 (they were at 3e-3 and the
    driver moved to the primal, until the polish judged signs on the KKT solve's rounding); its map converges. Q/(FP)
    is held exactly and the stick zone is Cattaneo–Mindlin's c/a = sqrt(1 − Q/(FP)) to the mesh resolution."""
    h, ratio, friction = 0.02, 0.75, 0.6
    law = Coulomb(friction=friction)
    punch = cc.Obstacle("parabolic", radius=1.0, force=HERTZ_FORCE, tangential_force=ratio * friction * HERTZ_FORCE)
    scene = dataclasses.replace(
        frictional_punch(nu=0.499, element="Q2", law=law),
        body=cc.Body(punch_mesh(h, width=16.0, depth=8.0, quads=True), "Q2"),
        dirichlet=(cc.Dirichlet("bottom", uy=0.0), cc.Dirichlet("left", ux=0.0), cc.Dirichlet("right", ux=0.0)),
        contact=cc.Contact("top", punch, law),
    )
    result = cc.solve(scene)
    assert result.status == "solved", result.message
    assert result.certificate.passes(1e-6)
    assert [(a["formulation"], a["outcome"]) for a in result.extra["picard"]["attempts"]] == [("dual", "converged")]
    assert result.tangential_force / (friction * result.normal_force) == pytest.approx(ratio, abs=1e-6)
    s, status = result.contact.coordinate, result.contact.status
    c, a = np.ptp(s[status == "stick"]) / 2, np.ptp(s[status != "open"]) / 2
    assert abs(c / a - np.sqrt(1 - ratio)) <= 2 * h / a
