"""The equilibrated-flux bound of 2-D P1 results (convexcontact.fem.flux): equilibrium, effectivity, the bound."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_estimate import flat_punch, hertz_levels, under_gravity

import convexcontact as cc
from convexcontact.fem.flux import FluxEstimate, cell_geometry
from convexcontact.scene.library import hertz_punch


def nested_levels(scene: cc.Scene, levels: int, finer: int):
    """:func:`test_estimate.hertz_levels` for any P1 scene on the nx = 8 block."""
    return hertz_levels("P1", levels, finer, base=scene)


@pytest.fixture(scope="module")
def hertz():
    return nested_levels(hertz_punch(nx=8), 2, 2)


@pytest.fixture(scope="module")
def punch():
    return nested_levels(flat_punch(), 2, 2)


@pytest.mark.parametrize("family", ["hertz", "punch"])
def test_bound_is_above_the_true_error_within_a_factor_three(family, request):
    """η ≥ ‖u_ref − u_h‖_E on Hertz and on the flat punch, and η / error ≤ 3 (measured: Hertz 1.8 and 1.6, the
    punch 2.6 and 2.3 with the reference 2 levels finer; docs/estimate.md)."""
    for result, error in request.getfixturevalue(family):
        estimated = result.error_estimate
        assert isinstance(estimated, FluxEstimate) and result.error_budget["calibration"] == 1.0
        assert error <= estimated.eta <= 3.0 * error
        assert estimated.terms["equilibrated"] ** 0.5 <= estimated.eta  # the other terms only add


def test_hertz_bound_needs_its_contact_term_on_the_coarse_mesh(hertz):
    """On the nx = 8 mesh the Hertz zone spans a few cells: the complementarity term of σ̂ n = t̂ (the lumped
    traction) is a quarter of η² and the bound is tight without asymmetry inflation (≤ 2)."""
    result, error = hertz[0]
    terms = result.error_estimate.terms
    assert terms["complementarity"] > 0.1 * sum(terms.values())
    assert result.error_estimate.eta < 2.0 * error


def test_reconstruction_is_in_equilibrium_with_the_body_force():
    """Under its own weight (P1 cannot hold the quadratic u): ∫_T div σ̂ = −∫_T f on every cell to round-off, the
    boundary fluxes are the applied ones, and the bound is far from zero."""
    result = cc.solve(under_gravity(cc.library.pressure_patch(4, "P1")))
    estimated = result.error_estimate
    assert estimated.defect < 1e-12 and estimated.relative > 0.1


def test_bound_is_invariant_under_scaling_of_the_load():
    """Linear elasticity with a contact zone fixed by a flat punch (its depth sets the load): the bound scales with
    the solution, the relative bound stays (same mesh, depth doubled)."""
    base = flat_punch()
    deeper = dataclasses.replace(base, contact=cc.Contact("top", cc.Obstacle("flat_punch", radius=0.5, depth=0.02)))
    one, two = cc.solve(base), cc.solve(deeper)
    assert np.isclose(one.error_estimate.relative, two.error_estimate.relative, rtol=1e-6)


def test_cell_geometry_gradients_are_those_of_the_hat_functions():
    """∇λ_k sums to zero and λ_k's gradient times an edge gives the change of λ_k along it."""
    result = cc.solve(hertz_punch(nx=4))
    corners, area, grads = cell_geometry(result.fem.mesh)
    np.testing.assert_allclose(grads.sum(axis=1), 0.0, atol=1e-9 * np.abs(grads).max())
    edge = corners[:, 1] - corners[:, 0]
    np.testing.assert_allclose(np.einsum("ckx,cx->ck", grads, edge), np.tile([-1.0, 1.0, 0.0], (len(area), 1)),
                               atol=1e-9)


@pytest.mark.parametrize("non_penetration", ["weak", "gauss"])
def test_weak_and_gauss_multipliers_equilibrate_through_their_nodal_forces(non_penetration):
    """Hild's weak rows and Gauss-point rows hold the contact through nodal forces F = Cᵀλ too: with the lumped
    traction F / w as the Neumann datum every patch problem is compatible (defect at round-off), and the bound is
    within 10 % of the nodal rows' on the same mesh (measured: 0.561 nodal, 0.594 weak, 0.590 gauss)."""
    scene = hertz_punch(nx=16)
    nodal = cc.solve(scene).error_estimate
    other = cc.solve(dataclasses.replace(scene, contact=dataclasses.replace(
        scene.contact, law=cc.Signorini(non_penetration=non_penetration)))).error_estimate
    assert other.defect < 1e-12
    assert abs(other.relative / nodal.relative - 1) < 0.1


def indicator_rows(method: str):
    """The patch test of two blocks (uniform pressure, rollers): the bound's indicators and the cell centres' heights
    (the lower block below the middle), scaled."""
    from convexcontact.scene.bodies_library import patch_pair

    result = cc.solve(patch_pair(method=method))
    mesh = result.fem.mesh
    height = mesh.p[1, mesh.t].mean(axis=0)
    return result, result.error_estimate.indicators, height, 0.5 * (mesh.p[1].min() + mesh.p[1].max())


def test_mortar_tractions_equilibrate_both_blocks_of_the_patch_test():
    """Mortar passes the contact patch test: with each body's mortar traction as its Neumann datum the reconstruction
    is exact in both blocks, at the interface and at the Dirichlet vertices (the circulations reproduce a constant
    stress: η at round-off). Node to segment fails the patch test, and its indicators show it in both blocks."""
    result = indicator_rows("mortar")[0]
    assert isinstance(result.error_estimate, FluxEstimate) and result.error_budget["algebraic"] < 1e-6
    assert result.error_estimate.relative < 1e-7
    _, segment, height, middle = indicator_rows("node_to_segment")
    assert segment[height > middle].max() > 0.01 * segment.sum()
