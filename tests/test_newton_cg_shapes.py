"""newton-cg on the duals of hard shapes (issue 25): a pair, long strips, and the scenes of the fuzz suite that
broke it, each against Clarabel on the same program or a closed form."""

import warnings
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact import solvers
from convexcontact.conic import ConicProgram
from convexcontact.fem.factorization import Approximation, factorize, factorize_sum
from convexcontact.fem.local_delassus import colouring, local_diagonal
from convexcontact.scene.library import whole_face
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def test_a_slip_bound_of_the_smallest_double_is_a_point_to_the_newton_step():
    """The fuzz suite's long profile drew a Tresca slip bound of 5e-324: the tangent curvature (‖y‖ − ρ)/(cρ) of a
    sliding node overflowed (an error under the warnings policy). Such a disc is its centre to the step: the
    friction traction is 0, so the answer is the frictionless one (its tangential force vanishes)."""
    depth = 5e-3
    scene = cc.Scene(name="tiny slip bound", body=cc.Body(cc.Rectangle(1.0, 0.5, 4, 2, origin=(-0.5, 0.0)), "P1"),
                     materials=cc.Material(1.0, 0.3), dirichlet=(cc.Dirichlet("top", ux=0.3 * depth, uy=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("flat", depth=depth), cc.Tresca(slip_bound=5e-324)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = cc.prepare(scene, "dual").solve("newton-cg")
        frictionless = cc.prepare(scene.with_law(cc.Signorini()), "dual").solve("clarabel")
    assert result.status == "solved" and result.certificate.worst < 1e-12
    assert np.abs(result.contact.friction).max() <= 1e-300
    assert np.allclose(result.contact.pressure, frictionless.contact.pressure, rtol=1e-8,
                       atol=1e-10 * frictionless.max_pressure)


def scaled_program(seed: int, bounds: int, balls: int, size: int, spread: float):
    """A planted program (tests/test_global_convergence.py) whose rows differ in scale by up to ``spread`` (P → S P S,
    as the Delassus rows of a graded mesh), P an operator with an exact approximation L Lᵀ and a diagonal estimate off
    by a factor in [½, 2] per row; (operator program, matrix program, x*)."""
    from test_global_convergence import planted

    base, answer = planted(seed, bounds, balls, size, 1e3, operator=False)
    rng = np.random.default_rng(seed)
    row = np.geomspace(1.0, spread, base.n_variables)[rng.permutation(base.n_variables)]
    row[bounds:] = np.repeat(row[bounds::size], size)  # one scale per ball
    S = sp.diags(1.0 / row)  # x = S x̃: P̃ = S P S, q̃ = S q, the sets scaled alike (A S)
    P = (S @ base.P @ S).toarray()
    matrix = ConicProgram(sp.csc_matrix(P), S @ base.q, sp.csc_matrix(base.A @ S), base.b, base.cones)
    operator = spla.aslinearoperator(P)
    operator.approximation = Approximation(sp.csr_matrix(np.linalg.cholesky(P)), sp.eye(P.shape[0], format="csr"),
                                           factorize_sum)
    operator.approximation.__dict__["diagonal"] = np.diag(P) * rng.uniform(0.5, 2.0, P.shape[0])
    return replace(matrix, P=operator), matrix, answer * row


@pytest.mark.parametrize("bounds, balls, size", [(30, 0, 1), (10, 10, 1), (8, 8, 2), (6, 6, 3)])
def test_rows_of_any_scale_are_solved_as_clarabel_solves_them(bounds, balls, size):
    """Bounds, intervals, discs and balls whose rows differ in scale by 10⁴, P an operator with a diagonal estimate
    (the step length and the preconditioner's shift per row): newton-cg reaches the planted answer and Clarabel's."""
    operator, matrix, answer = scaled_program(bounds + balls, bounds, balls, size, 1e4)
    solution, reference = solvers.solve(operator, "newton-cg"), solvers.solve(matrix, "clarabel")
    assert solution.status == "solved" and solution.iterations <= 20
    scale = np.abs(answer).max()
    assert np.abs(solution.x - answer).max() <= 1e-8 * scale
    assert np.abs(solution.x - reference.x).max() <= 1e-6 * scale


def test_the_local_diagonal_is_below_w_and_exact_on_the_whole_body():
    """d_j = b_jᵀ K_Ω⁻¹ b_j with Ω the support grown some layers: at most W_jj (the body clamped beyond Ω is stiffer),
    W_jj itself where Ω is the whole body; no two rows of one colour have touching patches."""
    model = cc.prepare(whole_face(2, 9, 200, cc.Tresca(slip_bound=0.002)), "dual-matrix-free")
    P, K = model.program.P, model.fem.K
    W = P.B @ factorize(K).solve(P.B.T.toarray())
    near, whole = local_diagonal(K, P.B, 2), local_diagonal(K, P.B, 50)
    assert np.all(near <= np.diag(W) * (1 + 1e-12)) and np.all(near > 0.1 * np.diag(W))
    np.testing.assert_allclose(whole, np.diag(W), rtol=1e-10)
    conflict = sp.csr_matrix(abs(P.B) @ abs(K) @ abs(P.B).T)
    colours = colouring(conflict)
    rows, columns = conflict.nonzero()
    assert np.all(colours[rows[rows != columns]] != colours[columns[rows != columns]])


@pytest.mark.parametrize("shape, most_steps", [("two-body", 20), ("strip-clamped-100", 10)])
def test_a_pair_and_a_clamped_strip_agree_with_clarabel_on_the_dense_dual(shape, most_steps):
    """The two-body Tresca dual applied matrix-free (68 Newton steps before the rows' own step lengths, here 14) and a
    strip 100 : 1 clamped at its ends (its bending: CG iterations in the thousands before the thin body was its own
    approximation): certified, and the same pressures and friction as Clarabel on the dense dual."""
    scene = scene_of(shape, 2, "tresca", 1e4 if shape == "two-body" else 2e3)
    free = cc.prepare(scene, "dual-matrix-free")
    solution = newton_cg.solve(free.program)
    result = free.result(solution, {}, free.slip_bound)
    reference = cc.prepare(scene, "dual").solve("clarabel")
    assert result.status == "solved" and result.certificate.worst < 1e-9 and solution.iterations <= most_steps
    assert solution.info["cg_iterations"] <= 30 * solution.iterations
    p = reference.max_pressure
    assert np.abs(result.contact.pressure - reference.contact.pressure).max() <= 1e-6 * p
    assert np.abs(result.contact.friction - reference.contact.friction).max() <= 1e-6 * p


def test_the_tall_2d_block_finds_its_slip_zone_in_a_few_newton_steps(monkeypatch):
    """A tall block (1 : 4, 17 bottom nodes) moved sideways on a Tresca foundation, its dual applied matrix-free: it
    slips at both ends and sticks in the middle. Newton's points on grown faces (GROW) find the slip zone in a few steps
    (5 measured); without them it was found a node every few steps and newton-cg failed after 100 (certificate 1e-3;
    at 2·10⁴ DOFs 75 steps, at 10⁵ failed); without them the face step (FACE) finds it in 9. Certified, and
    Clarabel's answer on the dense dual."""
    scene = scene_of("tall", 2, "tresca", 2e3)
    free = cc.prepare(scene, "dual-matrix-free")
    solution = newton_cg.solve(free.program)
    result = free.result(solution, {}, free.slip_bound)
    reference = cc.prepare(scene, "dual").solve("clarabel")
    assert result.status == "solved" and solution.iterations <= 10 and result.certificate.worst <= 1e-10
    p = reference.max_pressure
    assert np.abs(result.contact.pressure - reference.contact.pressure).max() <= 1e-6 * p
    assert np.abs(result.contact.friction - reference.contact.friction).max() <= 1e-6 * p
    slip = np.isclose(np.abs(result.contact.friction), np.abs(result.contact.friction).max(), rtol=1e-9)
    assert slip[0] and slip[-1] and not slip.all()  # slips at both ends, sticks in the middle
    monkeypatch.setattr(newton_cg, "GROW", 0)
    assert newton_cg.solve(free.program, max_iter=30).iterations <= 10  # the face step (FACE) mends it too
    monkeypatch.setattr(newton_cg, "FACE", False)
    assert newton_cg.solve(free.program, max_iter=30).iterations == 30  # the crawl the grown faces mend


@pytest.mark.parametrize("law", ["signorini", "tresca"])
def test_the_clamped_strip_400_is_certified_to_1e_10_from_the_displacement_its_multipliers_leave(law):
    """A strip 400 : 1 clamped at its ends on a flat foundation: the load alone would bend it 10⁸ times further than its
    contact lets it move, so W x and q = −(B K⁻¹f + c) cancel, and ∇f formed as their sum could not be told from 0
    below ε‖q‖ while the certificate's gaps were 10⁻⁹ (Tresca 4–8e-9 measured with the sum). From the displacement
    K⁻¹(f − Bᵀx) (the dual's ``gradient``) and stopped relative to the answer's own scale: certified to 1e-10."""
    scene = scene_of("strip-clamped-400", 2, law, 2e3)
    model = cc.prepare(scene, "dual-matrix-free")
    assert model.program.updated(q=model.program.q + 1.0).gradient is None  # another load: W x + q as a sum
    assert model.program.updated(b=model.program.b).gradient is model.program.gradient
    solution = newton_cg.solve(model.program)
    result = model.result(solution, {}, model.slip_bound)
    assert result.status == "solved" and solution.iterations <= 15 and result.certificate.worst <= 1e-10
    summed = newton_cg.solve(replace(model.program, gradient=None))
    assert model.result(summed, {}, model.slip_bound).certificate.worst > 1e-10
