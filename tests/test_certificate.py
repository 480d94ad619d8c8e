"""The certificate bounds the error: natural-map residuals grow like δ, not δ² (issue 10)."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp
from test_friction_hild import triangle_scene

import convexcontact as cc
from convexcontact import solvers
from convexcontact.fem.friction import FrictionPoints
from convexcontact.formulations.fields import ContactFields
from convexcontact.results.certificate import certify, friction_residuals

NU = 0.3
GRAZING = ((3 - 4 * NU) * -1.0, -1.0)  # F1 = (3 − 4ν) F2: node A touches with zero pressure (Hild, Prop. 4.1)


def grazing_answer():
    """The exact answer of Hild's triangle at the grazing load (OSQP polished), its model and node A."""
    model = cc.prepare(triangle_scene(*GRAZING, cc.Signorini()), "primal")
    fields = model.recover(solvers.solve(model.program, "osqp"))
    a = int(np.argmin(np.linalg.norm(model.fem.contact.coords, axis=1)))
    return model, fields, a


def test_grazing_answer_is_exact():
    """The reference the perturbations start from: zero gap and zero pressure at A, certificate at round-off."""
    model, fields, a = grazing_answer()
    fem = model.fem
    assert abs(fields.pressure[a]) < 1e-14
    assert abs((fem.contact.N @ fields.u)[a] - fem.contact.gap[a]) < 1e-14
    assert certify(fem.K, fem.f, fem.contact, model.C, fields).worst < 1e-12


@pytest.mark.parametrize("delta", [1e-4, 1e-6, 1e-8])
def test_an_open_and_pressed_node_costs_delta_not_delta_squared(delta):
    """Open A by δ and press it by δ: the product λ_N(u_N − g) would be δ²; the natural map is δ."""
    model, fields, a = grazing_answer()
    fem = model.fem
    row = fem.contact.N[a].toarray().ravel()
    pressure = fields.pressure.copy()
    pressure[a] += delta
    spoiled = dataclasses.replace(fields, u=fields.u - delta * row / (row @ row), pressure=pressure)
    residual = certify(fem.K, fem.f, fem.contact, model.C, spoiled).residuals["complementarity"]
    assert 0.5 * delta <= residual <= 2 * delta


def single_point(slip: float) -> FrictionPoints:
    """One friction point of unit weight whose slip is u itself."""
    identity = sp.identity(1, format="csr")
    return FrictionPoints(R=identity, offset=np.zeros(1), weights=np.ones(1), interpolation=identity,
                          coords=np.zeros((1, 1)), coupling=None)


@pytest.mark.parametrize("delta", [1e-4, 1e-6, 1e-8])
def test_a_point_that_slips_below_the_bound_costs_delta(delta):
    """|λ_T| = s − δ while the point slips by δ: the product λ_T|v| + s v is δ²; the projection residual is δ."""
    s = 0.5
    fields = ContactFields(u=np.array([delta]), pressure=np.ones(1), friction=np.array([-(s - delta)]))
    residuals = friction_residuals(single_point(delta), fields, np.array([s]), p_ref=1.0, u_ref=1.0)
    assert residuals["friction_bound"] == 0.0
    assert 0.5 * delta <= residuals["friction_law"] <= 2 * delta


@pytest.mark.parametrize("traction, slip, exact", [(-0.5, 0.3, True), (0.2, 0.0, True), (-0.5, 0.0, True),
                                                   (0.2, 0.3, False), (0.5, 0.3, False)])
def test_friction_law_residual_vanishes_exactly_on_the_law(traction, slip, exact):
    """Slip with λ_T = −s v/|v|, stick inside or on the bound: zero; a wrong direction or magnitude: not."""
    fields = ContactFields(u=np.array([slip]), pressure=np.ones(1), friction=np.array([traction]))
    residual = friction_residuals(single_point(slip), fields, np.array([0.5]), 1.0, 1.0)["friction_law"]
    assert (residual == 0.0) == exact


@pytest.mark.parametrize("solver", ["clarabel", "cvxpy", "osqp"])
@pytest.mark.parametrize("formulation", ["primal", "dual"])
@pytest.mark.parametrize("friction", [0.5, 1.5])
def test_grazing_coulomb_is_settled_exactly_on_every_path(solver, formulation, friction):
    """The interior point leaves A open by 2e-5 and pressed by 1e-5; the polish settles the active set."""
    result = cc.solve(triangle_scene(*GRAZING, cc.Coulomb(friction=friction)), solver, formulation=formulation)
    assert result.status == "solved", result.message
    a = int(np.argmin(np.linalg.norm(result.contact.coords, axis=1)))
    assert abs(result.contact.pressure[a]) < 1e-12 and abs(result.contact.normal_displacement[a]) < 1e-12
    assert result.certificate.passes(1e-10)


@pytest.mark.parametrize("solver", ["clarabel", "cvxpy", "osqp"])
@pytest.mark.parametrize("formulation", ["primal", "dual"])
def test_an_obstacle_no_node_touches_gives_no_force(solver, formulation):
    """No load, nearest gap 1.1e-4: u = 0 and λ = 0 exactly, not a closed node with a round-off pressure."""
    base = cc.library.pressure_patch(nx=8)
    scene = dataclasses.replace(
        base, tractions=(), dirichlet=(cc.Dirichlet("left", ux=0.0, uy=0.0),),
        contact=cc.Contact("bottom", cc.Obstacle("expression", expression="1.1e-4 + 0.01*x*x"),
                           cc.Tresca(slip_bound=0.01)))
    result = cc.solve(scene, solver, formulation=formulation)
    assert result.status == "solved", result.message
    assert not result.closed.any()
    assert np.abs(result.displacement).max() < 1e-14 and np.abs(result.contact.forces).max() < 1e-14


def test_quantities_the_problem_does_not_fix_are_flagged():
    """Gauss-point tractions that stick on more points than nodes, a clamped contact node, Coulomb."""
    law = cc.Tresca(slip_bound=1.0, quadrature="gauss")  # a large bound: everything sticks
    result = cc.solve(triangle_scene(0.5, -1.0, law), "clarabel")
    assert result.status == "solved"
    assert "pressure" in result.not_unique  # node B is clamped
    assert "friction_at_points" not in result.not_unique  # one facet: 2 Gauss points on 2 nodes
    punch = cc.solve(cc.library.tresca_punch(nx=16, slip_bound=1.0).with_law(law), "clarabel")
    assert punch.status == "solved" and "friction_at_points" in punch.not_unique
    assert "friction_at_points" in punch.summary()["not_unique"]
    nodal = cc.solve(cc.library.tresca_punch(nx=16, slip_bound=1.0), "clarabel")
    assert "friction_at_points" not in nodal.not_unique
    coulomb = cc.solve(triangle_scene(0.5, -1.0, cc.Coulomb(friction=0.5)), "clarabel")
    assert "solution" in coulomb.not_unique


def test_weak_friction_on_p2_tetrahedra_measures_slips_as_lengths():
    """Weak contact on P2 tetrahedra weighs the rows by the transformed multipliers' ∫ψ̃_k > 0 (ψ's vertex functions
    integrate to 0, and a weighted slip (M v)_k divided by that was no length: the natural map's step ρ there was
    1e18, and the 13,328-DOF level of the 3-D Tresca family came back `inaccurate`). A weighted slip over its weight
    is bounded by the largest nodal slip times the row's Σ_j |(T M)_kj| / ∫ψ̃_k."""
    from convexcontact.scene.description import Obstacle, Tresca
    from convexcontact.scene.library import HERTZ_SPHERE_FORCE, quarter_box

    obstacle = Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0), force=HERTZ_SPHERE_FORCE / 4)
    scene = quarter_box(2, "P2", 1.0, obstacle, Tresca(slip_bound=0.005, non_penetration="weak"), "p2", size=0.4)
    model = cc.prepare(scene, "dual")
    friction, contact = model.friction, model.fem.contact
    spread = np.asarray(abs(contact.mass).sum(axis=1)).ravel() / friction.weights
    assert friction.weights.min() > 0 and spread.max() < 3
    result = cc.solve(scene, "clarabel", formulation="dual")
    u = result.displacement[model.fem.free] / model.fem.scaling.displacement
    nodal = friction.components(contact.T @ u + contact.tangent_offset)
    slips = friction.components(friction.slip(u)) / friction.weights[:, None]
    assert np.all(np.abs(slips).max(axis=1) <= np.abs(nodal).max() * spread * (1 + 1e-12))
    assert result.certificate.residuals["friction_law"] < 1e-9


@pytest.mark.parametrize("status, worst, expected, said", [
    ("inaccurate", 8.5e-13, "inaccurate", "certificate passes (worst 8.5e-13"),  # was an empty message
    ("inaccurate", 1e-3, "inaccurate", "worst residual is 1.0e-03"),
    ("solved", 1e-3, "inaccurate", "worst residual is 1.0e-03"),
    ("solved", 1e-12, "solved", ""),
])
def test_a_result_s_status_says_why_it_is_inaccurate(status, worst, expected, said):
    from convexcontact.conic import ConicSolution
    from convexcontact.drivers.prepared import judge
    from convexcontact.results.certificate import Certificate

    solution = ConicSolution(x=np.zeros(1), z=np.zeros(1), s=np.zeros(1), status=status, solver_status="max_iter",
                             iterations=30, solve_time=0.0, solver="newton-cg")
    verdict, message = judge(solution, Certificate({"complementarity": worst}), extended=False)
    assert verdict == expected and said in message and (said or not message)
