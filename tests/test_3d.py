"""3-D bodies: patch test, Hertz sphere, frictional punch with the exact isotropic cone, inputs, quadrature."""

import dataclasses
import functools

import meshio
import numpy as np
import pytest
import skfem as fe

import convexcontact as cc
from convexcontact.analytic import hertz_sphere
from convexcontact.fem.basis import vector_basis
from convexcontact.fem.stiffness import stiffness
from convexcontact.scene.description import Box
from convexcontact.scene.library import HERTZ_SPHERE_FORCE, punch_3d
from convexcontact.scene.library import hertz_sphere as hertz_scene
from convexcontact.scene.meshing import build_mesh, tensor_mesh
from convexcontact.solvers import ConeNotSupported


def patch(element: str, cells=(3, 3, 3), pressure: float = 0.1, body=None) -> cc.Scene:
    """Box on a flat rigid foundation, uniform pressure on top, rollers on two sides."""
    return cc.Scene(
        name="patch3d",
        body=body or cc.Body(Box(size=(1.0, 2.0, 1.0), cells=cells), element=element),
        materials=cc.Material(E=1.0, nu=0.3),
        dirichlet=(cc.Dirichlet("left", ux=0.0), cc.Dirichlet("front", uy=0.0)),
        tractions=(cc.Traction("top", pressure=pressure),),
        contact=cc.Contact("bottom", cc.Obstacle("flat")),
    )


def perturbed(hexes: bool) -> cc.Body:
    """A box whose nodes move randomly, each coordinate only where the node is off the faces normal to
    that axis: the faces stay plane, the contact face is meshed irregularly."""
    upper = np.array([[1.0], [2.0], [1.0]])
    mesh = tensor_mesh(*(np.linspace(0.0, top, 4) for top in upper.ravel()), quads=hexes)
    p = mesh.p.copy()
    movable = (p > 1e-9) & (p < upper - 1e-9)
    p += movable * np.random.default_rng(0).uniform(-0.08, 0.08, p.shape)
    return cc.Body(dataclasses.replace(mesh, doflocs=p), element="Q1" if hexes else "P1")


@pytest.mark.parametrize("element, body", [("P1", None), ("Q1", None), ("P1", "perturbed"), ("Q1", "perturbed")])
def test_uniform_pressure_patch(element, body):
    """Case 1 in 3-D: the contact pressure is p at every node, on any mesh."""
    scene = patch(element, body=perturbed(element == "Q1") if body else None)
    result = cc.solve(scene, "clarabel")
    assert result.status == "solved" and result.fem.dim == 3
    assert np.abs(result.contact.pressure - 0.1).max() < 1e-7
    assert result.normal_force == pytest.approx(0.1 * 2.0, rel=1e-9)  # p × area (a force, not per thickness)


def test_p2_tetrahedra_need_the_weak_form():
    """∫ψ = 0 for the vertices of P2 triangles: nodal contact is refused, the weak form is exact."""
    with pytest.raises(cc.SceneError, match="weak") as error:
        cc.prepare(patch("P2", cells=(1, 1, 1)))
    assert error.value.field == "contact.non_penetration"
    weak = dataclasses.replace(patch("P2", cells=(2, 2, 1)), contact=cc.Contact("bottom", law=cc.Signorini("weak")))
    result = cc.solve(weak, "clarabel")
    assert np.abs(result.contact.pressure - 0.1).max() < 1e-7


def test_p2_tetrahedra_weak_multipliers_have_positive_means_and_keep_the_partition_of_unity():
    """The transformed multiplier basis ψ̃ = T ψ of weak rows on P2 tetrahedra: Σ ψ̃ = Σ ψ (Tᵀ1 = 1), and each ψ̃
    integrates to 2|E|/15 per facet at a vertex and |E|/5 at an edge (ψ's vertex functions to 0): the weights are
    T's rows of the boundary mass, summing to Γ_C's area."""
    weak = dataclasses.replace(patch("P2", cells=(2, 3, 1)), contact=cc.Contact("bottom", law=cc.Signorini("weak")))
    fem = cc.prepare(weak).fem
    contact = fem.contact
    np.testing.assert_allclose(np.asarray(contact.multiplier_transform.sum(axis=0)).ravel(), 1.0, rtol=0, atol=1e-15)
    vertex = contact.dofs[:, 0] // 3 < fem.mesh.p.shape[1]
    area = 2.0 / 12 / fem.scaling.length**2  # the 1 × 2 bottom face: 2 × 3 squares, each cut into two triangles
    facets = np.concatenate([contact.weights[vertex] / (2 * area / 15), contact.weights[~vertex] / (area / 5)])
    np.testing.assert_allclose(facets, np.round(facets), rtol=0, atol=1e-12)  # whole numbers of facets at each node
    assert facets.min() >= 1 and contact.weights.sum() == pytest.approx(12 * area, rel=1e-12)


def test_p2_tetrahedra_hertz_sphere_against_the_closed_form():
    """Weak contact on P2 tetrahedra with the transformed multipliers (hertz_sphere(4, "P2"), 1,800 DOFs): the
    sphere's approach, the contact radius and the peak pressure near Hertz's (measured 0.92 a²/R, the box's own
    compliance, as P1 at 5,772 DOFs: 0.91; a 1.07 a; p_max 1.30 p₀). With ψ's zero-mean vertex functions as
    multipliers the same scene read 14 a²/R, 10.8 a and 70 p₀ (docs/estimate.md, "P2 tetrahedra's weak multiplier")."""
    a, p0 = hertz_sphere(HERTZ_SPHERE_FORCE, 1.0, 1.0, 0.3)
    result = cc.solve(hertz_scene(4, "P2", law=cc.Signorini(non_penetration="weak")))
    assert result.certificate.passes(1e-8)
    assert 0.85 <= result.obstacle_advance / a**2 <= 1.0
    assert result.contact_half_width == pytest.approx(a, rel=0.15)
    assert result.max_pressure == pytest.approx(p0, rel=0.35)


@functools.cache
def linear_and_quadratic_meshes():
    """Hertz's box on P2 tetrahedra, solved on its MeshTet1 and on the same straight mesh as a MeshTet2 (as gmsh's
    second-order files are read: p holds the edge nodes too)."""
    scene = hertz_scene(4, "P2", law=cc.Signorini(non_penetration="weak"))
    mesh = build_mesh(scene.body)
    quadratic = fe.MeshTet2.from_mesh(mesh)
    quadratic = dataclasses.replace(quadratic, _boundaries=mesh._boundaries, _subdomains=mesh._subdomains)
    return tuple(cc.solve(dataclasses.replace(scene, body=dataclasses.replace(scene.body, geometry=m)))
                 for m in (mesh, quadratic))


def test_p2_tetrahedra_on_a_quadratic_mesh_take_the_same_transformed_multipliers():
    """The transform counted a MeshTet2's edge nodes as vertices, so ψ̃ was ψ there and Hertz's box read an approach
    15× and a peak 54× the linear mesh's, `inaccurate`: the two meshes now give the same answer."""
    linear, quadratic = linear_and_quadratic_meshes()
    assert quadratic.solved and quadratic.fem.n_free == linear.fem.n_free
    assert quadratic.obstacle_advance == pytest.approx(linear.obstacle_advance, rel=1e-9)
    np.testing.assert_allclose(quadratic.contact.pressure, linear.contact.pressure, atol=1e-9 * linear.max_pressure)


def test_a_result_on_a_quadratic_mesh_is_written_at_every_node(tmp_path):
    """solution.vtu of a MeshTet2 has a point at every P2 node: the displacement there is the DOFs' (vertices then
    edges), the vertices' equal to the linear mesh's result. Before, writing it failed on a shape mismatch."""
    linear, quadratic = linear_and_quadratic_meshes()
    quadratic.save(tmp_path)
    written = meshio.read(tmp_path / "solution.vtu")
    assert len(written.points) == quadratic.fem.mesh.p.shape[1] > quadratic.fem.mesh.nvertices
    displacement = written.point_data["displacement"]
    np.testing.assert_allclose(displacement, quadratic.displacement.reshape(-1, 3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(displacement[:linear.fem.mesh.nvertices],
                               linear.displacement[linear.fem.basis.nodal_dofs].T, rtol=0, atol=1e-12)
    pressure = written.point_data["contact_pressure"]
    assert pressure.max() == pytest.approx(quadratic.max_pressure, rel=1e-12)


def test_p2_tetrahedra_gauss_point_pressures_are_moments_of_the_transformed_basis():
    """Gauss-point rows on P2 tetrahedra report ∫p ψ̃_i / ∫ψ̃_i at the nodes (the point forces' moments with the
    transformed basis): near Hertz's peak (measured 0.89 p₀ at 4 cells), where the force over ∫ψ̃_i read 1.40 p₀
    (a vertex's ∫p ψ_i is ~0 for a smooth p) and over ψ's own ∫ψ_i ≈ 1e-19 anything at all."""
    _, p0 = hertz_sphere(HERTZ_SPHERE_FORCE, 1.0, 1.0, 0.3)
    result = cc.solve(hertz_scene(4, "P2", law=cc.Signorini(non_penetration="gauss")))
    assert result.certificate.passes(1e-8)
    assert result.max_pressure == pytest.approx(p0, rel=0.2)
    assert result.contact.pressure.min() > -0.01 * p0


def test_hertz_sphere():
    """3-D Hertz (quarter model, 12³ graded P1 cells, 5.8k DOFs): a and p₀ within 5%.

    Measured (docs/scenes.md): p_max +4.0 / +3.6 / +3.3 %, fitted a −1.6 / −0.6 / +0.1 % at
    12 / 16 / 20 cells; examples/hertz_sphere.py runs the finer meshes.
    """
    result = cc.solve(hertz_scene(12), "clarabel")
    a, p0 = hertz_sphere(HERTZ_SPHERE_FORCE, 1.0, 1.0, 0.3)
    assert result.certificate.passes(1e-8)
    assert 4 * result.normal_force == pytest.approx(HERTZ_SPHERE_FORCE, rel=1e-8)  # force control
    assert result.max_pressure == pytest.approx(p0, rel=0.05)
    assert result.contact_half_width == pytest.approx(a, rel=0.05)
    fitted_p0, fitted_a = fit_hertz(result)
    assert fitted_p0 == pytest.approx(p0, rel=0.05) and fitted_a == pytest.approx(a, rel=0.05)


def fit_hertz(result) -> tuple[float, float]:
    """p0, a of p² = p0²(1 − r²/a²) fitted to the nodes carrying more than 30% of the peak."""
    p, r = result.contact.pressure, result.contact.radius
    inside = p > 0.3 * p.max()
    (c0, c1), *_ = np.linalg.lstsq(np.column_stack([np.ones(inside.sum()), r[inside] ** 2]), p[inside] ** 2, rcond=None)
    return float(np.sqrt(c0)), float(np.sqrt(-c0 / c1))


def swapped(contact) -> np.ndarray:
    """Index of each contact node's mirror image under x ↔ y."""
    key = {tuple(np.round(xyz, 9)): i for i, xyz in enumerate(contact.coords)}
    return np.array([key[tuple(np.round(xyz[[1, 0, 2]], 9))] for xyz in contact.coords])


@pytest.fixture(scope="module")
def coulomb_punch():
    """Rounded punch, Coulomb F = 0.3, quarter model of Q1 hexes (symmetric under x ↔ y): primal and dual."""
    scene = punch_3d(10, law=cc.Coulomb(friction=0.3, tol=1e-7))
    return cc.prepare(scene, "primal").solve("cvxpy"), cc.prepare(scene, "dual").solve("clarabel")


def test_coulomb_punch_stick_zone(coulomb_punch):
    """Stick in the middle, slip at the edge, ‖λ_T‖ = Fλ_N in slip, ≤ everywhere, symmetric under x ↔ y."""
    result = coulomb_punch[0]
    # cvxpy's Clarabel may call the fixed point's inner solve optimal_inaccurate: then the status says so,
    # and the certificate decides
    assert result.status in ("solved", "inaccurate") and result.certificate.passes(1e-6)
    c = result.contact
    stick, slip = c.status == "stick", c.status == "slip"
    assert stick.sum() >= 3 and slip.sum() >= 3
    assert c.radius[stick].max() < c.radius[slip].min()  # a central stick zone, a slip ring
    assert stick[np.argmin(c.radius)]  # the node on the axis sticks
    p_max = c.pressure.max()
    magnitude = c.friction_magnitude
    assert c.friction.shape == (result.fem.contact.m, 2)
    assert np.abs(magnitude[slip] - 0.3 * c.pressure[slip]).max() < 1e-6 * p_max
    assert (magnitude <= 0.3 * c.pressure + 1e-6 * p_max).all()  # within the certificate's 1e-6, as slip above
    mirror = swapped(c)
    assert (c.status[mirror] == c.status).all()
    assert np.abs(c.friction[mirror][:, ::-1] - c.friction).max() < 1e-5 * p_max  # t1 = x, t2 = y swap too
    # the shear points along the radius (axisymmetric problem): no circumferential component
    radial = c.coords[:, :2] / np.maximum(c.radius, 1e-300)[:, None]
    circumferential = radial[:, 0] * c.friction[:, 1] - radial[:, 1] * c.friction[:, 0]
    assert np.abs(circumferential).max() < 0.05 * magnitude.max()


def test_coulomb_punch_primal_and_dual_agree(coulomb_punch):
    primal, dual = coulomb_punch
    assert dual.certificate.worst < 1e-6
    p_max = primal.contact.pressure.max()
    assert np.abs(primal.contact.pressure - dual.contact.pressure).max() < 1e-5 * p_max
    assert np.abs(primal.contact.friction - dual.contact.friction).max() < 1e-5 * p_max
    assert (primal.contact.status == dual.contact.status).all()


def test_tresca_clarabel_and_cvxpy_agree():
    """The exact SOC(3) friction cone through both paths: ‖λ_T‖ = s where the point slips."""
    model = cc.prepare(punch_3d(6, law=cc.Tresca(slip_bound=0.004)), "primal")
    assert {cone.dim for cone in model.program.cones if cone.kind == "soc"} == {3}
    native, modelled = model.solve("clarabel"), model.solve("cvxpy")
    for result in (native, modelled):
        assert result.certificate.passes(1e-6)
    slip = native.contact.status == "slip"
    assert slip.any() and (native.contact.status == "stick").any()
    assert np.abs(native.contact.friction_magnitude[slip] - 0.004).max() < 1e-6 * native.max_pressure
    assert np.abs(native.contact.friction - modelled.contact.friction).max() < 1e-5 * native.max_pressure
    assert np.abs(native.contact.pressure - modelled.contact.pressure).max() < 1e-5 * native.max_pressure


def test_osqp_refuses_the_3d_friction_cone_and_solves_3d_signorini():
    with pytest.raises(ConeNotSupported, match="3-D friction cone"):
        cc.solve(punch_3d(2, law=cc.Tresca(slip_bound=0.01)), "osqp", formulation="primal")
    result = cc.solve(patch("Q1", cells=(2, 2, 2)), "osqp")
    assert result.status == "solved" and np.abs(result.contact.pressure - 0.1).max() < 1e-7


@pytest.mark.parametrize("change, field", [
    (lambda s: dataclasses.replace(s, dirichlet=(cc.Dirichlet("left", ux=0.0, uz=0.1),)), None),
    (lambda s: dataclasses.replace(s, tractions=(cc.Traction("top", vector=(0.0, -0.1)),)), "traction[top].vector"),
    (lambda s: dataclasses.replace(s, body_force=(0.0, 1.0)), "body_force"),
    (lambda s: dataclasses.replace(s, body=cc.Body(s.body.geometry, plane="stress")), "body.plane"),
    (lambda s: dataclasses.replace(s, contact=cc.Contact("bottom", cc.Obstacle("parabolic", radius=1.0, center=0.5))),
     "obstacle.center"),
    (lambda s: dataclasses.replace(s, contact=cc.Contact("bottom", cc.Obstacle("cylinder", radius=9.0))),
     "obstacle.shape"),
])
def test_bad_3d_input_names_the_field(change, field):
    if field is None:  # a valid 3-D scene: uz is accepted
        assert cc.prepare(change(patch("P1", cells=(1, 1, 1)))).fem.dim == 3
        return
    with pytest.raises(cc.SceneError) as error:
        cc.prepare(change(patch("P1", cells=(1, 1, 1))))
    assert error.value.field == field


def test_bad_component_input_names_the_field():
    with pytest.raises(cc.SceneError) as error:
        cc.prepare(dataclasses.replace(cc.library.pressure_patch(nx=2), dirichlet=(cc.Dirichlet("left", uz=0.0),)))
    assert error.value.field == "dirichlet[left].uz"
    for bad, field in (((1, 2, 3, 4), "traction[top].vector"), ((1.0,), "traction[top].vector")):
        with pytest.raises(cc.SceneError) as error:
            cc.Traction("top", vector=bad)
        assert error.value.field == field
    with pytest.raises(cc.SceneError) as error:
        Box(cells=(2, 2))
    assert error.value.field == "body.cells"


@pytest.mark.parametrize("mesh_type, element", [
    (fe.MeshTet1, "P1"), (fe.MeshTet1, "P2"), (fe.MeshHex1, "Q1"), (fe.MeshHex1, "Q2"),
    (fe.MeshTri1, "P1"), (fe.MeshTri1, "P2"), (fe.MeshQuad1, "Q1"), (fe.MeshQuad1, "Q2"),
])
def test_chosen_quadrature_gives_the_default_stiffness(mesh_type, element):
    """K with the chosen intorder equals scikit-fem's default (2·maxdeg) to round-off."""
    solid = mesh_type in (fe.MeshTet1, fe.MeshHex1)
    axes = [np.array([0.0, 0.3, 1.0]), np.array([0.0, 0.7, 2.0]) if solid else np.array([0.0, 0.5, 0.7, 2.0]),
            np.array([0.0, 1.5])]
    mesh = mesh_type.init_tensor(*axes[: 3 if solid else 2])
    lame = (np.full(mesh.t.shape[1], 0.6), np.full(mesh.t.shape[1], 0.4))
    chosen = vector_basis(mesh, element)
    default = vector_basis(mesh, element, intorder=2 * chosen.elem.elem.maxdeg)
    assert chosen.X.shape[-1] < default.X.shape[-1]
    K, K_default = stiffness(chosen, lame), stiffness(default, lame)
    assert abs(K - K_default).max() < 1e-12 * abs(K_default).max()


def test_toml_box_scene_is_the_library_scene():
    from pathlib import Path

    from convexcontact.scene import load_scene

    loaded = load_scene(Path(__file__).resolve().parents[1] / "examples" / "scenes" / "hertz_sphere.toml")
    built = hertz_scene(12)
    assert loaded.body == built.body and loaded.dirichlet == built.dirichlet
    assert loaded.contact.obstacle.force == pytest.approx(built.contact.obstacle.force, rel=1e-12)
    assert dataclasses.replace(loaded.contact.obstacle, force=None) == dataclasses.replace(built.contact.obstacle,
                                                                                           force=None)


def test_a_stalled_interior_point_is_retried_until_it_solves():
    """A sheared 3-D Tresca block (found by the fuzz suite): Clarabel stalls at 1e-12 and 1e-11 and solves at
    1e-10; the primal's answer then agrees with the polished dual's."""
    from convexcontact.scene.description import Box

    scene = cc.Scene(name="sheared", body=cc.Body(Box(size=(1.0, 1.0, 0.5), cells=(3, 3, 3),
                                                      origin=(-0.5, -0.5, 0.0)), "P1"),
                     materials=cc.Material(1.0, 0.0), dirichlet=(cc.Dirichlet("top", ux=5e-4, uy=0.0, uz=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("parabolic", radius=2.0, center=(0.0, 0.0, 0.0),
                                                              depth=1e-3), cc.Tresca(slip_bound=5e-4)))
    primal, dual = (cc.prepare(scene, form).solve("clarabel") for form in ("primal", "dual"))
    assert primal.status == dual.status == "solved"
    assert np.abs(primal.displacement - dual.displacement).max() < 1e-8 * np.abs(dual.displacement).max()
