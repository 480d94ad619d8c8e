"""The stiffness kernel and the mesh it is built on, against scikit-fem's own forms and meshes."""

import dataclasses

import numpy as np
import pytest
import skfem as fe
from skfem.helpers import ddot, div, sym_grad

import convexcontact as cc
from convexcontact.fem.assembly import assemble, lame_per_element, stiffness
from convexcontact.fem.mesh import build_mesh, scaled, vector_basis


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
    monkeypatch.setattr("convexcontact.fem.assembly.CHUNK", 7)
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
