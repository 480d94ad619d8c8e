"""Signorini on the clamped strips (issue 25): the answer's opening zone near each clamped end is found in the first
Newton step, Newton's point on the empty face grown by the nodes it leaves (newton_cg's GROW and FIRST_FORCING), so
the step count does not grow with the mesh as the zone's nodes do."""

import pytest

import convexcontact as cc
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import law_of
from convexcontact.studies.benchmarks.shapes import shape_scene


@pytest.mark.parametrize(("shape", "dofs", "formulation", "former"), [
    ("strip-clamped-400", 1e4, "dual-matrix-free", "4 Newton steps, 32 products"),
    ("strip-clamped-100", 5e3, "dual", "7 Newton steps, the face read at v swinging"),
])
def test_the_clamped_strip_s_opening_zone_is_found_in_the_first_step(shape, dofs, formulation, former):
    """The former code (no grown faces with bounds alone, the face read at v on a dense W) took ``former``; the
    second step only confirms the first's point: at most 2 steps, certified (1e-10, the issue's target)."""
    model = cc.prepare(shape_scene(shape, law_of("signorini"), dofs), formulation)
    solution = newton_cg.solve(model.program)
    assert solution.status == "solved" and solution.iterations <= 2, (solution.iterations, former)
    assert solution.info["grown"] >= 1  # the opening zone is not the empty face's point: a face grew
    assert model.result(solution, {}, None).certificate.worst < 1e-10
