"""Newton's method on the Coulomb problem on the clamped strip 400 : 1 (issue 25): Newton's point on grown faces where
the radii move too (newton_cg.GROW), from a frictionless start solved to picard.START_TOL."""

import pytest

import convexcontact as cc
from convexcontact.drivers import picard
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import law_of
from convexcontact.studies.benchmarks.shapes import shape_scene


def newton_record(result) -> tuple[list, dict]:
    """Newton's natural residuals on the Coulomb problem and the first attempt's record."""
    history, attempt = result.extra["history"], result.extra["picard"]["attempts"][0]
    return history[0].get("newton_residuals", []), attempt


@pytest.mark.parametrize("grow", [True, False])
def test_newton_on_the_coulomb_problem_takes_newton_s_points_on_the_clamped_strip(grow, monkeypatch):
    """10⁴ DOFs, matrix-free: a slip node leaves its interval at Newton's point, whose projection then raised the
    natural residual, so each step went half way to that same point (6 Newton steps, the residual halved 3 times);
    the face grown by that node gives the answer in at most 3 steps (certified). Without the grown faces (GROW = 0)
    the halving is back: the check catches it. From the frictionless start (solved to START_TOL), where the halving was
    found: from the stick start (STICK_START) Newton takes 3 steps with or without grown faces."""
    monkeypatch.setattr(picard, "stick_start", lambda *args: False)
    if not grow:
        monkeypatch.setattr(newton_cg, "GROW", 0)
    result = cc.prepare(shape_scene("strip-clamped-400", law_of("coulomb"), 1e4), "dual-matrix-free").solve()
    residuals, attempt = newton_record(result)
    assert result.status == "solved" and result.certificate.worst <= 1e-8
    assert attempt["newton"].startswith("solved") and result.extra["picard"]["iterations"] == 1
    assert (len(residuals) - 1 <= 3) == grow


def test_the_clamped_strip_s_coulomb_problem_is_newton_s_at_5e4_dofs():
    """5·10⁴ DOFs, ``auto`` (the matrix-free dual): before, the start (the frictionless answer at a natural residual of
    1e-2 relative to ‖c q‖ = 10³ ‖v‖) held 1,400 of 3,200 nodes open where the answer has none, Newton stalled after 4
    steps and the Picard map took 7 steps (16–40 s); from the START_TOL start without grown faces, Newton's answer
    failed the certificate (1.7e-5) and the primal map ran. Now Newton answers alone, certified to the law's 1e-8."""
    result = cc.prepare(shape_scene("strip-clamped-400", law_of("coulomb"), 5e4), "auto").solve()
    residuals, attempt = newton_record(result)
    assert result.status == "solved" and result.certificate.worst <= 1e-8
    assert attempt["formulation"] == "dual" and attempt["newton"].startswith("solved")
    assert len(residuals) - 1 <= 4 and result.extra["picard"]["iterations"] == 1


def test_the_clamped_strip_s_coulomb_newton_starts_from_the_stick_answer(monkeypatch):
    """10⁴ DOFs, 100 : 1, matrix-free: the strip sticks almost everywhere, and Newton's Coulomb solve starts from the
    stick answer's first Newton point on its own program (picard.STICK_START): no frictionless program is solved, and
    start and Newton together take at most 35 products with W where the frictionless start (solved to START_TOL, its own
    preconditioner) and Newton from it took 19 + 31 (400 : 1: 26 + 42 → 8 + 20)."""
    products = []
    solve = newton_cg.newton_cg

    def counted(*args, **kwargs):
        solution = solve(*args, **kwargs)
        products.append(solution.info["products"])
        return solution

    monkeypatch.setattr(newton_cg, "newton_cg", counted)
    model = cc.prepare(shape_scene("strip-clamped-100", law_of("coulomb"), 1e4), "dual-matrix-free")
    result = model.solve()
    residuals, attempt = newton_record(result)
    assert result.status == "solved" and result.certificate.worst <= 1e-8
    assert attempt["newton"].startswith("solved") and len(residuals) - 1 <= 3
    assert not any(key[0] == "frictionless" for key in model.cache if isinstance(key, tuple))
    assert len(products) == 2 and sum(products) <= 35
