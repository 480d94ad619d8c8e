"""Mortar pairs of P2 and Q2 elements in 2-D (docs/bodies.md): the dual basis of quadratic facets against closed forms."""

import numpy as np
import pytest
import skfem as fe

import convexcontact as cc
from convexcontact import Pair, Part, bodies_scene
from convexcontact.fem.assembly import assemble
from convexcontact.fem.mortar import dual_coefficients, gauss, lagrange
from convexcontact.scene.bodies_library import patch_pair, two_cylinders
from convexcontact.scene.meshing import build_mesh

STEEL = cc.Material(1.0, 0.3)


def hertz(force, radius=2.0, effective=0.5 / (1 - 0.3**2)):
    """Half-width and peak pressure of two cylinders in plane strain (R and E* of the pair)."""
    a = np.sqrt(4 * force * radius / (np.pi * effective))
    return a, 2 * force / (np.pi * a)


def test_the_quadratic_dual_basis_is_biorthogonal():
    """φ*_a = Σ_b A_ab ψ_b on a quadratic facet: ∫φ*_a ψ_b = δ_ab ∫ψ_b with ∫ψ = h/6, h/6, 2h/3, and Σ_a φ*_a = 1
    (a uniform pressure has equal nodal multipliers)."""
    coefficients, shares = dual_coefficients(2)
    np.testing.assert_allclose(shares, [1 / 6, 1 / 6, 2 / 3], rtol=1e-14)
    t, w = gauss(6)
    psi = lagrange(2, t)
    np.testing.assert_allclose((psi @ coefficients.T).T @ (w[:, None] * psi), np.diag(shares), atol=1e-14)
    np.testing.assert_allclose((psi @ coefficients.T).sum(axis=1), 1.0, rtol=1e-14)


@pytest.mark.parametrize("element", ["P2", "Q2"])
@pytest.mark.parametrize("law", [cc.Signorini(), cc.Tresca(0.001)], ids=["signorini", "tresca"])
@pytest.mark.parametrize("cells", [(5, 7), (7, 5)])
def test_quadratic_mortar_passes_the_contact_patch_test(element, law, cells):
    """Taylor–Papadopoulos with quadratic elements: every slave node — vertices and middle nodes — carries the
    uniform pressure exactly, and the master receives the opposite resultant."""
    result = cc.solve(patch_pair(*cells, element=element, law=law))
    assert result.status == "solved" and result.certificate.passes(1e-9)
    assert result.fem.contact.m == 2 * cells[0] + 1
    assert np.abs(result.contact.pressure / 0.01 - 1).max() <= 1e-10
    assert result.certificate.residuals["pair_balance"] <= 1e-12
    np.testing.assert_allclose(result.contact.master_forces.sum(axis=0), -result.contact_force, atol=1e-15)


@pytest.mark.parametrize("element", ["P2", "Q2"])
def test_the_rows_of_m_sum_to_the_slave_weights(element):
    """Σ_k M_ik = w_i on a curved, non-matching interface (the resultants balance whatever the pressure), w_i = ∫ψ_i:
    a middle node weighs twice an inner vertex (2h/3 against h/6 + h/6)."""
    trace = assemble(two_cylinders(0.04, radii=(4.0, 4.0), width=4.0, height=2.0, master_h=0.052,
                                   element=element)).contact
    mortar = trace.mass @ trace.transfer  # M = D Π
    assert trace.m > 50 and mortar.nnz > 3 * trace.m
    np.testing.assert_allclose(np.asarray(mortar.sum(axis=1)).ravel(), trace.weights, rtol=1e-12)
    fem = assemble(patch_pair(5, 7, element=element))
    weights, vertex = fem.contact.weights, fem.contact.dofs[:, 0] // 2 < fem.mesh.p.shape[1]
    inner = vertex & (weights > 0.75 * weights[vertex].max())  # the two end vertices have one facet
    assert np.count_nonzero(~vertex) == 5 and np.count_nonzero(inner) == 4
    np.testing.assert_allclose(weights[~vertex], 2 * weights[inner][0], rtol=1e-13)
    np.testing.assert_allclose(weights[inner], weights[inner][0], rtol=1e-13)


def test_a_quadratic_pair_on_a_finely_faceted_master_meets_hertz_no_worse_than_p1():
    """A flat P2 slave on a cylinder R = 2 faceted four times finer: p₀ (the peak, and fitted to p² = p₀²(1 − x²/a²))
    within 1 % of Hertz and no further than P1's at the same h; a within the node spacing h/2."""
    h, errors = 0.02, {}
    for element in ("P1", "P2"):
        result = cc.solve(two_cylinders(h, radii=(np.inf, 2.0), approach=0.006, width=3.0, height=2.0,
                                        master_h=h / 4, element=element))
        assert result.certificate.passes(1e-9) and result.certificate.residuals["pair_balance"] < 1e-12
        a, p0 = hertz(result.normal_force)
        s, p = result.contact.coordinate, result.contact.pressure
        inside = p > 0.3 * p.max()
        (c0, _), *_ = np.linalg.lstsq(np.column_stack([np.ones(inside.sum()), s[inside] ** 2]), p[inside] ** 2,
                                      rcond=None)
        errors[element] = abs(result.max_pressure / p0 - 1), abs(np.sqrt(c0) / p0 - 1)
    assert max(errors["P2"]) < 0.01
    assert errors["P2"][0] <= errors["P1"][0] and errors["P2"][1] <= errors["P1"][1]
    assert a - h / 2 <= result.contact_half_width <= a


def test_quadratic_elements_see_the_kinks_of_faceted_cylinders():
    """Two cylinders whose faces are polygons of straight facets: the exact pressure of the polygons peaks at their
    corners (a kink of angle h/R), which P2 resolves and P1 averages away. The peak's excess over Hertz halves
    with h — the geometry's error, O(h/R), not the mortar's (docs/bodies.md)."""
    excess = []
    for h in (0.04, 0.02):
        result = cc.solve(two_cylinders(h, radii=(4.0, 4.0), approach=0.006, width=4.0, height=2.0, element="P2"))
        assert result.certificate.passes(1e-9)
        excess.append(result.max_pressure / hertz(result.normal_force)[1] - 1)
        peak = np.argmax(result.contact.pressure)
        assert result.fem.contact.dofs[peak, 0] // 2 < result.fem.mesh.p.shape[1]  # at a vertex, not a middle node
    assert excess[1] > 0.05 and excess[0] / excess[1] == pytest.approx(2.0, rel=0.1)


def test_coulomb_on_a_quadratic_pair():
    """A stiff P2 punch (E = 10, R = 1) on a P2 foundation (E = 1), F = 0.3: Picard converges to a certified answer
    with a stick zone flanked by slip both ways, the resultants balanced."""
    result = cc.solve(two_cylinders(0.02, radii=(1.0, np.inf), moduli=(10.0, 1.0), approach=0.01, law=cc.Coulomb(0.3),
                                    width=1.0, master_h=0.026, element="P2"))
    assert result.status == "solved" and result.certificate.passes(1e-8)
    assert {"stick", "slip+", "slip-"} <= set(result.contact.status)
    assert result.certificate.residuals["pair_balance"] < 1e-12


def quadratic_block(cells: int, y: float = 0.0, bend: float = 0.0) -> fe.MeshTri2:
    """A unit block as a quadratic mesh, its edge nodes moved up by ``bend`` · sin(πx) (0: straight edges)."""
    linear = build_mesh(cc.Body(cc.Rectangle(1.0, 1.0, cells, cells, origin=(0.0, y))))
    doflocs = fe.MeshTri2.from_mesh(linear).doflocs.copy()
    edges = np.arange(linear.p.shape[1], doflocs.shape[1])
    doflocs[1, edges] += bend * np.sin(np.pi * doflocs[0, edges])
    return fe.MeshTri2(doflocs, linear.t, _boundaries=linear.boundaries)


def quadratic_patch(bend: float):
    parts = [Part("upper", quadratic_block(3, 1.0, bend), STEEL, "P2"), Part("lower", quadratic_block(4), STEEL, "P2")]
    return bodies_scene(parts, Pair("upper.bottom", master="lower.top"),
                        dirichlet=[cc.Dirichlet("lower.bottom", uy=0.0), cc.Dirichlet("lower.left", ux=0.0),
                                   cc.Dirichlet("upper.left", ux=0.0)],
                        tractions=[cc.Traction("upper.top", pressure=0.01)])


def test_a_straight_sided_quadratic_mesh_joins_and_a_curved_one_is_refused():
    """A MeshTri2 with straight edges is the linear mesh P2 runs on (the patch test passes); edge nodes off the
    midpoints are curved facets, refused by name."""
    result = cc.solve(quadratic_patch(0.0))
    assert np.abs(result.contact.pressure / 0.01 - 1).max() <= 1e-10
    with pytest.raises(cc.SceneError, match="curved edges") as error:
        quadratic_patch(0.01)
    assert error.value.field == "parts[upper].geometry"


def quadratic_box(cells: int, z: float = 0.0, bend: float = 0.0) -> fe.MeshTet2:
    """A unit box of P1 tetrahedra as a MeshTet2, its edge nodes moved up by ``bend`` · sin(πx) (0: straight)."""
    linear = build_mesh(cc.Body(cc.Box(size=(1, 1, 1), cells=(cells, cells, 2), origin=(0, 0, z)), "P2"))
    doflocs = fe.MeshTet2.from_mesh(linear).doflocs.copy()
    edges = np.arange(linear.nvertices, doflocs.shape[1])
    doflocs[2, edges] += bend * np.sin(np.pi * doflocs[0, edges])
    return fe.MeshTet2(doflocs, linear.t, _boundaries=linear.boundaries)


def test_a_3d_pair_of_straight_quadratic_meshes_passes_the_patch_test_and_a_curved_one_is_refused():
    """MeshTet2 boxes (as gmsh's second-order files are read) with straight edges: the P2 pair's patch test passes; edge
    nodes off the midpoints are refused by name, as in 2-D."""
    def scene(bend):
        parts = [Part("upper", quadratic_box(3, 1.0, bend), STEEL, "P2"), Part("lower", quadratic_box(4), STEEL, "P2")]
        return bodies_scene(parts, Pair("upper.bottom", master="lower.top"),
                            dirichlet=[cc.Dirichlet("lower.bottom", uz=0.0),
                                       *(cc.Dirichlet(f"{part}.{side}", **{axis: 0.0}) for part in ("upper", "lower")
                                         for side, axis in (("left", "ux"), ("front", "uy")))],
                            tractions=[cc.Traction("upper.top", pressure=0.01)])
    result = cc.solve(scene(0.0))
    assert np.abs(result.contact.pressure / 0.01 - 1).max() <= 1e-9 and result.certificate.passes(1e-9)
    with pytest.raises(cc.SceneError, match="curved edges") as error:
        scene(0.01)
    assert error.value.field == "parts[upper].geometry"
