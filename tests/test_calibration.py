"""The residual estimate's calibration (`EFFECTIVITY`, `EFFECTIVITY_3D`), family by family: on small instances of the
families it serves, the calibrated estimate η / calibration lies within 1–3 times the true energy error, against a
finer reference solve (docs/estimate.md, "The calibration, family by family"). Each test also names the former
constant that read the same family below its error."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_estimate import hertz_levels
from test_estimate_pairs import coarse_cylinders

import convexcontact as cc
from convexcontact.drivers.adapt import adapt, body_meshes, refined_uniformly, scene_on
from convexcontact.results.result import EFFECTIVITY, EFFECTIVITY_3D, effectivity
from convexcontact.scene.description import Rectangle
from convexcontact.scene.library import HERTZ_SPHERE_FORCE, hertz_punch, punch_3d, quarter_box
from convexcontact.scene.meshing import build_mesh
from convexcontact.studies.precision.refinement import true_errors

FORMER = {("Q1", 2): 4.6, ("P2", 2): 7.2, ("P1", 3): 3.9}
"""The constants before issue 26's calibration on every family (Hertz's band's low end alone)."""


def flat_punch(element: str, law=None, graded: bool = False) -> cc.Scene:
    """The flat punch (half-width 0.5) on hertz_punch's block, its cells uniform across (8 of width 0.5): the punch's
    edges are vertices on every uniform level, so the discrete contact boundary is the punch's. ``graded``: the
    block graded 10:1 across, as hertz_punch's, where the contact boundary is cut to the facets wholly under the
    punch (a geometric error no estimator sees; docs/estimate.md)."""
    scene = hertz_punch(nx=8, element=element)
    block = Rectangle(width=4.0, height=2.0, nx=8, ny=4, origin=(-2.0, -2.0), grading=(10.0 if graded else 1.0, 10.0),
                      refine_x=0.0 if graded else None)
    return dataclasses.replace(scene, body=cc.Body(block, element=element),
                               contact=cc.Contact("top", cc.Obstacle("flat_punch", radius=0.5, depth=0.01),
                                                  law or cc.Signorini()))


def effectivities(levels, calibration: float | None = None) -> np.ndarray:
    """(η / calibration) / true error of each (result, error) pair; ``calibration`` None: the result's own."""
    return np.array([r.residual_estimate.eta / (calibration or r.error_budget["calibration"]) / e
                     for r, e in levels])


def test_q1_hertz_is_calibrated_from_its_coarsest_level():
    """2-D Hertz, Q1, 72 and 272 DOFs against 4,160 (two levels finer than the second): calibrated within 1–3
    (measured 1.11, 1.29 with 3.3); the former 4.6 read the coarse level at 0.80."""
    levels = hertz_levels("Q1", 2, 2)
    calibrated = effectivities(levels)
    assert all(r.error_budget["calibration"] == effectivity("Q1", 2) for r, _ in levels)
    assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated
    assert effectivities(levels, FORMER["Q1", 2]).min() < 1.0


def test_p2_flat_and_coulomb_punches_are_calibrated():
    """The flat punch and a Coulomb punch (F = 0.3), P2, 272 and 1,056 DOFs against 16,512: calibrated within 1–3
    (measured 1.32, 1.42 and 1.34, 1.44 with 5.2); the former 7.2 read them at 0.95–1.04."""
    for law in (None, cc.Coulomb(friction=0.3)):
        levels = hertz_levels("P2", 2, 2, base=flat_punch("P2", law))
        calibrated = effectivities(levels)
        assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated
        assert effectivities(levels, FORMER["P2", 2]).min() < 1.0


def test_q1_and_q2_flat_punches_with_and_without_friction_are_calibrated():
    """The flat punch, Q1 and Q2, Signorini and Tresca (s = 0.005), 72 and 272 (Q1) or 272 and 1,056 (Q2) DOFs against
    65,792 DOFs (four and three levels finer than the second): calibrated within 1–3 (measured Q1 1.15, 1.13 and 1.18,
    1.19 with 2.8; Q2 1.19, 1.16 and 1.25, 1.17 with 4.5); the constants set on Hertz and the pair alone (3.3, 5.2)
    read the frictionless Q1 levels at 0.97, 0.96 (Q2 at 1.03, 0.999)."""
    for element, finer in (("Q1", 4), ("Q2", 3)):
        for law in (None, cc.Tresca(slip_bound=0.005)):
            levels = hertz_levels(element, 2, finer, base=flat_punch(element, law))
            calibrated = effectivities(levels)
            assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated
            if element == "Q1" and law is None:
                assert effectivities(levels, 3.3).max() < 1.0


def test_q1_and_q2_coulomb_pairs_are_calibrated():
    """Two cylinders with Coulomb (F = 0.2, moduli 1 and 3: points slip at the contact's edges), Q1 at 544 and 2,112
    DOFs and Q2 at 2,112, against 33,024: calibrated within 1–3 (measured Q1 1.46, 1.59, Q2 1.80; 1.44–1.54 and
    1.63–1.75 on four and three levels against 525,312 DOFs, docs/estimate.md, "The coverage")."""
    for element, levels in (("Q1", (0, 1, 3)), ("Q2", (0, 2))):
        runs = [cc.solve(coarse_cylinders(element, k, law=cc.Coulomb(friction=0.2), moduli=(1.0, 3.0)))
                for k in levels]
        u = runs[-1].displacement / runs[-1].fem.scaling.displacement
        errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u @ (runs[-1].fem.K_full @ u))
        assert all(r.summary()["n_slip"] > 0 for r in runs[:-1])
        calibrated = effectivities(list(zip(runs[:-1], errors)))
        assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated


def test_adaptive_3d_hertz_is_calibrated():
    """3-D Hertz on P1 tetrahedra (the 0.4 quarter box of 2³ cubes), ten adaptive levels to 411 DOFs against the last
    one's mesh refined uniformly (2,756 DOFs): calibrated within 1–3 (measured 1.21–1.70 with 2.8); the former 3.9,
    set on uniform levels, read the adaptive ones at 0.87–1.22."""
    sphere = cc.Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0), force=HERTZ_SPHERE_FORCE / 4)
    levels = adapt(quarter_box(2, "P1", 1.0, sphere, None, "hertz_sphere", size=0.4), target=1e-9, max_dofs=500)
    scene = levels[-1].scene
    reference = cc.solve(scene_on(scene, [refined_uniformly(mesh, 1) for mesh in body_meshes(scene)]))
    u = reference.displacement / reference.fem.scaling.displacement
    errors = np.array(true_errors(levels, reference)) * np.sqrt(u @ (reference.fem.K_full @ u))
    measured = list(zip(levels, errors))
    calibrated = effectivities(measured)
    assert len(levels) >= 8 and all(r.error_budget["calibration"] == effectivity("P1", 3) for r in levels)
    assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated
    assert effectivities(measured, FORMER["P1", 3]).min() < 1.0


def uniform_levels_3d(base: cc.Scene, levels: int, finer: int):
    """``base`` refined uniformly 0 … levels − 1 times, each level with its true energy error against ``base`` refined
    ``finer`` times more than the last level (nested: prolonged exactly)."""
    element, mesh = base.body.element, build_mesh(base.body)
    runs = [cc.solve(dataclasses.replace(base, body=cc.Body(refined_uniformly(mesh, k), element=element)))
            for k in (*range(levels), levels - 1 + finer)]
    u = runs[-1].displacement / runs[-1].fem.scaling.displacement
    errors = np.array(true_errors(runs[:-1], runs[-1])) * np.sqrt(u @ (runs[-1].fem.K_full @ u))
    return list(zip(runs[:-1], errors))


def test_3d_q1_hexahedra_have_their_own_calibration():
    """The 3-D punch on Q1 hexahedra (the library's default 3-D scene and element), 42 and 260 DOFs against 13,328 (two
    levels finer than the second): the budget divides by the 3-D Q1 constant, not the 2-D one, and reads within 1–3
    (measured 1.62, 1.98 with 2.0; docs/estimate.md, "Hexahedra in 3-D"); the 2-D 3.3 read the first at 0.98, the
    former 4.6 both at 0.70, 0.86."""
    levels = uniform_levels_3d(punch_3d(2, element="Q1"), 2, 2)
    assert all(r.error_budget["calibration"] == EFFECTIVITY_3D["Q1"] != EFFECTIVITY["Q1"] for r, _ in levels)
    calibrated = effectivities(levels)
    assert np.all((1.0 <= calibrated) & (calibrated <= 3.0)), calibrated
    assert effectivities(levels, FORMER["Q1", 2]).max() < 1.0


def test_3d_q2_hexahedra_budget_uses_the_3d_constant():
    """A Q2 hexahedral result's budget divides η by the 3-D Q2 constant (set on the graded box, which the 2-D 5.2 read
    at 0.76–0.86), and reports it."""
    result = cc.solve(quarter_box(1, "Q2", 1.0, cc.Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0),
                                                           force=HERTZ_SPHERE_FORCE / 4), None, "hertz_sphere", 0.4))
    budget = result.error_budget
    assert budget["calibration"] == EFFECTIVITY_3D["Q2"] == effectivity("Q2", 3) != EFFECTIVITY["Q2"]
    assert budget["discretization"] == pytest.approx(result.residual_estimate.relative / EFFECTIVITY_3D["Q2"])
