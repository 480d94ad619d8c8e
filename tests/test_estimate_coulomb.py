"""The error estimate of Coulomb answers (docs/estimate.md, "The coverage, law × bodies × dimension"). Pairs: F = 0.2, the upper
body's Young's modulus 1 and the lower's 3, so the normal load shears the interface and points slip: two cylinders on
the coarse graded family of tests/test_estimate_pairs.py, and two spheres' caps of P1 tetrahedra; true errors
against a reference solve finer levels. One body in 3-D: the Hertz box, F = 0.05."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_estimate_pairs import coarse_cylinders

import convexcontact as cc
from convexcontact.drivers.adapt import refined_uniformly
from convexcontact.fem import flux
from convexcontact.fem.estimate import estimate
from convexcontact.results.result import EFFECTIVITY, EFFECTIVITY_3D, contact_state
from convexcontact.scene.bodies import bodies_scene
from convexcontact.scene.bodies_library import two_spheres
from convexcontact.scene.description import Obstacle
from convexcontact.scene.library import HERTZ_SPHERE_FORCE, quarter_box
from convexcontact.scene.meshing import build_mesh
from convexcontact.studies.precision.refinement import true_errors

COULOMB = cc.Coulomb(friction=0.2)


def levels(element: str, cols: int) -> tuple[list, np.ndarray]:
    """Levels 0 and 1 (544 and 2,112 DOFs) and their energy errors against level 3 (33,024 DOFs)."""
    runs = [cc.solve(coarse_cylinders(element, k, law=COULOMB, moduli=(1.0, 3.0), cols=cols)) for k in (0, 1, 3)]
    u_ref = runs[-1].displacement / runs[-1].fem.scaling.displacement
    errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u_ref @ (runs[-1].fem.K_full @ u_ref))
    return runs[:-1], errors


@pytest.fixture(scope="module")
def p1_cylinders():
    return levels("P1", 16)


@pytest.fixture(scope="module")
def p2_cylinders():
    return levels("P2", 8)


def reversed_slip(result):
    """The result's contact state with every slip reversed: the slip along its traction, not against it."""
    state = contact_state(result)
    return dataclasses.replace(state, slip=-state.slip)


def test_the_bound_of_a_p1_coulomb_pair_is_above_its_true_error(p1_cylinders):
    """2-D P1, the budget's equilibrated bound: error ≤ η ≤ 3 error on both levels (measured 1.37, 1.32 here; 1.25–1.36
    on four levels against a reference two or more levels finer), where points slip (2 and 4 nodes)."""
    runs, errors = p1_cylinders
    assert all(r.summary()["n_slip"] > 0 for r in runs)
    ratio = np.array([r.error_estimate.eta for r in runs]) / errors
    assert all(r.error_budget["estimator"].startswith("equilibrated") for r in runs)
    assert np.all(1.0 <= ratio) and np.all(ratio <= 3.0)


def test_the_bounds_friction_term_is_zero_where_the_slip_opposes_the_traction(p1_cylinders):
    """The bound's friction term ∫ |t̂_T| |v_T| + t̂_T · v_T is round-off on the discrete answer (measured ≤ 5e-18:
    on every contact facet the mean traction opposes both nodes' slips), and not zero with the slips reversed (6 and
    11 % of η²): it checks the direction of slip, and the discrete answer's is right."""
    runs, _ = p1_cylinders
    for result in runs:
        assert result.equilibrated_bound.terms["friction"] < 1e-12 * result.equilibrated_bound.eta**2
        wrong = flux.flux_estimate(result.fem, result.displacement / result.fem.scaling.displacement,
                                   reversed_slip(result))
        assert wrong.terms["friction"] > 0.03 * wrong.eta**2


def test_the_calibrated_estimate_of_a_p2_coulomb_pair_is_near_its_true_error(p2_cylinders):
    """2-D P2, the calibrated residual (5.2): within 1–3 of the true error (measured 1.17, 1.31; 1.16–1.43 on four
    levels against a reference two or more levels finer); its friction term is not zero where points slip (0.7 and
    1.5 % of η²: the consistent-mass traction changes sign between the nodes), and grows with the slips reversed."""
    runs, errors = p2_cylinders
    assert all(r.summary()["n_slip"] > 0 for r in runs)
    ratio = np.array([r.residual_estimate.eta / EFFECTIVITY["P2"] for r in runs]) / errors
    assert np.all(1.0 <= ratio) and np.all(ratio <= 3.0)
    for result in runs:
        terms = result.residual_estimate.terms
        assert 1e-3 * result.residual_estimate.eta**2 < terms["friction"]
        wrong = estimate(result.fem, result.displacement / result.fem.scaling.displacement, reversed_slip(result))
        assert wrong.terms["friction"] > 1.1 * terms["friction"]


def test_the_estimates_of_a_p1_coulomb_pair_of_spheres_read_above_their_true_error():
    """3-D P1, ``two_spheres(cells=3)``, levels 288 and 1,764 DOFs against 12,168: the calibrated residual (2.8, the
    budget's) within 1–3 (measured 1.35, 1.75; with the partly covered slave nodes' rows, branch ``partial``: 1.84,
    2.00) and the bound on request above the error (1.82, 2.92; 3.19, 2.92 with those rows), where points slip."""
    base = two_spheres(cells=3, moduli=(1.0, 3.0), law=COULOMB)
    runs = [cc.solve(bodies_scene(tuple(dataclasses.replace(p, geometry=refined_uniformly(p.geometry, k))
                                        for p in base.body.parts), base.contact, dirichlet=list(base.dirichlet)))
            for k in (0, 1, 2)]
    u_ref = runs[-1].displacement / runs[-1].fem.scaling.displacement
    errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u_ref @ (runs[-1].fem.K_full @ u_ref))
    runs = runs[:-1]
    assert all(r.summary()["n_slip"] > 0 for r in runs)
    assert all(r.error_budget["calibration"] == EFFECTIVITY_3D["P1"] for r in runs)
    calibrated = np.array([r.residual_estimate.eta / EFFECTIVITY_3D["P1"] for r in runs]) / errors
    assert np.all(1.0 <= calibrated) and np.all(calibrated <= 3.0)
    assert np.all(np.array([r.equilibrated_bound.eta for r in runs]) >= errors)


@pytest.mark.parametrize("element", ["P1", "Q1"])
def test_the_calibrated_estimate_of_a_3d_coulomb_body_is_near_its_true_error(element):
    """The Hertz 0.4 box of 2³ cubes with Coulomb F = 0.05 (at 0.2 no node slips on these levels), levels 42 and 260
    DOFs against 1,800: the calibrated residual within 1–3 (measured P1 1.48, 1.86; Q1 2.26, 2.03; 1.41–1.48 and
    1.80–2.17 on three levels against 102,432) and P1's bound above the error (2.87, 2.54), a node slipping on the
    second level."""
    base = quarter_box(2, element, 1.0, Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0),
                                                 force=HERTZ_SPHERE_FORCE / 4), cc.Coulomb(friction=0.05),
                       "hertz_sphere", size=0.4)
    coarse = build_mesh(base.body)
    runs = [cc.solve(dataclasses.replace(base, body=cc.Body(refined_uniformly(coarse, k), element=element)))
            for k in (0, 1, 2)]
    u_ref = runs[-1].displacement / runs[-1].fem.scaling.displacement
    errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u_ref @ (runs[-1].fem.K_full @ u_ref))
    runs = runs[:-1]
    assert runs[1].summary()["n_slip"] > 0
    calibrated = np.array([r.residual_estimate.eta / r.error_budget["calibration"] for r in runs]) / errors
    assert all(r.error_budget["calibration"] == EFFECTIVITY_3D[element] for r in runs)
    assert np.all(1.0 <= calibrated) and np.all(calibrated <= 3.0)
    if element == "P1":
        assert np.all(np.array([r.equilibrated_bound.eta for r in runs]) >= errors)


def test_a_tresca_pair_tied_across_its_gap_is_bounded_and_warns_where_the_tie_reaches_the_coverages_end():
    """Two cylinders of moduli 1 and 3 with Tresca (docs/estimate.md, "Tresca pairs tied across their gap: the
    cause"): with s = 0.01 on all of Γ_C the open nodes are tied to the other body across the gap. The mortar's search
    missed the master facets that the slave's tilted normals meet far aside, so the covered part of Γ_C, and the tie,
    shrank with the mesh (|x| ≤ 0.35, 0.27, 0.20 on levels 2, 3, 5) and the P1 bound read 0.51 of the true error on
    level 2; now (|x| ≤ 0.41, 0.43, 0.45) 1.09 (against level 5; 1.13 here against level 4). The tie still ends at the
    coverage's end, which moves with the mesh: the result warns. With s on |x| < 0.28 (inside every level's coverage)
    open nodes are tied as well, the bound is above the error and the result does not warn."""
    def runs(s):
        return [cc.solve(coarse_cylinders("P1", k, law=cc.Tresca(slip_bound=s), moduli=(1.0, 3.0))) for k in (2, 4)]

    for s, at_end in ((0.01, True), (lambda x, y: 0.01 * (np.abs(x) < 0.28), False)):
        level, reference = runs(s)
        u_ref = reference.displacement / reference.fem.scaling.displacement
        error = true_errors([level], reference)[0] * np.sqrt(u_ref @ (reference.fem.K_full @ u_ref))
        force = np.linalg.norm(level.contact.forces, axis=1)
        assert np.count_nonzero(force[~level.closed] > 1e-3 * force.max()) >= 10  # open nodes tied in both
        assert level.equilibrated_bound.eta >= error
        assert (level.tied_at_coverage_end > 0) == at_end
        assert any(w.startswith("the error estimate is not verified") for w in level.warnings) == at_end


def test_an_unsolved_tresca_pair_has_no_tied_nodes_and_warns_as_before():
    """An answer that is not there (no contact nodes) reads 0 tied nodes, not an error."""
    result = cc.solve(coarse_cylinders("P1", 0, law=cc.Tresca(slip_bound=0.01), moduli=(1.0, 3.0)))
    failed = dataclasses.replace(result, status="failed", contact=None)
    assert result.tied_at_coverage_end > 0 and failed.tied_at_coverage_end == 0
    assert not any(w.startswith("the error estimate is not verified") for w in failed.warnings)


def test_a_coarse_3d_tresca_pair_warns_where_its_contact_zone_reaches_the_coverages_end():
    """Two P2 spheres' caps (``cells=3``, moduli 1 and 3, 1,764 DOFs) with Tresca: the master covers 9 of the slave's
    49 nodes, all closed, so the contact zone itself ends where the coverage does. With s = 0.005 everywhere a finer
    mesh covers more and ties it across the gap: the calibrated residual reads 0.93 of the true error against the
    next level (0.60 against 90,000 DOFs, docs/estimate.md, "The last cells") and the result warns, though no open
    node is tied (a rule counting open tied nodes only counted 0). With s only where the caps touch (r < 0.15) the
    level solves the same problem, its estimate reads 1.59 and it does not warn: the slip bound is zero at the
    left-out nodes."""
    readings = []
    for s in (0.005, lambda x, y, z: 0.005 * (x**2 + y**2 < 0.15**2)):
        base = two_spheres(cells=3, moduli=(1.0, 3.0), law=cc.Tresca(slip_bound=s), element="P2")
        finer = bodies_scene(tuple(dataclasses.replace(p, geometry=refined_uniformly(p.geometry, 1))
                                   for p in base.body.parts), base.contact, dirichlet=list(base.dirichlet))
        level, reference = cc.solve(base), cc.solve(finer)
        u_ref = reference.displacement / reference.fem.scaling.displacement
        error = true_errors([level], reference)[0] * np.sqrt(u_ref @ (reference.fem.K_full @ u_ref))
        assert level.closed.all() and "40 of 49" in level.fem.warnings[0]
        warned = any(w.startswith("the error estimate is not verified") for w in level.warnings)
        readings.append((level.displacement, level.residual_estimate.eta / level.error_budget["calibration"] / error,
                         level.tied_at_coverage_end, warned))
    (u_all, everywhere, held, warned), (u_inside, inside, held_inside, warned_inside) = readings
    np.testing.assert_allclose(u_all, u_inside, rtol=0, atol=1e-12 * np.abs(u_all).max())
    assert everywhere < 1.0 and held > 0 and warned
    assert inside >= 1.0 and held_inside == 0 and not warned_inside


def sliding(element: str, cols: int, k: int) -> cc.Scene:
    """The coarse cylinders (equal bodies, approach 0.03), F = 0.6, the upper back moved 0.07 along x: gross sliding,
    Q/(F P) = 1.02–1.05, every closed node slips."""
    scene = coarse_cylinders(element, k, law=cc.Coulomb(friction=0.6), cols=cols)
    return dataclasses.replace(scene, dirichlet=[cc.Dirichlet("upper.back", ux=0.07, uy=-0.015), scene.dirichlet[1]])


@pytest.mark.parametrize("element, cols", [("P1", 16), ("P2", 8)])
def test_the_estimates_of_a_sliding_pair_read_above_their_true_error(element, cols):
    """A tangentially loaded pair sliding as a whole, levels 0 and 1 against level 3: the friction term is where it
    matters in P2's residual (7 and 12 % of η²: the consistent-mass traction turns along the slip within cells inside
    the zone, the largest at x = 0.67 a, and the large slip multiplies it), and the calibrated residual still reads 1–3
    (measured 1.21, 1.26);
    P1's bound keeps a friction term of round-off (every slip opposes its facet's traction) and reads above the error
    (1.26, 1.25). Against a finer reference (level 5) the P2 reading falls to 1.00 at level 2 (docs/estimate.md)."""
    runs = [cc.solve(sliding(element, cols, k)) for k in (0, 1, 3)]
    u_ref = runs[-1].displacement / runs[-1].fem.scaling.displacement
    errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u_ref @ (runs[-1].fem.K_full @ u_ref))
    runs = runs[:-1]
    assert all(r.summary()["n_slip"] > 0 and not np.any(r.contact.status == "stick") for r in runs)
    if element == "P2":
        estimates = [r.residual_estimate for r in runs]
        assert all(e.terms["friction"] > 0.05 * e.eta**2 for e in estimates)
        ratio = np.array([e.eta / EFFECTIVITY["P2"] for e in estimates]) / errors
        assert np.all(1.0 <= ratio) and np.all(ratio <= 3.0)
    else:
        bounds = [r.equilibrated_bound for r in runs]
        assert all(abs(b.terms["friction"]) < 1e-12 * b.eta**2 for b in bounds)
        assert np.all(np.array([b.eta for b in bounds]) >= errors)
