"""The equilibrated bound on locally refined meshes (convexcontact.fem.flux; docs/estimate.md, "The circulation")."""

from __future__ import annotations

import numpy as np
import pytest

from convexcontact.drivers.adapt import adapt, body_meshes
from convexcontact.fem import flux
from convexcontact.scene.bodies_library import two_cylinders
from convexcontact.scene.meshing import build_mesh
from convexcontact.studies.precision import refinement
from convexcontact.studies.precision.work_precision import library_scene


@pytest.fixture(scope="module")
def levels():
    return adapt(library_scene("flat-punch", 8), target=1e-9, max_dofs=8000)


def test_a_constant_stress_is_reconstructed_exactly_on_an_adaptive_mesh(levels):
    """A linear displacement has a constant stress σ, in equilibrium with the traction σ n on the whole boundary: the
    reconstruction is σ itself (zero bound) on the graded and locally refined punch meshes, with or without the
    Dirichlet side's free fluxes, the divergence-free correction included (CG from τ = 0 with a zero load). The former
    circulation (nearest to ψ_a σ_h) left η / ‖σ‖ ≈ 10 % there."""
    for result in (levels[0], levels[-1]):
        fem = result.fem
        mesh = fem.mesh
        u = np.array([[0.3, -0.7], [0.2, 0.5]]) @ mesh.p
        _, det, gradients = flux.triangles(mesh)
        area = 0.5 * np.abs(det)
        sigma = flux.elastic_stress(fem, u, gradients)[0]
        facets = mesh.boundary_facets()
        edge = np.diff(mesh.p[:, mesh.facets[:, facets]], axis=1)[:, 0]
        normal = np.stack([edge[1], -edge[0]])  # |E| n, oriented outward below
        inward = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1) - mesh.p[:, mesh.facets[0, facets]]
        normal *= np.where((normal * inward).sum(axis=0) > 0, -1.0, 1.0)
        moments = np.zeros((2, 2, mesh.nfacets))
        moments[:, :, facets] = 0.5 * (sigma @ normal)[None]
        held = np.zeros((2, mesh.nfacets), dtype=bool)
        energy = float((area * (sigma**2).sum()).sum())
        for dirichlet in (False, True):
            held[:, facets] = flux.held_components(fem, facets) if dirichlet else False
            stress = flux.equilibrate(fem, u, moments, held)
            assert stress.symmetric.sum() + stress.skew.sum() < 1e-20 * energy
            np.testing.assert_allclose(stress.vertex_stress, np.broadcast_to(sigma[:, :, None, None],
                                       (2, 2, *area.shape, 3)), atol=1e-12 * np.abs(sigma).max())


def test_the_bound_stays_within_1_to_2_4_times_the_true_error_on_adaptive_punch_levels(levels):
    """The bound's effectivity no longer rises with the adaptive levels (before: 2.2 at 1,230 DOFs, 2.6 at 4,316, 2.9 at 7,910;
    now 2.0–2.1 from 1,000 DOFs on), and it is a bound on every level; true errors against two uniform refinements
    of the last level's mesh (≈ 13 % small on the last level, less on the others)."""
    scene = library_scene("flat-punch", 8)
    reference = refinement.timed_solve(refinement.scene_on(scene, [build_mesh(levels[-1].scene.body).refined(2)]))[0]
    errors = np.array(refinement.true_errors(levels, reference))
    estimates = np.array([r.error_budget["discretization"] for r in levels])
    ndof = np.array([r.ndof for r in levels])
    effectivity = estimates / errors
    assert ndof[-1] > 4000 and np.all(effectivity >= 1.0)
    assert np.all(effectivity[ndof > 1000] <= 2.4), effectivity


def test_two_bodies_are_refined_together_and_bounded_on_every_level():
    """Several bodies (mortar, 2-D P1) are refined by their equilibrated bound, Dörfler's cells of both together: on the
    two-cylinder Hertz every level is certified, both bodies are refined, the true error falls level by level and the
    bound holds with effectivity in the issue's 1–3 (true errors against two uniform refinements of the last level's
    meshes; measured 1.24–1.43 here with the divergence-free correction, 1.47–1.58 before; docs/estimate.md)."""
    scene = two_cylinders(h=0.08)
    levels = adapt(scene, target=0.4)
    first, last = body_meshes(scene), body_meshes(levels[-1].scene)
    assert len(levels) >= 4 and all(r.status == "solved" for r in levels)
    assert all(after.nelements > before.nelements for before, after in zip(first, last))
    reference = refinement.timed_solve(refinement.scene_on(scene, [mesh.refined(2) for mesh in last]))[0]
    errors = np.array(refinement.true_errors(levels, reference))
    effectivity = np.array([r.error_budget["discretization"] for r in levels]) / errors
    assert np.all(np.diff(errors) < 0), errors
    assert np.all((effectivity >= 1.0) & (effectivity <= 3.0)), effectivity
