"""Newton polish of second-order-cone programs in bound form (solvers/cone_polish.py)."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.conic import ConicProgram, ConicSolution, nonnegative, soc
from convexcontact.scene.library import punch_3d
from convexcontact.solvers import clarabel_direct
from convexcontact.solvers.cone_polish import bound_form, cone_polish
from convexcontact.solvers.polish import polish


def kkt_violation(program: ConicProgram, x, z) -> float:
    """Largest violation of the KKT conditions of a program with zero, nonnegative and SOC cones,
    computed here from the cones' definitions: s = b − Ax ∈ K, z ∈ K*, ⟨s, z⟩ = 0 per cone, Px + q + Aᵀz = 0."""
    s = program.b - program.A @ x
    worst = np.abs(program.P @ x + program.q + program.A.T @ z).max()
    for cone, rows in program.blocks():
        si, zi = s[rows], z[rows]
        if cone.kind == "zero":
            worst = max(worst, np.abs(si).max())
        elif cone.kind == "nonnegative":
            worst = max(worst, -si.min(), -zi.min(), np.abs(si * zi).max())
        else:
            worst = max(worst, np.linalg.norm(si[1:]) - si[0], np.linalg.norm(zi[1:]) - zi[0], abs(si @ zi))
    return worst


def projection_program():
    """min ½‖(x₀, x₁, x₂) − c‖² + ½(x₄ − 5)² s.t. ‖(x₀, x₁)‖ ≤ 1, x₂ ≥ 0.5, ‖(x₃, x₄)‖ ≤ 2, with x₃ (a
    roller: in a ball, in no cost) and x₅ (in nothing) idle. Answer: (x₀, x₁) = c/‖c‖, ν₁ = ‖c‖ − 1;
    x₂ = 0.5 with multiplier 0.5 − c₂; (x₃, x₄) = (0, 2), ν₂ = 3; x₅ as given."""
    c = np.array([3.0, 4.0, 0.2])
    P = sp.diags([1.0, 1.0, 1.0, 0.0, 1.0, 0.0], format="csc")
    q = np.array([-3.0, -4.0, -0.2, 0.0, -5.0, 0.0])
    A = np.zeros((7, 6))
    A[1, 0] = A[2, 1] = A[3, 2] = A[5, 3] = A[6, 4] = -1.0
    b = np.array([1.0, 0.0, 0.0, -0.5, 2.0, 0.0, 0.0])
    return ConicProgram(P, q, sp.csc_matrix(A), b, (soc(3), nonnegative(1), soc(3))), c


def test_newton_polish_finds_projections_onto_balls_from_a_rough_guess():
    program, c = projection_program()
    guess = ConicSolution(x=np.array([0.5, 0.5, 1.0, 1.0, 1.0, 7.0]), z=np.array([1.0, 0.1, -0.1, 0.0, 1.0, 0.0, 0.0]),
                          s=np.zeros(7), status="inaccurate", solver_status="", iterations=0, solve_time=0.0, solver="")
    polished = cone_polish(program, guess, bound_form(program))
    assert polished.info.get("polished") and polished.status == "solved"
    norm = np.linalg.norm(c[:2])
    assert np.abs(polished.x - [c[0] / norm, c[1] / norm, 0.5, 0.0, 2.0, 7.0]).max() < 1e-12
    assert np.abs(polished.z[[0, 3, 4]] - [norm - 1.0, 0.5 - c[2], 3.0]).max() < 1e-12
    assert kkt_violation(program, polished.x, polished.z) < 1e-12


def test_programs_the_newton_polish_does_not_cover_are_left_to_the_interior_point():
    """Balls of two sizes and general cone rows (the primal contact program) have no bound form."""
    program, _ = projection_program()
    mixed = dataclasses.replace(program, A=sp.csc_matrix(program.A[:6]), b=program.b[:6],
                                cones=(soc(3), nonnegative(1), soc(2)))
    assert bound_form(mixed) is None
    model = cc.prepare(punch_3d(4, law=cc.Tresca(slip_bound=0.004)), "primal")
    assert bound_form(model.program) is None


def tresca_dual(cells=8):
    """The 3-D quarter punch under Tresca: three nodes stick, five slip, the rest open."""
    return cc.prepare(punch_3d(cells, law=cc.Tresca(slip_bound=0.008)), "dual")


def test_polished_3d_tresca_dual_is_exact_from_a_loose_interior_point_answer():
    """From Clarabel at tol 1e-6, the polish ends at a KKT point to round-off with stick and slip nodes,
    and the mechanical certificate (Tresca law, equilibrium) holds to 1e-12."""
    model = tresca_dual()
    rough = clarabel_direct.Session(model.program, tol=1e-6, polishing=False).solve()
    polished = polish(model.program, rough)
    assert polished.info.get("polished") and not rough.info.get("polished")
    assert kkt_violation(model.program, rough.x, rough.z) > 1e-8
    assert kkt_violation(model.program, polished.x, polished.z) < 1e-12
    result = model.result(polished, {}, model.slip_bound)
    assert result.certificate.worst < 1e-12
    status = result.contact.status
    assert (status == "slip").sum() >= 3 and (status == "stick").sum() >= 3


def test_warm_started_resolves_after_changed_slip_bounds_equal_cold_solves():
    """A Picard step changes the balls' radii: the session's Newton warm start from the last answer (no
    interior point) lands on the answer of a fresh interior-point solve of the changed program."""
    model = tresca_dual()
    form = bound_form(model.program)
    session = clarabel_direct.Session(model.program)
    session.solve()
    rng = np.random.default_rng(1)
    for change in (1e-3, 1e-2, 1e-1):
        b = model.program.b.copy()
        b[form.ball_radius_rows] *= 1.0 + change * rng.uniform(-1.0, 1.0, form.ball_radius_rows.size)
        session.update(b=b)
        warm = session.solve()
        cold = clarabel_direct.Session(dataclasses.replace(model.program, b=b)).solve()
        assert warm.info.get("warm_start") and warm.iterations == 0 and cold.iterations > 0
        assert np.abs(warm.x - cold.x).max() < 1e-10 * np.abs(cold.x).max()
        assert kkt_violation(session.program, warm.x, warm.z) < 1e-12


def test_a_warm_start_from_zero_slip_bounds_lands_on_the_cold_answer():
    """Balls of radius 0 hold their answer at the centre; when the radii become positive (a Picard map's first
    step from s = 0) the warm start's guess puts some of those answers on their spheres, where the centre has
    no direction: the polish starts them where the cost pulls instead of on NaN (found through FClib)."""
    model = tresca_dual()
    form = bound_form(model.program)
    radius = model.program.b[form.ball_radius_rows]
    session = clarabel_direct.Session(dataclasses.replace(model.program, b=_with_radius(model.program, form, 0.0)))
    assert session.solve().solved
    b = _with_radius(model.program, form, 1e-4 * radius)  # small beside the pull on the centres: on the spheres
    session.update(b=b)
    warm = session.solve()
    cold = clarabel_direct.Session(dataclasses.replace(model.program, b=b)).solve()
    assert warm.info.get("warm_start") and warm.solved
    assert np.abs(warm.x - cold.x).max() < 1e-10 * np.abs(cold.x).max()
    assert kkt_violation(session.program, warm.x, warm.z) < 1e-12


def _with_radius(program, form, radius):
    b = program.b.copy()
    b[form.ball_radius_rows] = radius
    return b


def test_roller_directions_give_empty_friction_rows():
    """On the quarter model's symmetry planes one tangential direction is a roller: the friction rows of
    those nodes must be empty (not round-off), or the dual's W is rank-deficient instead of having an
    empty column."""
    model = tresca_dual(6)
    contact = model.fem.contact
    on_planes = (np.abs(contact.coords[:, :2]) < 1e-12).sum()  # nodes on x = 0 or y = 0 (the axis node twice)
    empty = np.diff(sp.csr_matrix(model.friction.R).indptr) == 0
    assert empty.sum() == on_planes


def test_a_failed_polish_returns_its_input_even_when_the_guess_says_polished(monkeypatch):
    """A warm start's guess is an earlier answer that carries {"polished": True}; when the rounds fail the
    polish must hand the guess back (the session then runs the interior point), not pass it off as polished."""
    import convexcontact.solvers.cone_polish as cone
    import convexcontact.solvers.polish as linear

    model_2d = cc.prepare(cc.library.hertz_punch(nx=16, law=cc.Tresca(slip_bound=0.01)), "dual")
    for model, module in ((model_2d, linear), (tresca_dual(6), cone)):
        answer = clarabel_direct.Session(model.program).solve()
        assert answer.info.get("polished")
        monkeypatch.setattr(module, "ROUNDS", 0)
        monkeypatch.setattr(module, "LOOSE_ROUNDS", 0, raising=False)  # the linear polish's second pass
        guess = dataclasses.replace(answer, x=0.5 * answer.x)
        assert polish(model.program, guess) is guess


@pytest.mark.parametrize("bound", [1e-259, 8.7e-311])
def test_a_vanishing_slip_bound_polishes_without_underflow(bound):
    """3-D slip bounds found by the fuzz suite: 1e-259 squared to 0 in ‖w‖ (NaN directions), 8.7e-311 made
    the curvature ν/ρ overflow; the dual now polishes to the answer of the primal."""
    from convexcontact.scene.description import Box

    scene = cc.Scene(name="tiny bound", body=cc.Body(Box(size=(1.0, 1.0, 0.5), cells=(2, 2, 2),
                                                          origin=(-0.5, -0.5, 0.0)), "P1"),
                     materials=cc.Material(1.0, 0.0), dirichlet=(cc.Dirichlet("top", ux=0.0, uy=0.0, uz=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("flat", depth=0.0078125), cc.Tresca(slip_bound=bound)))
    dual, primal = (cc.prepare(scene, form).solve("clarabel") for form in ("dual", "primal"))
    assert dual.status == primal.status == "solved" and dual.certificate.passes(1e-12)
    assert np.abs(dual.displacement - primal.displacement).max() < 1e-9 * np.abs(primal.displacement).max()
