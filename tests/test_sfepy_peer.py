"""A real peer end to end: sfepy's penalty contact on the scene's mesh, its output file against the exact
answer (issue 14). sfepy is in the test extras; its contact terms are 3-D, penalize at Gauss points and
measure along the obstacle's normal."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.studies import sfepy_peer

pytest.importorskip("sfepy")


def errors(sweep):
    return np.array([row["error"] for row in sweep.rows])


def test_a_flat_plane_penalty_error_falls_like_one_over_k(tmp_path):
    """Pressed by a flat plane over the whole face the exact answer is on every mesh the same: sfepy's
    penalty error is the penalty's alone, tenfold smaller per decade of k."""
    scene = sfepy_peer.sphere_scene(6)
    flat = dataclasses.replace(scene, contact=cc.Contact("top", cc.Obstacle("flat", depth=0.02), cc.Signorini()))
    error = errors(sfepy_peer.penalty_study(flat, [1e1, 1e2, 1e3], tmp_path))
    assert np.all((error[1:] / error[:-1] > 0.07) & (error[1:] / error[:-1] < 0.14))


def test_the_sphere_penalty_error_falls_until_the_discretization_dominates(tmp_path):
    """sfepy's sphere example: the energy error falls like 1/k while the penalty dominates, then stalls at
    the difference of the two discretizations of contact (its Gauss points, our nodes), which a finer mesh
    lowers."""
    sweep = sfepy_peer.penalty_study(sfepy_peer.sphere_scene(8), [1e0, 1e1, 1e3, 1e4], tmp_path / "8")
    error = errors(sweep)
    assert error[1] / error[0] < 0.5 and error[2] / error[1] < 0.3  # the penalty's part
    assert 0.8 < error[3] / error[2] < 1.25  # the floor: more k changes nothing
    finer = errors(sfepy_peer.penalty_study(sfepy_peer.sphere_scene(12), [1e4], tmp_path / "12"))
    assert finer[0] < 0.6 * error[3]


def test_what_sfepy_cannot_be_given_is_named(tmp_path):
    scene = sfepy_peer.sphere_scene(4)
    body_normal = dataclasses.replace(scene, contact=dataclasses.replace(
        scene.contact, obstacle=dataclasses.replace(scene.contact.obstacle, normal="body")))
    with pytest.raises(ValueError, match="obstacle.normal.*'obstacle'"):
        sfepy_peer.run_sfepy(body_normal, 1e3, tmp_path)
    with pytest.raises(ValueError, match="body.mesh.*box"):
        sfepy_peer.run_sfepy(cc.library.hertz_punch(nx=8), 1e3, tmp_path)
    tresca = scene.with_law(cc.Tresca(slip_bound=0.01))
    with pytest.raises(ValueError, match="contact.law.*signorini"):
        sfepy_peer.run_sfepy(tresca, 1e3, tmp_path)
