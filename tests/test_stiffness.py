"""The stiffness kernel and the mesh it is built on, against scikit-fem's own forms and meshes."""

import dataclasses

import numpy as np
import pytest
import skfem as fe
from skfem.helpers import ddot, div, sym_grad

import convexcontact as cc
from convexcontact.fem.assembly import assemble, lame_per_element, load_vector
from convexcontact.fem.basis import vector_basis
from convexcontact.fem.scaling import Scaling
from convexcontact.fem.stiffness import stiffness
from convexcontact.scene.meshing import build_mesh, scaled, tensor_mesh


@fe.BilinearForm
def elasticity(u, v, w):
    """The reference: the weak form as scikit-fem writes it."""
    return 2.0 * w["mu"] * ddot(sym_grad(u), sym_grad(v)) + w["lam"] * div(u) * div(v)


MESHES = [(fe.MeshTri().refined(3), "P1"), (fe.MeshTri().refined(2), "P2"), (fe.MeshQuad().refined(2), "Q1"),
          (fe.MeshQuad().refined(2), "Q2"), (fe.MeshTet().refined(2), "P1"), (fe.MeshHex().refined(2), "Q1")]


@pytest.mark.parametrize("mesh, element", MESHES, ids=[f"{type(m).__name__}-{e}" for m, e in MESHES])
def test_the_kernel_is_the_weak_form(mesh, element, monkeypatch):
    """Element-wise random Lamé parameters, in blocks smaller than the mesh: K equals the form's to round-off, is
    symmetric, and holds the rigid motions in its kernel."""
    monkeypatch.setattr("convexcontact.fem.stiffness.BLOCK", 1000)  # blocks of 1–27 cells
    basis = vector_basis(mesh, element)
    rng = np.random.default_rng(1)
    lam, mu = rng.uniform(0.5, 2.0, basis.nelems), rng.uniform(0.5, 2.0, basis.nelems)
    K = stiffness(basis, (lam, mu))
    points = basis.X.shape[-1]
    reference = fe.asm(elasticity, basis, lam=np.repeat(lam[:, None], points, 1), mu=np.repeat(mu[:, None], points, 1))
    assert abs(K - reference).max() <= 1e-14 * abs(reference).max()
    assert abs(K - K.T).max() <= 1e-14 * abs(K).max()
    for motion in (lambda x: (np.ones_like(x[0]), 0 * x[0]), lambda x: (-x[1], x[0])):  # translation, rotation
        u = np.zeros(basis.N)
        for component, dofs in enumerate(basis.split_indices()[:2]):
            u[dofs] = motion(basis.doflocs[:, dofs])[component]
        assert np.abs(K @ u).max() <= 1e-12 * abs(K).max()


@pytest.mark.parametrize("mesh, element", [(fe.MeshTri().refined(2), "P2"), (fe.MeshHex().refined(1), "Q1")],
                         ids=["MeshTri-P2", "MeshHex-Q1"])
def test_the_kernel_does_not_rely_on_the_numbering(mesh, element, monkeypatch):
    """Nodes and cells numbered at random (blocks of cells then touch rows all over K): still the form's K."""
    monkeypatch.setattr("convexcontact.fem.stiffness.BLOCK", 1000)
    rng = np.random.default_rng(7)
    order = rng.permutation(mesh.p.shape[1])
    shuffled = type(mesh)(mesh.p[:, order], np.argsort(order)[mesh.t][:, rng.permutation(mesh.t.shape[1])])
    basis = vector_basis(shuffled, element)
    lam, mu = rng.uniform(0.5, 2.0, basis.nelems), rng.uniform(0.5, 2.0, basis.nelems)
    points = basis.X.shape[-1]
    reference = fe.asm(elasticity, basis, lam=np.repeat(lam[:, None], points, 1), mu=np.repeat(mu[:, None], points, 1))
    assert abs(stiffness(basis, (lam, mu)) - reference).max() <= 1e-14 * abs(reference).max()


@pytest.mark.parametrize("mesh, element", MESHES, ids=[f"{type(m).__name__}-{e}" for m, e in MESHES])
def test_the_basis_evaluates_what_scikit_fem_does(mesh, element):
    """The lazy basis holds scikit-fem's DOFs, locations, shape functions and measures on the same quadrature, and
    its vector DOFs interleave components (d·s + a for scalar DOF s, component a), which the kernel and the
    contact trace rely on."""
    lazy = vector_basis(mesh, element)
    eager = fe.CellBasis(mesh, lazy.elem, quadrature=(lazy.X, lazy.W))
    np.testing.assert_array_equal(lazy.element_dofs, eager.element_dofs)
    np.testing.assert_allclose(lazy.doflocs, eager.doflocs, rtol=0, atol=1e-15)
    np.testing.assert_allclose(lazy.dx, eager.dx, rtol=1e-15)
    for mine, theirs in zip(lazy.basis, eager.basis):
        np.testing.assert_allclose(np.asarray(mine[0]), np.asarray(theirs[0]), rtol=0, atol=1e-14)
        np.testing.assert_allclose(mine[0].grad, theirs[0].grad, rtol=1e-14, atol=1e-12)
    cells = np.arange(0, mesh.t.shape[1], 3)
    part, eager_part = lazy.with_elements(cells), eager.with_elements(cells)  # scikit-fem builds this class again
    assert isinstance(part, type(lazy))
    np.testing.assert_allclose(part.basis[-1][0].grad, eager_part.basis[-1][0].grad, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(part.dx, eager_part.dx, rtol=1e-15)
    dim, scalar = mesh.dim(), fe.Dofs(mesh, lazy.elem.elem).element_dofs
    interleaved = (dim * scalar[:, None, :] + np.arange(dim)[None, :, None]).reshape(-1, scalar.shape[1])
    np.testing.assert_array_equal(lazy.element_dofs, interleaved)


def test_the_centroid_rule_integrates_p1_loads_exactly():
    """P1 triangles integrate with one point (scikit-fem's lowest rule has three): a body force's load vector
    (degree 1) is the exact one."""
    scene = dataclasses.replace(cc.scene.library.hertz_punch(8), body_force=(0.3, -1.2))
    mesh = build_mesh(scene.body)
    one, exact = vector_basis(mesh, "P1"), vector_basis(mesh, "P1", intorder=4)
    assert one.X.shape[-1] == 1
    scaling = Scaling(1.0, 1.0, 1.0, 2)
    exact_load = load_vector(scene, mesh, exact, scaling)
    np.testing.assert_allclose(load_vector(scene, mesh, one, scaling), exact_load, rtol=0,
                               atol=1e-14 * np.abs(exact_load).max())


@pytest.mark.parametrize("quads", [False, True])
@pytest.mark.parametrize("dim", [2, 3])
def test_the_sides_are_the_boundary_facets_on_each_plane(dim, quads):
    """The named sides of a tensor mesh are the boundary facets whose midpoints lie on each bounding plane, as
    scikit-fem's own test of every facet finds them."""
    axes = [np.array([0.0, 0.4, 1.0]), np.array([-1.0, 0.5, 2.0, 3.0]), np.array([0.0, 0.1, 0.3])][:dim]
    mesh = tensor_mesh(*axes, quads=quads)
    names = {2: ("left", "right", "bottom", "top"), 3: ("left", "right", "front", "back", "bottom", "top")}[dim]
    for index, name in enumerate(names):
        axis, value = index // 2, axes[index // 2][-(index % 2)]
        found = mesh.facets_satisfying(lambda x, axis=axis, value=value: np.abs(x[axis] - value) < 1e-12, True)
        np.testing.assert_array_equal(np.sort(mesh.boundaries[name]), found)
        assert found.size > 0


def test_plane_stress_enters_through_the_lame_parameters():
    """Plane stress is λ* = 2λμ/(λ + 2μ): the kernel with those equals the form with those."""
    scene = cc.scene.library.hertz_punch(8)
    stress = dataclasses.replace(scene, body=cc.Body(scene.body.geometry, scene.body.element, "stress"))
    mesh = build_mesh(stress.body)
    lam, mu = lame_per_element(stress, mesh, 1.0)
    E, nu = scene.materials.E, scene.materials.nu
    assert lam == pytest.approx(E * nu / (1 - nu**2)) and mu == pytest.approx(E / (2 * (1 + nu)))


def test_scaling_a_mesh_keeps_its_topology_and_moves_its_nodes():
    """The scaled mesh reuses the facets already built, which are those a new mesh would build."""
    mesh = build_mesh(cc.scene.library.hertz_punch(10).body)
    moved = scaled(mesh, 0.5)
    np.testing.assert_array_equal(moved.p, 0.5 * mesh.p)
    fresh = type(mesh)(moved.p, moved.t)
    np.testing.assert_array_equal(moved.facets, fresh.facets)
    np.testing.assert_array_equal(moved.f2t, fresh.f2t)
    assert moved.boundaries.keys() == mesh.boundaries.keys()


def test_an_assembled_scene_is_unchanged_by_the_kernel():
    """Hertz: the assembled K against the form on the same basis and parameters."""
    fem = assemble(cc.scene.library.hertz_punch(12, element="Q1"))
    points = fem.basis.X.shape[-1]
    lam, mu = (np.repeat(p[:, None], points, 1) for p in fem.lame)
    reference = fe.asm(elasticity, fem.basis, lam=lam, mu=mu)
    assert abs(fem.K_full - reference).max() <= 1e-14 * abs(reference).max()
