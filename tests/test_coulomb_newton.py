"""Newton's method on the Coulomb problem itself: the dual whose friction balls have radii F·λ_N that move
with the unknowns, against the Picard map's fixed point and against Clarabel on the Tresca program of the
radii Newton reached (a fixed point of the map), judged by the certificate."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact import solvers
from convexcontact.conic import ConicProgram, nonnegative, soc
from convexcontact.drivers import picard
from convexcontact.formulations.dual import normal_multipliers, stick_guess
from convexcontact.scene.description import Coulomb, SceneError
from convexcontact.scene.library import punch_3d, whole_face
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of, two_body_scene


def coulomb_like(rng, nodes: int, size: int, friction: float):
    """min ½xᵀPx + qᵀx over x_N ≥ 0 and ‖x_T,k‖ ≤ s_k (P random SPD, the balls after the bounds, their radius
    rows first), and the coupling s = F x_N."""
    n = nodes * (1 + size)
    G = rng.standard_normal((n, n))
    P = G @ G.T / n + 0.05 * np.eye(n)
    rows, cones = [-sp.eye(nodes, n)], [nonnegative(nodes)]
    for k in range(nodes):
        rows.append(sp.vstack([sp.csr_matrix((1, n)), -sp.eye(size, n, nodes + k * size)]))
        cones.append(soc(1 + size))
    q = rng.standard_normal(n)
    q[:nodes] = -np.abs(q[:nodes]) - 0.5  # pressed: most x_N > 0
    program = ConicProgram(sp.csc_matrix(P), q, sp.vstack(rows).tocsc(), np.zeros(nodes * (2 + size)), tuple(cones))
    return program, friction * sp.eye(nodes, n, format="csr")


@pytest.mark.parametrize("size", [1, 2])
@pytest.mark.parametrize("operator", [False, True])
def test_newton_reaches_a_fixed_point_of_the_tresca_map_on_random_programs(size, operator):
    """Intervals (2-D friction) and discs (3-D), P a matrix (dense LU steps) or an operator (GMRES): Newton's
    answer x is the Tresca answer for the radii F x_N it reached (Clarabel on that program, an independent
    solve), and the radii it reports are F x_N."""
    rng = np.random.default_rng(size)
    program, coupling = coulomb_like(rng, 12, size, 0.3)
    P = spla.aslinearoperator(program.P.toarray()) if operator else program.P
    answer = newton_cg.coupled(dataclasses.replace(program, P=P), coupling, None)
    assert answer.status == "solved" and answer.info["natural_residual"] <= newton_cg.TOL
    radii = answer.info["radii"]
    np.testing.assert_allclose(radii, coupling @ answer.x, rtol=0, atol=1e-14)
    norm = np.linalg.norm(answer.x[12:].reshape(12, size), axis=1)
    slipping = np.isclose(norm, radii, rtol=1e-9, atol=0) & (radii > 0)
    assert slipping.any() and (norm < radii * (1 - 1e-9)).any()  # the balls move: points slip, others stick
    b = program.b.copy()
    b[12 + np.arange(12) * (1 + size)] = radii
    tresca = solvers.solve(dataclasses.replace(program, b=b), "clarabel", tol=1e-12)
    assert np.abs(tresca.x - answer.x).max() < 1e-8 * np.abs(answer.x).max()


def test_bad_couplings_are_refused():
    program, coupling = coulomb_like(np.random.default_rng(0), 4, 1, 0.3)
    with pytest.raises(ValueError, match="one row per ball"):
        newton_cg.coupled(program, coupling[:3], None)
    with pytest.raises(ValueError, match="balls' own variables"):
        newton_cg.coupled(program, sp.eye(4, 8, 4), None)


@pytest.mark.parametrize("formulation, dim, nodes, dofs, options", [
    ("dual", 2, 61, 2e3, {}), ("dual-matrix-free", 2, 61, 2e3, {}), ("dual-matrix-free", 3, 49, 6e2, {}),
    ("dual", 3, 49, 6e2, {}),
    ("dual", 2, 61, 2e3, {"smoothing_radius": 0.05}),  # nonlocal: s = F S λ_N, S the mollifier
])
def test_newton_gives_the_maps_fixed_point(formulation, dim, nodes, dofs, options):
    """Whole-face Coulomb: Newton's answer is the plain Picard map's fixed point (tol 1e-10), certified to
    1e-10 where the map's own stops at its tolerance, in fewer inner solves."""
    law = Coulomb(friction=0.3, tol=1e-10, **options)
    scene = whole_face(dim, nodes, dofs, law)
    newton = cc.prepare(scene, formulation).solve()
    picard = cc.prepare(scene.with_law(dataclasses.replace(law, newton=False)), formulation).solve()
    assert newton.status == picard.status == "solved"
    assert newton.extra["history"][-1]["coulomb_newton"]
    assert not any(step["coulomb_newton"] for step in picard.extra["history"])
    assert len(newton.extra["history"]) < len(picard.extra["history"])
    assert newton.certificate.worst <= 1e-10
    scale = np.abs(picard.contact.pressure).max()
    assert np.abs(newton.contact.pressure - picard.contact.pressure).max() < 1e-8 * scale
    assert np.abs(newton.contact.friction - picard.contact.friction).max() < 1e-8 * scale


def test_friction_at_gauss_points_runs_the_map():
    """More friction points than nodes leave λ_T not unique (W singular on it): Newton stalled there, so the map
    runs alone, and its answer is certified."""
    law = Coulomb(friction=0.3, quadrature="gauss")
    result = cc.prepare(whole_face(2, 61, 2e3, law), "dual").solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-8
    assert result.extra["picard"]["attempts"][0]["newton"] is None


def test_a_stalled_newton_leaves_the_map_to_converge(monkeypatch):
    """Newton's method is local: where it fails, the map goes on from where it was, and converges. Cut to no step:
    one step (before) no longer fails here, its point on the natural map's faces is the answer (RELEASE_MOVING)."""
    original = newton_cg.Session.coupled
    monkeypatch.setattr(newton_cg.Session, "coupled", lambda self, coupling: original(self, coupling, max_iter=0))
    scene = whole_face(2, 61, 2e3, Coulomb(friction=0.3))
    result = cc.prepare(scene, "dual").solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-6
    assert not any(step["coulomb_newton"] for step in result.extra["history"])
    assert len(result.extra["history"]) > 2
    assert result.extra["picard"]["attempts"][0]["newton"] == "max_iter after 0 Newton steps"


def test_newton_option_is_checked():
    with pytest.raises(SceneError) as error:
        Coulomb(friction=0.3, newton="yes")
    assert error.value.field == "contact.newton"


def test_a_named_solver_runs_its_own_map():
    """A study that names its solver compares that solver's map: Newton answers only for "auto"."""
    scene = whole_face(2, 61, 2e3, Coulomb(friction=0.3))
    named = cc.prepare(scene, "dual").solve("clarabel")
    left = cc.prepare(scene, "dual").solve()
    assert named.solver == "clarabel" and not any(step["coulomb_newton"] for step in named.extra["history"])
    assert left.solver == "newton-cg" and [step["coulomb_newton"] for step in left.extra["history"]] == [True]
    assert named.extra["picard"]["attempts"][0]["newton"] is None
    assert left.extra["picard"]["attempts"][0]["newton"].startswith("solved after")
    residuals = left.extra["history"][0]["newton_residuals"]  # what the Picard plot draws
    assert residuals[-1] <= newton_cg.TOL < residuals[0]


def test_newton_on_a_singular_delassus_operator():
    """The quarter 3-D punch: multipliers at nodes whose DOFs the symmetry planes hold make W singular (a dense
    LU of a Tresca Newton system failed there); Newton's answer is the map's, certified."""
    scene = punch_3d(cells=6, law=Coulomb(friction=0.3, tol=1e-10))
    model = cc.prepare(scene, "dual")
    assert np.abs(model.program.P.diagonal()).min() == 0.0
    newton = model.solve()
    picard = model.solve("clarabel")
    assert newton.extra["history"][-1]["coulomb_newton"] and newton.certificate.worst <= 1e-10
    scale = np.abs(picard.contact.pressure).max()
    assert np.abs(newton.contact.pressure - picard.contact.pressure).max() < 1e-8 * scale
    assert np.abs(newton.contact.friction - picard.contact.friction).max() < 1e-8 * scale


def test_a_step_towards_the_projected_gradient_gets_newton_past_a_stall():
    """The 2-D punch with F = 2: no step towards Newton's point lowered the natural residual after 2 Newton steps;
    one towards the projected gradient's does, and Newton reaches the map's fixed point."""
    from convexcontact.studies.benchmarks.bench import punch_scene

    scene = punch_scene(2, "coulomb", 1e4).with_law(Coulomb(friction=2.0, tol=1e-10))
    newton = cc.solve(scene)
    picard = cc.solve(scene.with_law(Coulomb(friction=2.0, tol=1e-10, newton=False)))
    assert newton.extra["picard"]["attempts"][0]["newton"].startswith("solved after")
    assert newton.certificate.worst <= 1e-10 and picard.status == "solved"
    scale = np.abs(picard.contact.pressure).max()
    assert np.abs(newton.contact.pressure - picard.contact.pressure).max() < 1e-8 * scale
    assert np.abs(newton.contact.friction - picard.contact.friction).max() < 1e-8 * scale


def stiff_on_soft_spheres() -> cc.Scene:
    """Two P1 caps (12 cells, radii 5) of moduli 34.8 and 1.1, ν 0.3 and 0.45, F = 0.6: found by a sweep of random
    pairs, where Newton's Coulomb solve crawled."""
    from convexcontact.scene.bodies_library import two_spheres

    return two_spheres(cells=12, radii=(5.0, 5.0), moduli=(34.8, 1.1), nu=(0.3, 0.45), approach=0.0309,
                       law=Coulomb(friction=0.6))


def test_the_stiff_on_soft_spheres_coulomb_problem_is_solved_by_newton():
    """The pair on which newton-cg's inert sets' switch at their rounding (FLOOR, since removed) was made: on the
    former trace the axis node's slip, held by both symmetry planes, crawled for 30 steps at 7.6e-13. With the
    planes' rows empty it has no disc: Newton's Coulomb solve takes 5 steps, certificate 1.1e-13."""
    result = cc.solve(stiff_on_soft_spheres())
    assert result.status == "solved" and result.extra["history"][0]["coulomb_newton"]
    assert result.certificate.worst <= 1e-12 and result.extra["history"][0]["inner_iterations"] < 20


def soft_on_stiff_p2_spheres(law) -> cc.Scene:
    """Two P2 caps of 6 cells, soft on stiff (a random pair's find; 12,168 DOFs)."""
    from convexcontact.scene.bodies_library import two_spheres

    return two_spheres(cells=6, radii=(2.0, 2.0), moduli=(13.9, 75.9), nu=(0.3, 0.0), approach=0.00868, law=law,
                       element="P2")


def test_a_map_that_cannot_reach_its_tol_says_so():
    """The Picard map with newton-cg's inner solves on a whole face (2·10³ DOFs): their certificate, 5.3e-14, bounds
    it at 10 × that (NOISE) whatever tol asks, and the result says so instead of a silent "solved"; a tol it reaches
    leaves no message. (Before, the check ran two P2 caps on the former trace with newton_cg.HELD off, whose axis node
    held the law to 5.3e-9; with the symmetry planes' rows empty those caps reach 1e-11.)"""
    def solve(tol):
        return cc.prepare(whole_face(2, 61, 2e3, Coulomb(friction=0.3, tol=tol, newton=False)), "dual").solve(
            "newton-cg")

    result = solve(1e-13)
    stop = result.extra["picard"]["stop_change"]
    assert result.status == "solved" and stop > 1e-13
    assert "above tol = 1e-13" in result.message and f"{stop / picard.NOISE:.1e}" in result.message
    assert solve(1e-6).message == ""


def test_the_soft_on_stiff_p2_caps_coulomb_problem_is_certified_on_both_paths():
    """The caps on which newton_cg.HELD (the axis node's step length from its Schur complement, since removed) was
    made: on the former trace 0.1 / P̃_jj left that node inside its disc, slipping, 5.3e-9 (friction law). With the
    symmetry planes' rows empty the disc is gone: Newton's Coulomb solve certifies it to 1e-10 on both paths (5 and
    4 steps)."""
    scene = soft_on_stiff_p2_spheres(Coulomb(friction=0.1))
    for result in (cc.solve(scene), cc.prepare(scene, "dual-matrix-free").solve()):
        assert result.status == "solved" and result.extra["history"][0]["coulomb_newton"]
        assert result.certificate.worst <= 1e-10


@pytest.mark.parametrize("newton", [True, False])
def test_a_coulomb_solve_whose_inner_solves_all_fail_is_reported(newton):
    """newton-cg held to one step (the user's max_iter, which bounds Newton's Coulomb solve too): every solve
    fails, and the result says so with the failed solve's certificate against its own slip bounds (this raised a
    TypeError: no slip bounds to certify against)."""
    scene = whole_face(2, 61, 2e3, Coulomb(friction=0.3, newton=newton))
    result = cc.prepare(scene, "dual-matrix-free").solve("newton-cg", max_iter=1)
    assert result.status == "failed" and result.solver_status == "max_iter"
    assert result.certificate is not None and result.certificate.worst > 1e-6
    assert result.extra["picard"]["attempts"][0]["outcome"] == "failed (inner solve max_iter)"


def test_newton_on_a_dense_w_starts_where_every_point_sticks():
    """On the dual with W a matrix Newton's Coulomb solve starts from the frictionless answer, solved only to
    START_TOL, every point sticking: its first natural residual is that of this guess, recomputed here."""
    model = cc.prepare(whole_face(2, 61, 2e3, Coulomb(friction=0.3)), "dual")
    result = model.solve("newton-cg")
    assert result.status == "solved" and result.extra["history"][0]["coulomb_newton"]
    frictionless, _ = model.cache[("frictionless", "newton-cg", repr([("tol", picard.START_TOL)]))]
    assert frictionless.solved and frictionless.info["natural_residual"] <= picard.START_TOL
    guess = stick_guess(model.program, frictionless, model.fem.contact)
    _, _, linear = picard.pressure_map(model)
    coupling = linear @ normal_multipliers(model.program, model.C, model.fem.contact)
    first = newton_cg.coupled(model.program, coupling, guess.x, max_iter=0).info["residuals"][0]
    assert result.extra["history"][0]["newton_residuals"][0] == pytest.approx(first, rel=1e-12)


def test_matrix_free_newton_starts_from_the_stick_answer():
    """Where W is an operator Newton starts from the stick answer's first Newton point, the points outside their
    Coulomb discs put on their edges (STICK_START), and no frictionless program is solved: its first natural residual
    is that of this start, recomputed here (every ball within its radius F λ_N)."""
    model = cc.prepare(whole_face(2, 61, 2e3, Coulomb(friction=0.3)), "dual-matrix-free")
    result = model.solve()
    assert result.status == "solved" and result.extra["history"][0]["coulomb_newton"]
    assert not any(key[0] == "frictionless" for key in model.cache if isinstance(key, tuple))
    session = newton_cg.Session(model.program)
    stuck = session.trial(model.bound_update(np.full(model.friction.count, picard.STICK_RADIUS))["b"],
                          picard.STICK_START)
    coupling = picard.radius_coupling(model, picard.pressure_map(model)[2])
    balls = newton_cg.bound_form_of(model.program).ball_vars
    x, radii = stuck.x.copy(), np.maximum(coupling @ stuck.x, 0.0)
    norms = np.linalg.norm(x[balls], axis=1)
    outside = norms > radii
    assert outside.any()  # the case this is about
    x[balls[outside]] *= (radii[outside] / norms[outside])[:, None]
    assert (np.linalg.norm(x[balls], axis=1) <= radii * (1 + 1e-12)).all()
    first = newton_cg.coupled(model.program, coupling, x, max_iter=0).info["residuals"][0]
    assert result.extra["history"][0]["newton_residuals"][0] == pytest.approx(first, rel=1e-12)


def test_a_stick_start_that_is_not_finite_gives_way_to_the_frictionless_one(monkeypatch):
    """A stick start with a NaN (an overflow of its Newton point) is no start: the frictionless one serves, and the
    answer is certified as before."""
    trial = newton_cg.Session.trial

    def overflowing(self, b, max_iter):
        solution = trial(self, b, max_iter)
        return dataclasses.replace(solution, x=np.full_like(solution.x, np.nan))

    monkeypatch.setattr(newton_cg.Session, "trial", overflowing)
    model = cc.prepare(whole_face(2, 61, 2e3, Coulomb(friction=0.3)), "dual-matrix-free")
    result = model.solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-8
    assert ("frictionless", "newton-cg", repr([("tol", picard.START_TOL)])) in model.cache


def test_a_sweep_s_next_coulomb_solve_starts_from_the_last_answer_not_a_stick_start(monkeypatch):
    """The models of a sweep share the map's newton-cg session (Model.with_law): the second law's Newton solve starts
    from the first one's answer, so no stick start is made for it (one trial in all), and both are certified."""
    trials = []
    trial = newton_cg.Session.trial
    monkeypatch.setattr(newton_cg.Session, "trial", lambda self, *args: trials.append(1) or trial(self, *args))
    model = cc.prepare(whole_face(2, 61, 2e3, Coulomb(friction=0.3)), "dual-matrix-free")
    first = model.solve()
    second = model.with_law(Coulomb(friction=0.35)).solve()
    assert first.status == second.status == "solved" and second.certificate.worst <= 1e-8
    assert second.extra["history"][0]["coulomb_newton"] and len(trials) == 1


def test_where_most_points_slip_at_the_stick_start_newton_starts_from_the_tresca_answer(monkeypatch):
    """On the 2-D pair (W an operator) most points of the stick start lie outside their Coulomb discs (TRESCA_SLIP):
    one Tresca solve follows, its slip bounds F·λ_N of the stick start's pressure (recomputed here from the start's
    recovered pressure by the Picard map's own bound), and Newton's Coulomb solve from its answer takes fewer steps
    than from the stick start (measured 4 → 2; docs/performance.md, "Coulomb's start on the pair"), or no more where
    Newton's points are on the natural map's faces at every step (RELEASE_MOVING: 2 and 2 here, and 16 Newton products
    from the stick start against 6 + 24 with the Tresca solve; at 3.5·10⁵ DOFs 124 against 35 + 33)."""
    bounds = []
    tresca_start = picard.tresca_start
    monkeypatch.setattr(picard, "tresca_start", lambda model, newton, radii: bounds.append(radii) or
                        tresca_start(model, newton, radii))
    scene = two_body_scene("coulomb", 3e3)

    def newton_steps(model):
        result = model.solve()
        assert result.status == "solved" and result.certificate.worst <= 1e-10
        assert result.extra["history"][0]["coulomb_newton"]
        return len(result.extra["history"][0]["newton_residuals"]) - 1

    model = cc.prepare(scene, "dual-matrix-free")
    tresca = newton_steps(model)
    assert len(bounds) == 1
    stuck = newton_cg.Session(model.program).trial(
        model.bound_update(np.full(model.friction.count, picard.STICK_RADIUS))["b"], picard.STICK_START)
    bound, _, _ = picard.pressure_map(model)
    np.testing.assert_allclose(bounds[0], bound(model.recover(stuck).pressure), rtol=1e-10, atol=1e-14)
    monkeypatch.setattr(picard, "TRESCA_SLIP", 1.0)  # the stick start alone
    assert tresca <= newton_steps(cc.prepare(scene, "dual-matrix-free")) and len(bounds) == 1


def test_where_a_coarse_program_begins_the_stick_start_its_answer_is_the_start(monkeypatch):
    """The 2-D pair at 2·10⁴ DOFs, forced matrix-free: the stick start's program is solved from the coarse program's
    answer (COARSE_SETS), which is the stick start itself (STICK_START counts it as its Newton step): no fine Newton
    step, 53 products with W against 58 (49 of them the coarse program's), and the Tresca start's bounds are F G S λ_N
    of that answer's pressure. At 1.4·10⁶ DOFs the fine step was 50 of the stick start's 89 products."""
    trials, bounds = [], []
    trial, tresca_start = newton_cg.Session.trial, picard.tresca_start
    monkeypatch.setattr(newton_cg.Session, "trial", lambda self, b, steps: trials.append(answer := trial(self, b, steps))
                        or answer)
    monkeypatch.setattr(picard, "tresca_start", lambda model, newton, radii: bounds.append(radii) or
                        tresca_start(model, newton, radii))
    model = cc.prepare(two_body_scene("coulomb", 2e4), "dual-matrix-free")
    result = model.solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-10
    [stuck], [bound] = trials, bounds
    assert stuck.info["coarse"] is not None and stuck.iterations == 0
    assert stuck.info["products"] == stuck.info["coarse"]["products"] + 1  # Hutchinson's (∇f: newton_cg.LIFT)
    np.testing.assert_allclose(bound, picard.pressure_map(model)[0](model.recover(stuck).pressure), rtol=1e-10,
                               atol=1e-14)


def test_the_tresca_start_is_solved_only_to_a_start_s_tolerance(monkeypatch):
    """The Tresca start only places Newton's Coulomb solve, whose first residual is the pressure's change (the pair:
    1.5e-3 at 3.2·10⁵ DOFs, 5.8e-4 at 1.4·10⁶): on the 2-D pair at 1.1·10⁴ DOFs (W an operator) solved to TRESCA_TOL
    it takes 1 Newton step, to START_TOL (before) 2, to the session's 1e-12 3, and Newton's Coulomb solve from each
    the same 2 steps and a certified answer."""
    solves = []
    solve = newton_cg.Session.solve
    monkeypatch.setattr(newton_cg.Session, "solve", lambda self, *args, **options:
                        solves.append(answer := solve(self, *args, **options)) or answer)
    scene = two_body_scene("coulomb", 6e3)

    def run(tol):
        monkeypatch.setattr(picard, "TRESCA_TOL", tol)
        solves.clear()
        result = cc.prepare(scene, "dual-matrix-free").solve()
        assert result.status == "solved" and result.certificate.worst <= 1e-10
        assert len(solves) == 1 and solves[0].solved  # the Tresca start, the session's one solve
        return solves[0].iterations, len(result.extra["history"][0]["newton_residuals"]) - 1

    assert [run(tol) for tol in (picard.TRESCA_TOL, picard.START_TOL, newton_cg.TOL)] == [(1, 2), (2, 2), (3, 2)]


@pytest.mark.parametrize("coarse", [False, True])
def test_a_large_tresca_start_is_solved_from_the_coarse_program_on_its_own_bounds(monkeypatch, coarse):
    """Where the Tresca start's program has TRESCA_COARSE unknowns or more it is solved from no start, so from the
    coarse program on the Tresca bounds (COARSE_SETS), not from the stick start: on the 2-D pair at 2·10⁴ DOFs
    (forced matrix-free, 296 unknowns; the threshold lowered to reach it) 1 fine Newton step after the coarse answer
    against 2 from the stick start, and Newton's Coulomb solve after each the same 3 steps to a certified answer. At
    1.4·10⁶ DOFs the start took 3 steps, 72 products and 18 refactorizations from the stick start, 1 step, 49 and 4 from
    the coarse answer (docs/performance.md, "The Tresca start from the coarse program on its own bounds")."""
    solves = []
    solve = newton_cg.Session.solve
    monkeypatch.setattr(newton_cg.Session, "solve", lambda self, *args, **options:
                        solves.append(answer := solve(self, *args, **options)) or answer)
    if coarse:
        monkeypatch.setattr(picard, "TRESCA_COARSE", 0)
    result = cc.prepare(two_body_scene("coulomb", 2e4), "dual-matrix-free").solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-10
    [tresca] = solves
    assert tresca.solved and (tresca.info["coarse"] is not None) == coarse
    assert tresca.iterations == (1 if coarse else 2)
    assert len(result.extra["history"][0]["newton_residuals"]) - 1 == 3


@pytest.mark.parametrize("release", [True, False])
def test_newton_s_coulomb_faces_on_intervals_are_the_natural_map_s(monkeypatch, release):
    """The 2-D block at 10⁵ DOFs (W a matrix): Newton's points on the Coulomb problem are on the natural map's faces at
    them (RELEASE_MOVING: released and flipped intervals, as with fixed radii), and Newton's Coulomb solve takes 2
    steps (6 with those faces only at refused points); with faces only grown by the sets a refused point leaves
    (before that) it crawled for 11."""
    monkeypatch.setattr(newton_cg, "RELEASE_MOVING", release)
    result = cc.prepare(scene_of("block", 2, "coulomb", 1e5), "auto").solve()
    assert result.status == "solved" and result.certificate.worst <= 1e-10
    [step] = result.extra["history"]
    assert step["coulomb_newton"] and len(step["newton_residuals"]) - 1 == (2 if release else 11)


def test_a_stall_is_left_by_the_fixed_point_map_s_step(monkeypatch):
    """Discs, F = 4 (seed 6): Newton on the Coulomb problem stalls at a natural residual of 2.6e-3 where no step may
    raise it (FIXED_STEPS = 0); one step to the Tresca answer under the radii reached (Picard's, from there) gets it
    past, and its answer is the Tresca answer for the radii it reached (Clarabel, an independent solve). The 3-D tall
    block stalled so only at 3.2·10⁵ DOFs (not at 3·10⁴ or 10⁵): this program stands in for it."""
    program, coupling = coulomb_like(np.random.default_rng(6), 12, 2, 4.0)
    monkeypatch.setattr(newton_cg, "FIXED_STEPS", 0)
    stalled = newton_cg.coupled(program, coupling, None)
    assert stalled.solver_status == "stalled" and stalled.info["natural_residual"] > 1e-4
    monkeypatch.setattr(newton_cg, "FIXED_STEPS", 3)
    answer = newton_cg.coupled(program, coupling, None)
    assert answer.status == "solved" and answer.info["fixed_steps"] == 1
    b = program.b.copy()
    b[12 + np.arange(12) * 3] = answer.info["radii"]
    tresca = solvers.solve(dataclasses.replace(program, b=b), "clarabel", tol=1e-12)
    assert np.abs(tresca.x - answer.x).max() < 1e-8 * np.abs(answer.x).max()
