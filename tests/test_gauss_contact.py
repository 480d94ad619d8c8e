"""Non-penetration at the Gauss points of Γ_C (``Signorini("gauss")``): the limit of penalty codes that
penalize at quadrature points, with the obstacle's gap evaluated at each point (issue 14)."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.scene.library import hertz_punch, pressure_patch

R = 2.0


def cylinder(normal, law, force=0.0086307):
    """The Hertz block [-2, 2] × [-2, 0] pressed by a cylinder of radius R = 2 (force control)."""
    obstacle = cc.Obstacle("cylinder", radius=R, force=force, normal=normal)
    return dataclasses.replace(hertz_punch(nx=40), contact=cc.Contact("top", obstacle, law))


def test_on_a_flat_obstacle_gauss_points_add_nothing_to_the_nodes():
    """With P1 facets and an affine gap, u_N − g is affine on each facet: it is ≤ 0 at the Gauss points
    exactly when it is at the nodes. The answers agree, the nodal pressures too (uniform patch)."""
    nodal = cc.solve(pressure_patch(nx=8))
    gauss = cc.solve(pressure_patch(nx=8, law=cc.Signorini("gauss")))
    assert gauss.status == "solved" and gauss.certificate.passes(1e-12)
    assert np.abs(gauss.displacement - nodal.displacement).max() < 1e-10 * np.abs(nodal.displacement).max()
    assert np.allclose(gauss.contact.pressure, 0.1, rtol=1e-9)


@pytest.mark.parametrize("normal", ["body", "obstacle"])
def test_the_gap_at_the_points_is_the_obstacles_and_holds_there(normal):
    """The gap at each Gauss point is the cylinder's own there (closed form, not the nodal gap
    interpolated), and the answer keeps u_N(x_q) ≤ g(x_q) at every point, touching at some."""
    result = cc.solve(cylinder(normal, cc.Signorini("gauss")))
    assert result.status == "solved" and result.formulation == "primal" and result.certificate.passes(1e-10)
    trace, scaling = result.fem.contact, result.fem.scaling
    points = trace.points
    x = points.coords[:, 0] * scaling.length
    d = result.obstacle_advance  # force control: the frame at first touch, the advance entering linearly
    closed_form = np.sqrt(x**2 + R**2) - R if normal == "obstacle" else R - np.sqrt(R**2 - x**2)
    assert np.allclose(points.gap * scaling.displacement, closed_form, rtol=0, atol=1e-14)
    interpolated = points.interpolation @ trace.gap
    assert np.abs(interpolated - points.gap).max() > 1e-3 * np.abs(points.gap).max()  # not the nodal gap
    coupling = points.interpolation @ trace.obstacle_coupling
    u_N = points.interpolation @ (trace.N @ (result.displacement[result.fem.free] / scaling.displacement)
                                  + trace.normal_offset)
    gap = (points.gap - u_N - coupling * d / scaling.displacement) * scaling.displacement
    assert gap.min() > -1e-12 * 0.01 and (gap < 1e-12).sum() >= 2


def test_gauss_points_and_nodes_differ_by_the_curvature_between_nodes():
    """Against a curved obstacle the Gauss law is stiffer (more points must stay out): less approach
    for the same force, by a fraction that shrinks as the mesh is refined."""
    differences = []
    for nx in (20, 40):
        nodal, gauss = (cc.solve(dataclasses.replace(cylinder("body", law), body=dataclasses.replace(
            hertz_punch(nx=nx).body))) for law in (cc.Signorini(), cc.Signorini("gauss")))
        assert gauss.obstacle_advance < nodal.obstacle_advance
        differences.append((nodal.obstacle_advance - gauss.obstacle_advance) / nodal.obstacle_advance)
    assert differences[1] < 0.7 * differences[0]


def test_nodal_pressure_is_unique_where_point_multipliers_are_not():
    """More touching points than nodes: the point multipliers are not unique (said in not_unique), their
    nodal force is: the primal by Clarabel and by cvxpy report the same nodal pressure."""
    scene = cylinder("obstacle", cc.Signorini("gauss"))
    clarabel, cvx = (cc.prepare(scene, "primal").solve(solver) for solver in ("clarabel", "cvxpy:CLARABEL"))
    assert "pressure_at_points" in clarabel.not_unique
    scale = clarabel.contact.pressure.max()
    assert np.abs(clarabel.contact.pressure - cvx.contact.pressure).max() < 1e-6 * scale


def test_gauss_point_options_are_checked():
    with pytest.raises(cc.SceneError, match="contact.order.*non_penetration = 'gauss'"):
        cc.Signorini(order=4)
    with pytest.raises(cc.SceneError, match="contact.non_penetration.*frictionless law only"):
        cc.Tresca(slip_bound=0.01, non_penetration="gauss")
    with pytest.raises(cc.SceneError, match="contact.order"):
        cc.Signorini("gauss", order=0)
    with pytest.raises(cc.SceneError, match="contact.non_penetration.*'nodal', 'gauss'"):
        cc.NormalCompliance(1e3, non_penetration="weak")
    with pytest.raises(cc.SceneError, match="contact.compliance.*lumped node-wise"):
        cc.Coulomb(friction=0.3, compliance=cc.NormalCompliance(1e3, non_penetration="gauss"))


def test_the_penalty_at_the_points_tends_to_the_gauss_point_law():
    """NormalCompliance(c_N, non_penetration='gauss'): Σ_q ω_q c_N/2 (u_N(x_q) − g(x_q))₊², exact at each c_N
    (certificate), its displacement error against Signorini('gauss') like 1/c_N: a fitted slope ≤ −0.8 over
    four decades (measured −0.86; the contact zone still changes between decades), each two decades at
    least tenfold."""
    exact = cc.solve(cylinder("obstacle", cc.Signorini("gauss")))
    stiffness, errors = np.array([1e1, 1e3, 1e5]), []
    for c in stiffness:
        penalty = cc.solve(cylinder("obstacle", cc.NormalCompliance(c, non_penetration="gauss")))
        assert penalty.status == "solved" and penalty.certificate.passes(1e-10)
        assert "pressure_at_points" not in penalty.not_unique  # c e at each point: unique
        errors.append(np.abs(penalty.displacement - exact.displacement).max() / np.abs(exact.displacement).max())
    errors = np.array(errors)
    assert np.all(errors[1:] / errors[:-1] < 0.1)
    assert np.polyfit(np.log(stiffness), np.log(errors), 1)[0] <= -0.8


@pytest.mark.parametrize("quadrature", ["nodal", "gauss"])
def test_a_node_held_tangentially_is_flagged_and_the_rest_agrees_across_solvers(quadrature):
    """The patch's bottom-left node has its ux prescribed (a roller), and it sticks. Its friction force goes into
    the support: with Gauss points its share of the point tractions differed between solvers (Clarabel −1.263e-3,
    OSQP −1.234e-3) while not_unique said nothing. Both quadratures report it as 0 and say so; every other node's
    friction traction is the same from both solvers."""
    scene = pressure_patch(nx=4, law=cc.Tresca(0.05, quadrature=quadrature))
    clarabel, osqp = (cc.prepare(scene, "primal").solve(solver) for solver in ("clarabel", "osqp"))
    held = np.isclose(clarabel.contact.coords[:, 0], 0.0)
    assert held.sum() == 1 and clarabel.contact.status[held][0] == "stick"
    for result in (clarabel, osqp):
        assert result.status == "solved" and "prescribed tangential displacement" in result.not_unique["friction"]
        assert result.contact.friction[held][0] == 0.0
    assert np.abs(clarabel.contact.friction - osqp.contact.friction).max() < 1e-6 * 0.05
    assert np.abs(clarabel.contact.friction[~held]).min() > 1e-3  # sticking and slipping nodes carry friction


def test_a_node_held_normally_reports_no_pressure_at_gauss_points_either():
    """The patch clamped on its left side: the corner's normal displacement is prescribed, and not_unique said its
    pressure was reported as 0 — but from the Gauss points' multipliers it was 0.0954 with Clarabel and 0.0723 with
    OSQP. Now 0 from both, and the other nodes' pressures agree."""
    scene = dataclasses.replace(pressure_patch(nx=4, law=cc.Signorini("gauss")),
                                dirichlet=(cc.Dirichlet("left", ux=0.0, uy=0.0),))
    clarabel, osqp = (cc.prepare(scene, "primal").solve(solver) for solver in ("clarabel", "osqp"))
    held = np.isclose(clarabel.contact.coords[:, 0], 0.0)
    for result in (clarabel, osqp):
        assert result.status == "solved" and "prescribed normal displacement" in result.not_unique["pressure"]
        assert result.contact.pressure[held][0] == 0.0
    assert np.abs(clarabel.contact.pressure - osqp.contact.pressure).max() < 1e-6 * 0.1
    assert clarabel.contact.pressure[~held].min() > 0.01
