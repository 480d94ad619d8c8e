"""Bad input gets a clear error naming the field; infeasible scenes are reported, not crashed."""

import dataclasses

import meshio
import numpy as np
import pytest
import skfem as fe

import convexcontact as cc
from convexcontact.scene.library import hertz_punch, pressure_patch


def error_field(build):
    with pytest.raises(cc.SceneError) as caught:
        build()
    return caught.value.field


def test_unknown_boundary_names_the_field_and_lists_the_names():
    scene = dataclasses.replace(pressure_patch(), contact=cc.Contact("botom"))
    with pytest.raises(cc.SceneError, match="bottom") as caught:
        cc.solve(scene)
    assert caught.value.field == "contact.boundary"
    scene = dataclasses.replace(pressure_patch(), dirichlet=(cc.Dirichlet("west", ux=0.0),))
    assert error_field(lambda: cc.solve(scene)) == "dirichlet[west].boundary"


def test_empty_contact_boundary():
    mesh = fe.MeshTri.init_tensor(np.linspace(0, 1, 3), np.linspace(0, 1, 3)).with_defaults()
    mesh = mesh.with_boundaries({"nowhere": lambda x: x[0] > 2.0})
    scene = dataclasses.replace(pressure_patch(), body=cc.Body(mesh), contact=cc.Contact("nowhere"))
    assert error_field(lambda: cc.solve(scene)) == "contact.boundary"


@pytest.mark.parametrize(
    "build, field",
    [
        (lambda: dataclasses.replace(pressure_patch(), dirichlet=()), "dirichlet"),
        (lambda: cc.Material(E=1.0, nu=0.5), "material.nu"),
        (lambda: cc.Material(E=1.0, nu=-1.0), "material.nu"),
        (lambda: cc.Material(E=0.0, nu=0.3), "material.E"),
        (lambda: cc.Material(E=float("nan"), nu=0.3), "material.E"),
        (lambda: cc.Traction("top", pressure=float("nan")), "traction[top].pressure"),
        (lambda: cc.Obstacle("parabolic", radius=1.0, depth=float("inf")), "obstacle.depth"),
        (lambda: cc.Obstacle("parabolic", radius=-1.0), "obstacle.radius"),
        (lambda: cc.Obstacle("parabolic", radius=1.0, depth=0.1, force=1.0), "obstacle"),
        (lambda: cc.Obstacle("expression", expression="__import__('os')"), "obstacle.expression"),
        (lambda: cc.Rectangle(nx=0), "body.nx"),
        (lambda: cc.Body(cc.Rectangle(), element="P3"), "body.element"),
    ],
)
def test_bad_values_name_their_field(build, field):
    assert error_field(build) == field


def test_element_must_fit_the_mesh():
    scene = dataclasses.replace(pressure_patch(), body=cc.Body(fe.MeshQuad().refined(2).with_defaults(), "P1"))
    assert error_field(lambda: cc.solve(scene)) == "body.element"


@pytest.mark.parametrize("solver", ["clarabel", "osqp", "cvxpy"])
def test_obstacle_penetrating_fixed_nodes_is_reported_infeasible(solver):
    """The contact boundary is clamped and the obstacle overlaps it: no admissible state."""
    scene = dataclasses.replace(
        pressure_patch(nx=4),
        dirichlet=(cc.Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=cc.Contact("bottom", cc.Obstacle("flat", gap=-0.01)),
    )
    result = cc.solve(scene, solver)
    assert result.status == "infeasible"
    assert not result.solved and result.certificate is None
    assert "infeasible" in result.solver_status.lower() or "Infeasible" in result.solver_status
    assert "obstacle" in result.message
    assert result.summary()["status"] == "infeasible"


def write_gmsh(mesh: fe.Mesh, path, subdomains: dict):
    """A gmsh 2.2 file with physical names for the boundaries and the given subdomains."""
    names = sorted(mesh.boundaries)
    lines = np.vstack([mesh.facets[:, mesh.boundaries[n]].T for n in names])
    line_tags = np.concatenate([np.full(len(mesh.boundaries[n]), k + 1) for k, n in enumerate(names)])
    cell_tags = np.zeros(mesh.t.shape[1], int)
    field_data = {n: np.array([k + 1, 1]) for k, n in enumerate(names)}
    for k, (name, cells) in enumerate(subdomains.items()):
        cell_tags[cells] = 100 + k
        field_data[name] = np.array([100 + k, 2])
    cells = [("line", lines), ("triangle", mesh.t.T)]
    tags = [line_tags, cell_tags]
    meshio.Mesh(mesh.p.T, cells, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                field_data=field_data).write(path, file_format="gmsh22", binary=False)


def test_gmsh_file_with_subdomain_materials(tmp_path):
    """A .msh file solves like the built-in rectangle; doubling E in both subdomains doubles λ_N.

    Under displacement control the contact problem is linear in E: same u, pressures × 2.
    """
    scene = hertz_punch(nx=24)
    scene = dataclasses.replace(scene, contact=cc.Contact("top", cc.Obstacle("parabolic", radius=1.0, depth=0.005)))
    mesh = cc.drivers.prepared.assemble(scene).mesh.scaled(4.0)  # the built-in mesh in user units
    upper = np.flatnonzero(mesh.p[1, mesh.t].mean(axis=0) > -0.5)
    lower = np.setdiff1d(np.arange(mesh.t.shape[1]), upper)
    path = tmp_path / "block.msh"
    write_gmsh(mesh, str(path), {"upper": upper, "lower": lower})

    def from_file(E_upper, E_lower):
        materials = {"upper": cc.Material(E_upper, 0.3), "lower": cc.Material(E_lower, 0.3)}
        return cc.solve(dataclasses.replace(scene, body=cc.Body(cc.MeshFile(path)), materials=materials))

    builtin = cc.solve(scene)
    same = from_file(1.0, 1.0)
    np.testing.assert_allclose(same.contact.pressure, builtin.contact.pressure, rtol=1e-6, atol=1e-9)
    stiffer = from_file(2.0, 2.0)
    np.testing.assert_allclose(stiffer.displacement, same.displacement, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(stiffer.contact.pressure, 2 * same.contact.pressure, rtol=1e-6, atol=1e-12)
    softer_top = from_file(0.5, 1.0)
    assert softer_top.normal_force < same.normal_force
    with pytest.raises(cc.SceneError) as caught:
        cc.solve(dataclasses.replace(scene, body=cc.Body(cc.MeshFile(path)), materials={"steel": cc.Material(1, 0.3)}))
    assert caught.value.field == "materials.steel"


def test_linear_elements_warn_of_locking_when_nearly_incompressible():
    locking = dataclasses.replace(pressure_patch(nx=2), materials=cc.Material(1.0, 0.4999))
    assert "lock" in cc.solve(locking).summary()["warnings"][0]
    quadratic = dataclasses.replace(locking, body=cc.Body(cc.Rectangle(nx=2, ny=2), "P2"))
    assert cc.solve(quadratic).summary()["warnings"] == []
    assert cc.solve(pressure_patch(nx=2)).summary()["warnings"] == []


def test_a_gmsh_file_with_geometry_points_is_read_without_them(tmp_path):
    """gmsh writes the points of its geometry (here an arc centre outside the body, as node 5) with vertex cells
    naming them. The file is read: the unused node dropped, cells, boundary tags and subdomains renumbered,
    and the result's warnings say so — the answer is the one on the same mesh without that node."""
    mesh = fe.MeshTri.init_tensor(np.linspace(0, 1, 4), np.linspace(0, 1, 4)).with_defaults()
    names = sorted(mesh.boundaries)
    lines = np.vstack([mesh.facets[:, mesh.boundaries[n]].T for n in names])
    line_tags = np.concatenate([np.full(len(mesh.boundaries[n]), k + 1) for k, n in enumerate(names)])
    after = lambda nodes: np.where(nodes >= 5, nodes + 1, nodes)  # node 5 is the arc centre
    points = np.insert(np.column_stack([mesh.p.T, np.zeros(mesh.p.shape[1])]), 5, [0.5, 2.0, 0.0], axis=0)
    tags = [np.array([50, 51]), line_tags, np.full(mesh.t.shape[1], 100)]
    field_data = {n: np.array([k + 1, 1]) for k, n in enumerate(names)}
    field_data.update(block=np.array([100, 2]), centre=np.array([50, 0]), corner=np.array([51, 0]))
    path = tmp_path / "arc.msh"
    meshio.Mesh(points, [("vertex", np.array([[5], [0]])), ("line", after(lines)), ("triangle", after(mesh.t.T))],
                cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                field_data=field_data).write(path, file_format="gmsh22", binary=False)
    patch = pressure_patch(nx=3)
    from_file = cc.solve(dataclasses.replace(patch, body=cc.Body(cc.MeshFile(path)),
                                             materials={"block": cc.Material(1.0, 0.3)}))
    same_mesh = cc.solve(dataclasses.replace(patch, body=cc.Body(mesh)))
    warning, = from_file.summary()["warnings"]
    assert "1 of 17 nodes belong to no cell" in warning and "node 5 at [0.5, 2.0, 0.0]" in warning
    assert from_file.status == "solved" and np.allclose(from_file.contact.pressure, 0.1, rtol=1e-9)
    assert np.abs(from_file.displacement - same_mesh.displacement).max() < 1e-12
