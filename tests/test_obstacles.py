"""Obstacles a peer's limit needs: the gap along the obstacle's normal, a cylinder as wide as Γ_C, a flat
punch with sharp edges (issue 14)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.scene.library import hertz_punch, quarter_box
from convexcontact.scene.toml import load_scene


def punch(obstacle, law=None, nx=80):
    """The Hertz block [-2, 2] × [-2, 0], its top pressed by ``obstacle``."""
    return dataclasses.replace(hertz_punch(nx=nx), contact=cc.Contact("top", obstacle, law or cc.Signorini()))


def test_closest_point_gap_and_normals_are_the_distance_to_the_cylinder():
    """normal = 'obstacle': at a node x on the top face the gap is |c − x| − R and the normal points to the
    centre c = (0, R − d), also at nodes beyond the radius (where the body's normal misses the cylinder)."""
    R, d = 1.0, 0.01
    result = cc.solve(punch(cc.Obstacle("cylinder", radius=R, depth=d, normal="obstacle")))
    trace, scaling = result.fem.contact, result.fem.scaling
    x = trace.coords * scaling.length
    to_centre = np.array([0.0, R - d]) - x
    distance = np.linalg.norm(to_centre, axis=1)
    assert np.abs(x[:, 0]).max() == pytest.approx(2.0)  # twice the radius
    assert np.allclose(trace.gap * scaling.displacement, distance - R, rtol=0, atol=1e-14)
    assert np.allclose(trace.normals, to_centre / distance[:, None], rtol=0, atol=1e-14)
    assert result.status == "solved" and result.certificate.passes(1e-12)
    beyond = np.abs(x[:, 0]) > R
    assert not result.closed[beyond].any() and result.closed.any()


def test_the_two_normals_differ_by_less_than_the_turn_of_the_obstacles_normal():
    """Against a cylinder, the closest-point variant turns the nodal forces towards the centre by up to
    a/R over the contact zone: both answers differ by less than a/R, and less as R grows."""
    differences = []
    for R in (10.0, 100.0):
        body, obstacle = (cc.solve(punch(cc.Obstacle("cylinder", radius=R, force=0.01, normal=normal)))
                          for normal in ("body", "obstacle"))
        assert body.status == obstacle.status == "solved" and obstacle.certificate.passes(1e-10)
        turn = obstacle.contact_half_width / R
        difference = np.abs(body.displacement - obstacle.displacement).max() / np.abs(body.displacement).max()
        assert 0 < difference < turn
        assert obstacle.contact_half_width == pytest.approx(body.contact_half_width, rel=0.05)
        differences.append(difference)
    assert differences[1] < 0.7 * differences[0]


def test_a_cylinder_as_wide_as_the_contact_boundary_is_accepted():
    """R = the half-width: the end nodes see the gap R (the circle's vertical tangent); a smaller R is
    refused with the body's normal and names the closest-point alternative."""
    result = cc.solve(punch(cc.Obstacle("cylinder", radius=2.0, depth=0.01)))
    assert result.status == "solved" and result.certificate.passes(1e-12)
    assert result.fem.contact.gap.max() * result.fem.scaling.displacement == pytest.approx(2.0 - 0.01)
    with pytest.raises(cc.SceneError, match="normal = 'obstacle'"):
        cc.prepare(punch(cc.Obstacle("cylinder", radius=1.999, depth=0.01)))


def test_sphere_smaller_than_the_face_in_3d_agrees_across_formulations():
    """A sphere of radius 0.8 on a unit quarter face (corner at √2): refused along the body's normal, solved
    along the obstacle's, by the primal and the dual alike, nothing beyond the radius touching."""
    obstacle = cc.Obstacle("sphere", radius=0.8, center=(0.0, 0.0, 0.0), depth=0.01, normal="obstacle")
    scene = quarter_box(6, "Q1", 4.0, obstacle, cc.Signorini(), "sphere")
    primal, dual = (cc.prepare(scene, formulation).solve() for formulation in ("primal", "dual"))
    assert primal.status == dual.status == "solved" and dual.certificate.passes(1e-10)
    assert np.abs(primal.displacement - dual.displacement).max() < 1e-8 * np.abs(dual.displacement).max()
    r = np.linalg.norm(dual.fem.contact.coords[:, :2] * dual.fem.scaling.length, axis=1)
    assert r.max() > 0.8 and dual.closed.any() and not dual.closed[r > 0.8].any()
    with pytest.raises(cc.SceneError, match="obstacle.radius"):
        cc.prepare(dataclasses.replace(scene, contact=dataclasses.replace(
            scene.contact, obstacle=dataclasses.replace(obstacle, normal="body"))))


@pytest.mark.parametrize("normal", ["body", "obstacle"])
def test_flat_punch_is_the_expression_obstacle_that_nothing_outside_can_touch(normal):
    """Node-wise, a flat punch of half-width a acts as a gap of 0 under it and of 1 outside: the same
    displacements (the cut trace drops the nodes outside and their weights)."""
    a = 0.25
    flat = cc.solve(punch(cc.Obstacle("flat_punch", radius=a, force=0.01, normal=normal)))
    outside = cc.Obstacle("expression", force=0.01,
                          expression=lambda x, y: np.where(np.abs(x) <= a * (1 + 1e-12), 0.0, 1.0))
    ramp = cc.solve(punch(outside))
    assert flat.status == ramp.status == "solved" and flat.certificate.passes(1e-12)
    x = flat.fem.contact.coords[:, 0] * flat.fem.scaling.length
    assert np.abs(x).max() <= a and flat.closed.all()
    assert np.abs(flat.displacement - ramp.displacement).max() < 1e-9 * np.abs(ramp.displacement).max()


def test_flat_punch_pressure_has_the_square_root_singularity():
    """Sadowsky's rigid flat punch on a half-plane: p(x) = P / (π sqrt(a² − x²)). On the 4 × 2 block with
    a = 1/8 of its width the interior nodes follow it to about 1 %, with the weak law as with the nodal."""
    a, P = 0.25, 0.01
    for law in (cc.Signorini("nodal"), cc.Signorini("weak")):
        result = cc.solve(punch(cc.Obstacle("flat_punch", radius=a, force=P), law))
        x = result.fem.contact.coords[:, 0] * result.fem.scaling.length
        inner = np.abs(x) < a / 2
        shape = result.contact.pressure[inner] * np.pi * np.sqrt(a**2 - x[inner] ** 2) / P
        assert result.certificate.passes(1e-12)
        assert np.abs(shape - 1.0).max() < 0.02


@pytest.mark.parametrize("shape", [{"shape": "parabolic", "radius": 1.0}, {"shape": "expression", "expression": "x**2"}])
def test_closest_point_needs_a_known_obstacle(shape):
    with pytest.raises(cc.SceneError, match="obstacle.normal.*no closest point"):
        cc.Obstacle(**shape, normal="obstacle")
    with pytest.raises(cc.SceneError, match="obstacle.normal.*'body', 'obstacle'"):
        cc.Obstacle("flat", normal="slave")


def test_a_flat_punch_over_no_whole_facet_is_refused():
    with pytest.raises(cc.SceneError, match="obstacle.radius.*no facet.*finer mesh"):
        cc.prepare(punch(cc.Obstacle("flat_punch", radius=1e-4, depth=0.01), nx=16))


def test_toml_names_the_new_obstacle_keys(tmp_path):
    """The scene file carries shape = 'flat_punch' and normal; a normal the shape cannot have is named."""
    text = (Path(__file__).parents[1] / "examples" / "scenes" / "hertz.toml").read_text()
    punch_file = tmp_path / "punch.toml"
    punch_file.write_text(text.replace('shape = "parabolic"\nradius = 1.0', 'shape = "flat_punch"\nradius = 0.25\n'
                                       'normal = "obstacle"'))
    obstacle = load_scene(punch_file).contact.obstacle
    assert (obstacle.shape, obstacle.radius, obstacle.normal) == ("flat_punch", 0.25, "obstacle")
    punch_file.write_text(text.replace('radius = 1.0', 'radius = 1.0\nnormal = "obstacle"'))
    with pytest.raises(cc.SceneError, match="obstacle.normal: the parabolic obstacle has no closest point"):
        load_scene(punch_file)


def test_a_closest_point_cylinder_indented_nearly_to_its_centre_is_still_the_distance():
    """depth = 0.9 R keeps the centre in front of Γ_C (0.9 R ≥ R is refused): the gap is still |c − x| − R and the
    normals point to the centre, at nodes far beyond the radius too — finite, and solved."""
    R, d = 0.5, 0.45
    result = cc.solve(punch(cc.Obstacle("cylinder", radius=R, depth=d, normal="obstacle"), nx=16))
    trace, scaling = result.fem.contact, result.fem.scaling
    to_centre = np.array([0.0, R - d]) - trace.coords * scaling.length
    distance = np.linalg.norm(to_centre, axis=1)
    assert np.allclose(trace.gap * scaling.displacement, distance - R, rtol=0, atol=1e-14)
    assert np.allclose(trace.normals, to_centre / distance[:, None], rtol=0, atol=1e-14)
    assert result.status == "solved" and result.certificate.passes(1e-10)


@pytest.mark.parametrize("normal", ["body", "obstacle"])
def test_a_huge_cylinder_is_the_parabola_it_tends_to(normal):
    """R − sqrt(R² − r²) lost every digit for R ≫ r (and R² overflowed beyond 1e154): written without the
    cancellation, the gap of a cylinder of radius 1e10 is r²/2R to round-off, along either normal."""
    R = 1e10
    obstacles = (cc.Obstacle("cylinder", radius=R, depth=0.0, normal=normal), cc.Obstacle("parabolic", radius=R))
    gaps = [cc.prepare(punch(obstacle, nx=8)).fem.contact.gap for obstacle in obstacles]
    assert np.allclose(gaps[0], gaps[1], rtol=1e-12, atol=0) and gaps[1].max() > 0  # the old form gave 0
