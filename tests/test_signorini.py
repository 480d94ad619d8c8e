"""Signorini contact: patch test, Hertz, solver agreement, certificate (DESIGN.md cases 1, 2)."""

import dataclasses

import numpy as np
import pytest
import skfem as fe

import convexcontact as cc
from convexcontact.analytic import hertz_plane_strain, hertz_pressure
from convexcontact.scene.library import HERTZ_FORCE, hertz_punch, pressure_patch, punch_mesh


def distorted(mesh: fe.Mesh, amount: float = 0.3, seed: int = 0) -> fe.Mesh:
    """The mesh with interior vertices moved randomly by ``amount`` of the local spacing."""
    rng = np.random.default_rng(seed)
    p = mesh.p.copy()
    interior = np.setdiff1d(np.arange(p.shape[1]), mesh.boundary_nodes())
    h = mesh.param()
    p[:, interior] += amount * h * rng.uniform(-1, 1, (2, interior.size))
    return type(mesh)(p, mesh.t).with_defaults()


def with_geometry(scene, geometry, element):
    return dataclasses.replace(scene, body=cc.Body(geometry, element=element))


@pytest.mark.parametrize("element", ["P1", "Q2"])
@pytest.mark.parametrize("mesh_kind", ["structured", "distorted"])
@pytest.mark.parametrize("non_penetration", ["nodal", "weak"])
def test_uniform_pressure_patch(element, mesh_kind, non_penetration):
    """Case 1: the contact pressure equals the applied pressure at every contact node."""
    pressure = 0.37
    scene = pressure_patch(nx=6, element=element, pressure=pressure, law=cc.Signorini(non_penetration))
    if mesh_kind == "distorted":
        mesh_type = fe.MeshQuad1 if element == "Q2" else fe.MeshTri1
        grid = mesh_type.init_tensor(np.linspace(0, 1, 7), np.linspace(0, 1, 7)).with_defaults()
        scene = with_geometry(scene, distorted(grid), element)
    result = cc.solve(scene, "clarabel")
    assert result.status == "solved"
    np.testing.assert_allclose(result.contact.pressure, pressure, rtol=1e-7)
    assert np.all(result.contact.status == "closed")
    assert result.normal_force == pytest.approx(pressure * 1.0, rel=1e-7)
    assert result.certificate.passes(1e-7)


def hertz_mesh(h: float) -> fe.Mesh:
    return punch_mesh(h)


def test_hertz_force_control_converges():
    """Case 2: a and p₀ within 3% of Hertz; the pressure error shrinks on refinement."""
    a, p0 = hertz_plane_strain(HERTZ_FORCE, 1.0, 1.0, 0.3)
    pressure_errors = []
    for h in (0.02, 0.005):
        result = cc.solve(with_geometry(hertz_punch(), hertz_mesh(h), "P1"), "osqp")
        assert result.status == "solved"
        assert result.normal_force == pytest.approx(HERTZ_FORCE, rel=1e-8)
        w, s = result.fem.contact.weights, result.contact.coordinate
        exact = hertz_pressure(s, a, p0)
        pressure_errors.append(np.sqrt(w @ (result.contact.pressure - exact) ** 2 / (w @ exact**2)))
    assert result.contact_half_width == pytest.approx(a, rel=0.03)
    assert result.max_pressure == pytest.approx(p0, rel=0.03)
    coarse, fine = pressure_errors
    assert fine < coarse / 3  # about O(h) in the weighted L² norm of the pressure


@pytest.fixture(scope="module")
def hertz_model():
    return cc.prepare(hertz_punch(nx=40))


@pytest.fixture(scope="module")
def hertz_reference(hertz_model):
    return hertz_model.solve("clarabel", tol=1e-11)


@pytest.mark.parametrize("solver, rtol", [("osqp", 1e-6), ("cvxpy", 1e-6), ("cvxpy:OSQP", 1e-3)])
def test_solvers_agree(hertz_model, hertz_reference, solver, rtol):
    """Clarabel, OSQP (polished) and cvxpy give the same displacement and pressure."""
    options = {"eps_abs": 1e-7, "eps_rel": 1e-7, "polishing": True} if solver == "cvxpy:OSQP" else {}
    result = hertz_model.solve(solver, **options)
    ref = hertz_reference
    assert result.status == "solved"
    scale_u = np.abs(ref.displacement).max()
    scale_p = ref.max_pressure
    assert np.abs(result.displacement - ref.displacement).max() < rtol * scale_u
    assert np.abs(result.contact.pressure - ref.contact.pressure).max() < rtol * scale_p


def test_weak_and_nodal_agree_on_the_load(hertz_model):
    """Hild's weak non-penetration carries the same force over the same zone (within 2 cells).

    Its P1 multiplier is not compared node by node: M λ = nodal forces makes it oscillate.
    """
    weak = cc.solve(hertz_punch(nx=40, law=cc.Signorini("weak")), "clarabel")
    nodal = hertz_model.solve("clarabel")
    assert weak.normal_force == pytest.approx(nodal.normal_force, rel=1e-8)
    spacing = np.diff(np.sort(nodal.contact.coordinate[nodal.closed])).max()
    assert abs(weak.contact_half_width - nodal.contact_half_width) <= 2 * spacing
    assert weak.certificate.passes(1e-7)


def test_certificate_detects_a_perturbed_solution(hertz_model, hertz_reference):
    """Small for the solve, large when the same answer is spoiled (so the check can fail)."""
    from convexcontact.formulations.fields import ContactFields
    from convexcontact.results.certificate import certify

    fem = hertz_model.fem
    C = hertz_model.C
    scaling = fem.scaling
    u = hertz_reference.displacement[fem.free] / scaling.displacement
    pressure = hertz_reference.contact.pressure / scaling.pressure
    advance = hertz_reference.obstacle_advance / scaling.displacement
    good = certify(fem.K, fem.f, fem.contact, C, ContactFields(u, pressure, obstacle_advance=advance))
    assert good.passes(1e-8)

    pushed = ContactFields(u, pressure, obstacle_advance=advance * 1.01)  # obstacle 1% deeper: penetration
    assert certify(fem.K, fem.f, fem.contact, C, pushed).residuals["non_penetration"] > 1e-3
    pulling = ContactFields(u, pressure - 0.1 * pressure.max(), obstacle_advance=advance)
    spoiled = certify(fem.K, fem.f, fem.contact, C, pulling).residuals
    assert spoiled["pressure_sign"] > 1e-2 and spoiled["equilibrium"] > 1e-3 and spoiled["complementarity"] > 1e-3


def test_cvxpy_model_can_be_extended(hertz_model, hertz_reference):
    """A user constraint added to the cvxpy Problem is honoured and changes the answer."""
    hertz_model = cc.prepare(hertz_model.fem.scene, "primal")  # the constraint is on the primal's unknowns
    cvx = hertz_model.cvxpy()
    advance = cvx.x[-1]  # force control: the obstacle's advance is the last unknown
    limit = 0.5 * hertz_reference.obstacle_advance / hertz_model.fem.scaling.displacement
    result = hertz_model.solve("cvxpy", cvxpy_model=cvx.extended([advance <= limit]))
    assert result.status == "solved"
    assert result.obstacle_advance == pytest.approx(0.5 * hertz_reference.obstacle_advance, rel=1e-6)
    assert result.normal_force < 0.9 * hertz_reference.normal_force
    assert result.certificate.residuals["obstacle_balance"] > 0.1  # the user's constraint holds the punch back
    assert "extended" in result.message


@pytest.mark.parametrize("plane, factor", [("strain", 1 - 0.3**2), ("stress", 1.0)])
def test_patch_top_displacement_plane_strain_and_stress(plane, factor):
    """Uniaxial compression with free sides: u_y(top) = −p H (1 − ν²)/E (strain) or −p H / E (stress)."""
    scene = pressure_patch(nx=4, pressure=0.2)
    scene = dataclasses.replace(scene, body=dataclasses.replace(scene.body, plane=plane))
    result = cc.solve(scene)
    top = np.isclose(result.fem.basis.doflocs[1], 1.0 / result.fem.scaling.length)
    uy = result.displacement[result.fem.basis.nodal_dofs[1]]
    on_top = top[result.fem.basis.nodal_dofs[1]]
    np.testing.assert_allclose(uy[on_top], -0.2 * 1.0 * factor / 1.0, rtol=1e-7)


def test_body_weight_is_carried_by_the_foundation():
    """A block under its own weight b on a frictionless foundation: Σ contact force = |b| × area."""
    scene = dataclasses.replace(pressure_patch(nx=6, pressure=0.0), tractions=(), body_force=(0.0, -0.05))
    result = cc.solve(scene)
    assert result.normal_force == pytest.approx(0.05 * 1.0, rel=1e-8)
    assert result.certificate.passes(1e-8)


def test_indentation_written_in_a_gap_formula_sets_the_scale():
    """A punch written as a formula with its indentation inside solves like the same punch with depth."""
    formula = dataclasses.replace(hertz_punch(nx=24),
                                  contact=cc.Contact("top", cc.Obstacle("expression", expression="x**2/2 - 0.02")))
    shaped = dataclasses.replace(hertz_punch(nx=24),
                                 contact=cc.Contact("top", cc.Obstacle("parabolic", radius=1.0, depth=0.02)))
    a, b = cc.solve(formula), cc.solve(shaped)
    assert a.fem.scaling.displacement == pytest.approx(b.fem.scaling.displacement)
    np.testing.assert_allclose(a.contact.pressure, b.contact.pressure, rtol=1e-9, atol=1e-12 * b.max_pressure)
