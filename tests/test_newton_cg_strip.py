"""newton-cg's path on the clamped strip 400 : 1 (issue 25): its Tresca answer is the empty face's point, and the
first Newton point (FIRST_FORCING) finds it whatever the round-off of the local diagonal d_j."""

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.fem import local_delassus
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import law_of
from convexcontact.studies.benchmarks.shapes import shape_scene


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_clamped_strip_takes_few_newton_steps_whatever_the_diagonal_s_round_off(seed, monkeypatch):
    """d_j × (1 + 1e-13 ξ): the former path (the face read at v, the first system solved to 0.1 ‖F‖) took 5 Newton
    steps and 77 products with W at 10⁴ DOFs, 11 and 207 at 2·10⁴, 16–26 and 300–572 at 5·10⁴; the empty face's
    point, solved to 1e-6 ‖F‖, is the answer: at most 3 steps and 40 products, certified."""
    exact = local_delassus.local_diagonal

    def perturbed(*args, **kwargs):
        d = exact(*args, **kwargs)
        return d * (1 + 1e-13 * np.random.default_rng(seed).standard_normal(d.shape))

    monkeypatch.setattr(local_delassus, "local_diagonal", perturbed)
    model = cc.prepare(shape_scene("strip-clamped-400", law_of("tresca"), 1e4), "dual-matrix-free")
    solution = newton_cg.solve(model.program)
    assert solution.status == "solved" and solution.iterations <= 3 and solution.info["products"] <= 40
    assert model.result(solution, {}, model.slip_bound).certificate.worst < 1e-10
