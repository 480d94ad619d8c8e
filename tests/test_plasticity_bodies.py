"""Issue 27, plastic parts in scenes of several bodies: the parts' plastic points carry the plastic strain, the pair's
mortar rows are the step's contact cones (scene/bodies.py joins the parts into one mesh, so the plastic step takes
the pair's program as it takes an obstacle's). Checked against the elastic two-body solve, against the closed forms
of two stacked blocks compressed across a frictionless interface (plane strain and 3-D), and against the
return-mapping baseline on the same pair."""

import dataclasses

import numpy as np
import pytest
from test_plasticity_fast import history

import convexcontact as cc
from convexcontact import Pair, Part, bodies_scene
from convexcontact.baselines import return_mapping_history
from convexcontact.scene.description import Box

E, NU, YIELD = 1.0, 0.3, 0.002
PUSH = 0.02  # on the left sides: lifts one end of the interface (test_bodies.py)


def pushed_blocks(upper: cc.Material, lower: cc.Material, law) -> cc.Scene:
    """Two unit blocks pressed together and pushed sideways at their left sides (test_bodies.py's): the pair's
    pressure is not uniform; one step."""
    parts = [Part("upper", cc.Rectangle(1.0, 1.0, 4, 4), upper, "Q1"),
             Part("lower", cc.Rectangle(1.0, 1.0, 4, 4, origin=(0.0, -1.0)), lower, "Q1")]
    return bodies_scene(parts, Pair("upper.bottom", master="lower.top", law=law),
                        dirichlet=[cc.Dirichlet("upper.top", ux=0.0, uy=-0.005),
                                   cc.Dirichlet("lower.bottom", ux=0.0, uy=0.005)],
                        tractions=[cc.Traction("upper.left", pressure=PUSH), cc.Traction("lower.left", pressure=PUSH)],
                        history=cc.History([1.0], {"dirichlet[upper.top].uy": [-0.005]}))


@pytest.mark.parametrize("law", [cc.Signorini(), cc.Tresca(slip_bound=1e-3), cc.Coulomb(friction=0.3)])
@pytest.mark.parametrize("both", [False, True])
def test_without_yield_a_step_is_the_elastic_two_body_solve(law, both):
    """σ_Y far above every stress in one part (or both): one step is today's static two-body solve (the elastic
    Coulomb pair by its own Picard map), and nothing flows."""
    elastic = cc.Material(E, NU)
    plastic = cc.Material(E, NU, yield_stress=1e3)
    scene = pushed_blocks(plastic, plastic if both else elastic, law)
    step = cc.run_history(scene).steps[0]
    static = cc.solve(dataclasses.replace(pushed_blocks(elastic, elastic, law), history=None))
    assert step.status == static.status == "solved"
    assert 0 < np.count_nonzero(step.closed) < step.fem.contact.m  # the push lifts one end
    assert np.abs(step.displacement - static.displacement).max() < 1e-8 * np.abs(static.displacement).max()
    assert np.abs(step.contact.forces - static.contact.forces).max() < 1e-8 * np.abs(static.contact.forces).max()
    assert step.max_equivalent_plastic_strain == 0.0


def test_a_viscous_part_beside_a_plastic_one_keeps_its_viscous_step():
    """A Kelvin–Voigt lower block under a plastic upper one (σ_Y far above every stress), the upper top held down for
    three steps while the lower one creeps: the plastic history is the elastic–viscous one of the same pair."""
    viscous = cc.Material(E, NU, viscosity=1.0)
    scenes = [dataclasses.replace(pushed_blocks(upper, viscous, cc.Signorini()),
                                  history=cc.History([0.5, 1.0, 2.0], {"dirichlet[upper.top].uy": [-0.005] * 3}))
              for upper in (cc.Material(E, NU, yield_stress=1e3), cc.Material(E, NU))]
    plastic, elastic = (cc.run_history(scene) for scene in scenes)
    assert plastic.status == elastic.status == "solved"
    moves = [np.abs(step.displacement - elastic.steps[0].displacement).max() for step in elastic.steps[1:]]
    assert min(moves) > 1e-3 * np.abs(elastic.steps[0].displacement).max()  # it creeps
    for a, b in zip(plastic.steps, elastic.steps, strict=True):
        assert np.abs(a.displacement - b.displacement).max() < 1e-9 * np.abs(b.displacement).max()


def stacked(depths, dim: int = 2, law=None) -> cc.Scene:
    """A plastic unit block on an elastic one, frictionless between them, compressed by moving the upper top down by
    ``depths``; rollers elsewhere (the lower bottom, one side of each block), so both are in homogeneous uniaxial
    stress σ_nn = −p, free to widen."""
    plastic, elastic = cc.Material(E, NU, yield_stress=YIELD), cc.Material(E, NU)
    if dim == 2:
        upper, lower = cc.Rectangle(1.0, 1.0, 2, 2), cc.Rectangle(1.0, 1.0, 2, 2, origin=(0.0, -1.0))
        rollers = [cc.Dirichlet(f"{part}.left", ux=0.0) for part in ("upper", "lower")]
    else:
        upper, lower = Box(cells=(1, 1, 1)), Box(cells=(1, 1, 1), origin=(0.0, 0.0, -1.0))
        rollers = [cc.Dirichlet(f"{part}.{side}", **{axis: 0.0}) for part in ("upper", "lower")
                   for side, axis in (("left", "ux"), ("front", "uy"))]
    normal = "uy" if dim == 2 else "uz"
    parts = [Part("upper", upper, plastic, "P1"), Part("lower", lower, elastic, "P1")]
    return bodies_scene(parts, Pair("upper.bottom", master="lower.top", law=law or cc.Signorini()),
                        dirichlet=[*rollers, cc.Dirichlet("upper.top", **{normal: 0.0}),
                                   cc.Dirichlet("lower.bottom", **{normal: 0.0})],
                        history=cc.History(list(range(1, len(depths) + 1)),
                                           {f"dirichlet[upper.top].{normal}": [-d for d in depths]}))


def test_a_plastic_block_on_an_elastic_one_plateaus_at_the_plane_strain_limit():
    """Plane strain (ε_zz = 0), σ_xx = 0, σ_yy = −p. Elastic: σ_zz = νσ_yy, so σ_vm = p√(1 − ν + ν²) and the block
    first yields at p_y = σ_Y/√(1 − ν + ν²), each block shortening by p(1 − ν²)/E. Flowing steadily, the elastic strain
    stops changing, so Δε_p,zz = 0: s_zz = 0 by the flow rule, σ_zz = (σ_xx + σ_yy)/2 = −p/2, σ_vm = (√3/2)p, and the
    load levels off at p = 2σ_Y/√3 = 2k — the plane-strain compression yield stress (Hill, *The Mathematical Theory of
    Plasticity*, 1950, ch. VI–VII; the Ford–Watts test's 1.155 Y). Below p_y nothing flows; beyond, the elastic block's
    shortening follows the plateau's p while the plastic one flows."""
    first_yield, limit = YIELD / np.sqrt(1 - NU + NU**2), 2 * YIELD / np.sqrt(3)
    yield_depth = 2 * first_yield * (1 - NU**2) / E
    result = cc.run_history(stacked([0.9 * yield_depth, 2 * yield_depth, 4 * yield_depth, 8 * yield_depth]))
    assert result.status == "solved" and max(step.certificate.worst for step in result.steps) < 1e-6
    pressure = np.array(result.series()["normal_force"])  # width 1
    below, *flowing = result.steps
    assert pressure[0] == pytest.approx(0.9 * first_yield, rel=1e-10) and below.max_equivalent_plastic_strain == 0.0
    assert (np.diff(pressure) > 0).all() and (pressure < limit * (1 + 1e-9)).all()
    assert pressure[-1] == pytest.approx(limit, rel=1e-4)
    for step, p in zip(flowing, pressure[1:]):
        assert step.max_equivalent_plastic_strain > 0
        mesh = step.fem.mesh
        lower = np.unique(mesh.t[:, mesh.subdomains["lower"]])
        top = lower[mesh.p[1, lower] == 0.0]
        shortening = -step.displacement[step.fem.basis.nodal_dofs[1, top]]
        np.testing.assert_allclose(shortening, p * (1 - NU**2) / E, rtol=1e-8)


def test_in_3d_the_plastic_block_carries_the_yield_stress():
    """3-D, free to widen both ways: uniaxial stress, σ_vm = p, so the block is elastic up to p = σ_Y and carries
    exactly σ_Y beyond (no constraint raises it, unlike plane strain's 2k)."""
    elastic_depth = 2 * YIELD / E
    result = cc.run_history(stacked([0.9 * elastic_depth, 3 * elastic_depth], dim=3))
    assert result.status == "solved" and max(step.certificate.worst for step in result.steps) < 1e-6
    pressure = result.series()["normal_force"]
    assert pressure[0] == pytest.approx(0.9 * YIELD, rel=1e-10) and result.steps[0].max_equivalent_plastic_strain == 0
    assert pressure[1] == pytest.approx(YIELD, rel=1e-8) and result.steps[1].max_equivalent_plastic_strain > 0


def test_the_return_mapping_baseline_agrees_on_two_bodies():
    """The baseline (penalty on the pair's mortar rows, radial return) runs the stacked pair unchanged and approaches
    the conic step's answer as 1/c: forces and displacements tenfold closer for a tenfold penalty."""
    scene = stacked([0.002, 0.004, 0.008, 0.012])
    conic = cc.run_history(scene)
    force = np.array(conic.series()["normal_force"])
    scale = np.abs(conic.steps[-1].displacement).max()
    errors = []
    for penalty in (1e3, 1e4):
        baseline = return_mapping_history(scene, penalty)
        errors.append((np.abs(baseline.normal_force / force - 1).max(),
                       max(np.abs(a - b.displacement).max() for a, b in zip(baseline.displacement, conic.steps)) / scale))
    assert errors[0][0] < 2e-3 and errors[0][1] < 1e-3
    for coarse, fine in zip(*errors):
        assert 8 < coarse / fine < 12


def test_a_plastic_part_in_coulomb_contact_is_its_own_tresca_step():
    """Coulomb friction between the stacked blocks (the plastic one widens faster than the elastic one beneath):
    certified, and the plastic Tresca step by the conic program at the answer's own slip bound F λ_N is the answer."""
    step = cc.run_history(stacked([0.012], law=cc.Coulomb(friction=0.2))).steps[0]
    assert step.status == "solved" and step.max_equivalent_plastic_strain > 0
    assert np.char.startswith(step.contact.status.astype(str), "slip").any()
    tresca = history(stacked([0.012], law=cc.Tresca(slip_bound=0.2 * step.contact.pressure)), fast=False).steps[0]
    assert tresca.status == "solved" and tresca.extra["path"] == "conic"
    assert np.abs(tresca.displacement - step.displacement).max() < 1e-7 * np.abs(step.displacement).max()
