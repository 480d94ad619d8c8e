"""Signorini's Newton path (issue 25): the clamped strip's opening zone near each end is found in the first Newton
step, Newton's point on the empty face grown by the nodes it leaves (newton_cg's GROW and FIRST_FORCING), so the step
count does not grow with the mesh as the zone's nodes do; on a dense W the face read at v grows the same way."""

import pytest

import convexcontact as cc
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


@pytest.mark.parametrize(("shape", "dofs", "formulation", "former"), [
    ("strip-clamped-400", 1e4, "dual-matrix-free", "4 Newton steps, 32 products"),
    ("two-body", 5e3, "dual", "4 Newton steps"),
])
def test_the_open_nodes_are_found_in_the_first_step(shape, dofs, formulation, former):
    """The former code (no grown faces with bounds alone) took ``former``; now at most 2 steps (the second only
    confirms the first's point), a face grown, certified to the issue's 1e-10."""
    model = cc.prepare(scene_of(shape, 2, "signorini", dofs), formulation)
    solution = newton_cg.solve(model.program)
    assert solution.status == "solved" and solution.iterations <= 2, (solution.iterations, former)
    assert solution.info["grown"] >= 1  # the answer's face is not the first face: it grew
    assert model.result(solution, {}, None).certificate.worst < 1e-10
