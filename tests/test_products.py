"""The products newton-cg takes that are no CG iterations (solvers/newton_cg.py; docs/performance.md, "The pair's
products that are not CG iterations"): no curvature probe where P's diagonal is known, no product at x = 0 (∇f = q),
∇f at the coarse answer from the coarse solve's products, no fresh sum against a loose tolerance (the coarse
program's), and a Newton step that starts where the last one ended starts from the gradient it ended with, while
the step's target is above the sum's rounding."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.conic import ConicProgram, nonnegative
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def recorded(monkeypatch):
    """The vectors newton-cg multiplies by P (its own operator) and the points of P's own formula of ∇f."""
    products, formulas = [], []
    operator, affine = newton_cg._operator, newton_cg._affine

    def recording_operator(P):
        inner = operator(P)
        return spla.LinearOperator(inner.shape, matvec=lambda x: products.append(np.array(x)) or inner.matvec(x),
                                   dtype=float)

    def recording_affine(program):
        as_sum, own = affine(program)
        return as_sum, own and (lambda x: formulas.append(np.array(x)) or own(x))

    monkeypatch.setattr(newton_cg, "_operator", recording_operator)
    monkeypatch.setattr(newton_cg, "_affine", recording_affine)
    return products, formulas


def pair_products(monkeypatch):
    """The vectors multiplied by W and the points of its own formula of ∇f in the 2-D pair's Tresca dual at 2·10⁴ DOFs,
    forced matrix-free (the coarse program's too)."""
    products, formulas = recorded(monkeypatch)
    result = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free").solve()
    assert result.solved and result.certificate.worst <= 1e-10
    return products, formulas


def test_the_pair_s_dual_takes_no_curvature_probe_where_its_diagonal_is_known(monkeypatch):
    """W's approximation estimates its diagonal: the step lengths need no probe, which took one product of each
    newton-cg call, the coarse program's too."""
    products, _ = pair_products(monkeypatch)
    probe = np.random.default_rng(0).standard_normal(products[0].size)  # the fine program's probe (scale 1)
    assert not any(x.size == probe.size and np.array_equal(x, probe) for x in products)


def test_the_pair_s_dual_takes_no_product_at_zero(monkeypatch):
    """∇f at the start x = 0 is q: it took one product, by W's own formula and, in the coarse program (no such
    formula), a product with 0."""
    products, formulas = pair_products(monkeypatch)
    assert not any(not x.any() for x in products + formulas)


def test_the_gradient_at_the_coarse_answer_comes_from_the_coarse_solve_s_products(monkeypatch):
    """From the coarse answer x (newton_cg.COARSE_SETS) ∇f there is q + W Q̃ x_c from the coarse solve's products
    (newton_cg.LIFT), a fresh one's by W's own formula to round-off, and the fine program takes no product at x (it
    took one)."""
    answers, coarse_start = [], newton_cg._coarse_start

    def kept(program, *args):
        answer = coarse_start(program, *args)
        if answer is not None:  # fresh, by W's own formula (the dual's scale is 1)
            answers.append((answer, program.gradient(answer[0])))
        return answer

    monkeypatch.setattr(newton_cg, "_coarse_start", kept)
    products, formulas = pair_products(monkeypatch)
    [((x, _, lifted), fresh)] = answers
    assert lifted is not None and np.abs(lifted - fresh).max() <= 1e-14 * np.abs(fresh).max()
    assert not any(point.size == x.size and np.array_equal(point, x) for point in products + formulas)


def dense_program(n: int = 40, seed: int = 5) -> ConicProgram:
    """min ½ xᵀPx + qᵀx over x ≥ 0, P a random SPD matrix applied as an operator (no diagonal known)."""
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    P = Q @ np.diag(np.geomspace(1.0, 1e-2, n)) @ Q.T
    return ConicProgram(spla.aslinearoperator(0.5 * (P + P.T)), rng.standard_normal(n), -sp.eye(n, format="csc"),
                        np.zeros(n), (nonnegative(n),))


@pytest.mark.parametrize("tol, fresh", [(1e-3, False), (1e-12, True)])
def test_a_fresh_sum_at_the_answer_only_against_a_tolerance_below_the_square_root_of_eps(monkeypatch, tol, fresh):
    """A program without its own formula of ∇f (the coarse program's): at tol 1e-3 (COARSE_TOL) the stopping test
    takes the sum CG's updates left (their rounding is ~ε a product), not a fresh product at the answer, which it
    took before; at 1e-12 it does."""
    products, _ = recorded(monkeypatch)
    solution = newton_cg.solve(dense_program(), tol=tol)
    assert solution.solved and solution.iterations >= 1
    assert any(np.array_equal(x, solution.x) for x in products) == fresh


def pair_solve(monkeypatch, law: str):
    """The 2-D pair at 2·10⁴ DOFs forced matrix-free, no coarse start: the result and newton-cg's solve."""
    monkeypatch.setattr(newton_cg, "COARSE_SETS", 10**9)  # no coarse start: the steps here are the fine program's
    solves, solve = [], newton_cg.newton_cg
    monkeypatch.setattr(newton_cg, "newton_cg", lambda *a, **k: solves.append(solve(*a, **k)) or solves[-1])
    result = cc.prepare(scene_of("two-body", 2, law, 2e4), "dual-matrix-free").solve()
    monkeypatch.setattr(newton_cg, "newton_cg", solve)
    [solution] = solves
    assert result.solved and result.certificate.worst <= 1e-10
    return solution


@pytest.mark.parametrize("law, steps, reused", [("signorini", 4, 3), ("tresca", 5, 6)])
def test_a_newton_step_on_the_face_it_ended_on_starts_from_the_gradient_it_ended_with(monkeypatch, law, steps, reused):
    """Each Newton step after a taken Newton point starts on that point's face, whose ∇f CG's products left
    (newton_cg._start_gradient): ``reused`` products fewer than with a fresh ∇f at each step's start, the same Newton
    steps, and that ∇f is a fresh one's to round-off (Tresca's 5 before a step whose target is below the sum's rounding
    started from updates of a fresh ∇f too, newton_cg._fresh_enough)."""
    start_gradient, drift = newton_cg._start_gradient, []
    owns, affine_of = [], newton_cg._affine  # W's own formula, outside newton-cg's count of its evaluations
    monkeypatch.setattr(newton_cg, "_affine", lambda program: owns.append(affine_of(program)[1]) or affine_of(program))

    def checked(point, known, affine, sets, products):
        if known is not None and np.array_equal(point, known[0]):
            fresh = sets.scale * owns[-1](sets.shift + sets.scale * point)
            drift.append(np.abs(known[1] - fresh).max() / np.abs(fresh).max())
        return start_gradient(point, known, affine, sets, products)

    monkeypatch.setattr(newton_cg, "_start_gradient", checked)
    now = pair_solve(monkeypatch, law)
    monkeypatch.setattr(newton_cg, "_start_gradient", lambda point, known, *rest: start_gradient(point, None, *rest))
    before = pair_solve(monkeypatch, law)
    assert now.iterations == before.iterations == steps
    assert before.info["products"] - now.info["products"] == reused == len(drift) and max(drift) <= 1e-13


def test_a_sum_of_updates_does_not_start_a_step_whose_target_is_below_its_rounding():
    """The clamped strip 20 : 1 (10⁵ DOFs, Tresca, ‖c q‖ = 10³ ‖v‖): its second step's target is below the sum's
    rounding (SUM_FLOOR × ε ‖c q‖), so that step starts from a fresh ∇f: 2 Newton steps, the second from 4e-10 to
    below 1e-16; from the sum of the first step's updates it stopped at 2e-13 and took a third."""
    model = cc.prepare(scene_of("strip-clamped-20", 2, "tresca", 1e5), "auto")
    solution = newton_cg.solve(model.program)
    assert solution.solved and solution.iterations == 2 and solution.info["residuals"][-1] <= 1e-16


def coupled_solve(monkeypatch):
    """The 2-D pair's Coulomb problem at 2·10⁴ DOFs, forced matrix-free: newton-cg's solve where radii move."""
    solves, solve = [], newton_cg.newton_cg
    monkeypatch.setattr(newton_cg, "newton_cg", lambda *a, **k: solves.append(solve(*a, **k)) or solves[-1])
    result = cc.prepare(scene_of("two-body", 2, "coulomb", 2e4), "dual-matrix-free").solve()
    monkeypatch.setattr(newton_cg, "newton_cg", solve)
    assert result.solved and result.certificate.worst <= 1e-8
    [solution] = [solution for solution in solves if "radii" in solution.info]
    return solution


def test_where_radii_move_the_gradient_at_newton_s_point_comes_from_gmres_s_products(monkeypatch):
    """∇f at Newton's point is ∇f at the step's start + P̃ Z ξ from GMRES's products (newton_cg.GMRES_LIFT), a fresh
    one's to round-off; the solve where radii move took 133 products with a fresh ∇f there (131 with the session's
    step lengths and the refused point's ∇f handed on where its face stays), 117–118 with the lift (GMRES's iterations
    follow PARDISO's rounding), the same 6 Newton steps; since Newton's points take the natural map's faces at every
    step (RELEASE_MOVING) 3 steps, 80 → 69 products: each lifted ∇f (11) is one product fewer, to GMRES's rounding;
    78 → 69 since a step may start from a fresh ∇f's updates (newton_cg._fresh_enough), which spares the solve
    without the lift two of the products the lift spares."""
    step, drift = newton_cg._step, []

    def checked(P, affine, sets, *args, **kwargs):
        new, iterations, at_point = step(P, affine, sets, *args, **kwargs)
        if sets.coupling is not None and at_point is not None:
            fresh = sets.scale * affine(sets.shift + sets.scale * new)
            drift.append(np.abs(at_point - fresh).max() / np.abs(fresh).max())
        return new, iterations, at_point

    monkeypatch.setattr(newton_cg, "_step", checked)
    now = coupled_solve(monkeypatch)
    monkeypatch.setattr(newton_cg, "GMRES_LIFT", False)
    before = coupled_solve(monkeypatch)
    assert now.iterations == before.iterations == 3 and len(drift) >= 8
    assert before.info["products"] - now.info["products"] >= len(drift) - 2
    assert max(drift) <= 1e-12


def test_a_session_s_solves_take_their_step_lengths_once(monkeypatch):
    """The pair's Coulomb problem at 2·10⁴ DOFs, forced matrix-free, solves three times in one session (the stick
    start, Tresca's answer, the solve where radii move): its P and scale do not change, so one Hutchinson product
    gives their step lengths (newton_cg's ``cache``), where each solve took one."""
    lengths, step_lengths = [], newton_cg._step_lengths
    monkeypatch.setattr(newton_cg, "_step_lengths", lambda P, *rest: lengths.append(P) or step_lengths(P, *rest))
    coupled_solve(monkeypatch)
    fine = [P for P in lengths if not isinstance(P, newton_cg._Coarse) and not sp.issparse(P)]  # nor the coarse
    # program's approximated start's (newton_cg._approximated: a matrix, its diagonal known without a product)
    assert len(fine) == 1


def test_the_last_step_s_updates_stand_for_a_fresh_gradient_at_the_answer(monkeypatch):
    """Where the last Newton step began from a fresh ∇f (its target below the sum's rounding) and moved c∇f little
    (newton_cg._fresh_enough), the stopping test takes CG's updates of it, not W's own formula at the answer: the
    pair's Signorini dual at 2·10⁴ DOFs forced matrix-free, 4 Newton steps both, 46 products before, 45 now; the natural
    residual by a fresh ∇f there below the tolerance."""
    _, formulas = recorded(monkeypatch)
    now = pair_solve(monkeypatch, "signorini")
    assert not any(np.array_equal(x, now.x) for x in formulas)
    program = cc.prepare(scene_of("two-body", 2, "signorini", 2e4), "dual-matrix-free").program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    c = newton_cg._step_lengths(program.P, sets, None)
    residual, _, size = newton_cg._natural(now.x, program.gradient(now.x), c, sets, program.q)  # scale 1, shift 0
    assert residual * size <= newton_cg.TOL * np.abs(now.x).max()
    monkeypatch.setattr(newton_cg, "_fresh_enough", lambda *args: False)
    before = pair_solve(monkeypatch, "signorini")
    assert (now.iterations, now.info["products"]) == (before.iterations, before.info["products"] - 1) == (4, 45)


def test_w_s_own_formula_is_not_taken_twice_at_one_point(monkeypatch):
    """The stopping test takes ∇f by W's own formula only where the ∇f it has is not one already: the 3-D flat
    block's Tresca dual at 5·10³ DOFs, forced matrix-free, whose Newton points leave their spheres, so the step's test
    takes ∇f at the projected point by the formula (``move``), and the stopping test took it again there: 15 → 14
    evaluations of the formula, none twice in a row."""
    _, formulas = recorded(monkeypatch)
    result = cc.prepare(scene_of("flat", 3, "tresca", 5e3), "dual-matrix-free").solve()
    assert result.solved and result.certificate.worst <= 1e-10
    assert len(formulas) == 14 and not any(np.array_equal(a, b) for a, b in itertools.pairwise(formulas))
