"""Every solution of a discrete Coulomb problem (issue 15): Hild's closed-form sets, and uniqueness for small F."""

import numpy as np
import pytest
from test_friction_hild import node_A, triangle_scene

import convexcontact as cc
from convexcontact.analytic import hild_critical_friction, hild_one_triangle_solutions, lame_plane_strain
from convexcontact.drivers.solutions import all_solutions

NU = 0.3
CRITICAL = hild_critical_friction(NU)
LOADS = [(0.3, 1.0), (0.5, -1.0), (3.0, -1.0), (-1.5, -1.0), (3.0, 0.3), (-1.0, -0.5), (-2.5, -1.0), (-1.0, -1.0),
         (0.0, -1.0), (-3.0, -1.0)]


def matches(solution, exact) -> bool:
    u, force = node_A(solution.result)
    return max(np.abs(u - exact["displacement"]).max(), np.abs(force - exact["contact_force"]).max()) < 1e-8


@pytest.mark.parametrize("load", LOADS)
@pytest.mark.parametrize("friction", [1.0, CRITICAL, 2.5])
def test_the_triangle_has_exactly_the_closed_form_solutions(load, friction):
    """Prop. 4.1: one, two or three solutions; each returned one is certified and is one of them."""
    exact = hild_one_triangle_solutions(*load, friction, 1.0, NU, 1.0)
    found = all_solutions(triangle_scene(*load, cc.Coulomb(friction=friction)))
    assert found.complete and len(found) == len(exact), found.statement
    for solution in found.solutions:
        assert solution.result.status == "solved" and solution.result.certificate.passes(1e-12)
        assert sum(matches(solution, e) for e in exact) == 1


def test_at_the_critical_friction_the_line_is_a_continuum():
    """F = F_c and F1 = F F2: a segment of solutions, reported as such with its two end points."""
    F2 = -1.0
    found = all_solutions(triangle_scene(CRITICAL * F2, F2, cc.Coulomb(friction=CRITICAL)))
    exact = hild_one_triangle_solutions(CRITICAL * F2, F2, CRITICAL, 1.0, NU, 1.0)
    assert all(e["continuum"] for e in exact) and len(found) == 2
    assert all(s.continuum == 1 for s in found.solutions) and "continuum of dimension 1" in found.statement
    assert all(any(matches(s, e) for e in exact) for s in found.solutions)


def test_the_left_slip_solution_repels_the_picard_map():
    """The map's slope at left slip is (λ+μ)F/(λ+3μ) > 1 beyond F_c: no Picard iteration reaches it."""
    lam, mu = lame_plane_strain(1.0, NU)
    friction = 2.5
    found = all_solutions(triangle_scene(-1.0, -0.5, cc.Coulomb(friction=friction)))
    left = [s for s in found.solutions if s.states[0] == "slip-"]
    assert len(left) == 1
    assert left[0].picard_slope == pytest.approx((lam + mu) * friction / (lam + 3 * mu), rel=1e-5)
    assert left[0].summary()["attracts"] is False


def test_a_small_mesh_with_small_friction_has_one_solution_the_picard_answer():
    """Six contact nodes (4096 state choices), F = 0.2: one solution, which the default solve finds."""
    scene = cc.Scene(name="block", body=cc.Body(cc.Rectangle(width=1.0, height=0.5, nx=5, ny=3)),
                     materials=cc.Material(1.0, NU), dirichlet=(cc.Dirichlet("top", ux=0.004, uy=-0.01),),
                     contact=cc.Contact("bottom", cc.Obstacle("flat"), cc.Coulomb(friction=0.2)))
    found = all_solutions(scene)
    assert found.complete and found.examined == 4**6 and len(found) == 1
    picard = cc.solve(scene)
    assert picard.status == "solved"
    only = found.solutions[0].result
    assert np.abs(only.displacement - picard.displacement).max() < 1e-7 * np.abs(picard.displacement).max()
    assert found.solutions[0].picard_slope < 1


def test_tresca_is_refused_with_the_reason():
    with pytest.raises(cc.SceneError, match="convex"):
        all_solutions(triangle_scene(0.5, -1.0, cc.Tresca(slip_bound=0.1)))


def test_the_uniqueness_map_reproduces_prop_4_1_on_a_grid(tmp_path):
    """The study's counts equal the closed form's on a grid crossing F_c and the critical load line,
    and its CSV and PNG are written."""
    from convexcontact.studies.verification import uniqueness

    rows = uniqueness.main(["--frictions", "4", "--max-friction", "2.7", "--angles", "13", "--out", str(tmp_path)])
    assert all(r["solutions"] == r["closed_form"] for r in rows)
    assert {1, 3} <= {r["solutions"] for r in rows}  # the grid reaches the three-solution wedge
    assert (tmp_path / "uniqueness.csv").read_text().count("\n") == len(rows) + 1
    assert (tmp_path / "uniqueness.png").stat().st_size > 0


def side_by_side_triangles(loads, friction):
    """Hild's triangle repeated along x, one per load, with nothing coupling them: the solutions of the
    whole are the products of each triangle's."""
    import skfem as fe

    n = len(loads)
    points = np.hstack([np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) + [[2.0 * i], [0.0]] for i in range(n)])
    boundaries = {"contact": lambda x: np.isclose(x[1], 0.0),
                  "clamped": lambda x: np.isclose((x[0] % 2.0) + x[1], 1.0)}
    boundaries.update({f"loaded{i}": (lambda x, i=i: np.isclose(x[0], 2.0 * i) & (x[1] > 0)) for i in range(n)})
    mesh = fe.MeshTri1(points, np.arange(3 * n).reshape(n, 3).T).with_boundaries(boundaries)
    return cc.Scene(name="triangles", body=cc.Body(mesh, "P1"), materials=cc.Material(1.0, NU),
                    dirichlet=(cc.Dirichlet("clamped", ux=0.0, uy=0.0),),
                    tractions=tuple(cc.Traction(f"loaded{i}", vector=load) for i, load in enumerate(loads)),
                    contact=cc.Contact("contact", cc.Obstacle("flat", gap=0.0), cc.Coulomb(friction=friction)))


def test_products_of_solution_sets_are_found():
    """Two triangles with three solutions each and one with one: 9, exhaustively."""
    found = all_solutions(side_by_side_triangles([(-1.0, -0.5), (-1.0, -0.5), (0.5, -1.0)], 2.5))
    assert found.complete and len(found) == 9


def test_beyond_the_exhaustive_size_the_search_finds_a_second_solution_and_says_it_is_not_complete():
    """Eleven triangles (beyond 10 nodes), one with three solutions: the search finds separation and stick
    there (left slip repels every Picard iteration) and does not claim completeness; its 17 Picard runs and
    each solution's slope are reported as they end."""
    reports = []
    found = all_solutions(side_by_side_triangles([(-1.0, -0.5)] + [(0.5, -1.0)] * 10, 2.5),
                          progress=lambda *report: reports.append(report))
    assert not found.complete and "not proven complete" in found.statement and found.examined > 2
    assert [r[0] for r in reports[:17]] == list(range(1, 18)) and reports[17:] == [
        (k, len(found), "Picard slope") for k in range(1, len(found) + 1)]  # every run and slope reported
    first = {s.states[0] for s in found.solutions}
    assert {"open", "stick"} <= first and all(s.result.status == "solved" for s in found.solutions)


def test_solve_takes_solutions_all():
    """cc.solve(..., solutions="all") is all_solutions; a misspelt value names the argument."""
    scene = triangle_scene(-1.0, -0.5, cc.Coulomb(friction=2.5))
    assert len(cc.solve(scene, solutions="all")) == 3
    with pytest.raises(cc.SceneError, match="solutions"):
        cc.solve(scene, solutions="every")


def test_the_command_line_lists_every_solution(tmp_path, capsys):
    """`convexcontact run SCENE --solutions all`: the statement, a row per solution, a summary that says it."""
    import json

    from convexcontact import cli

    scene = tmp_path / "block.toml"
    scene.write_text('[body]\nmesh = "rectangle"\nwidth = 1.0\nheight = 0.5\nnx = 3\nny = 2\n'
                     '[material]\nE = 1.0\nnu = 0.3\n[[dirichlet]]\nboundary = "top"\nux = 0.004\nuy = -0.01\n'
                     '[contact]\nboundary = "bottom"\nlaw = "coulomb"\nfriction = 0.2\n[obstacle]\nshape = "flat"\n')
    assert cli.main(["run", str(scene), "--solutions", "all", "--json", str(tmp_path / "all.json")]) == 0
    assert "all solutions, 1 isolated" in capsys.readouterr().out
    summary = json.loads((tmp_path / "all.json").read_text())
    assert summary["complete"] and len(summary["solutions"]) == 1 and summary["status"] == "solved"
