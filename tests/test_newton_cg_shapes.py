"""newton-cg on the duals of hard shapes (issue 25): a pair, long strips, and the scenes of the fuzz suite that
broke it, each against Clarabel on the same program or a closed form."""

import warnings

import numpy as np

import convexcontact as cc


def test_a_slip_bound_of_the_smallest_double_is_a_point_to_the_newton_step():
    """The fuzz suite's long profile drew a Tresca slip bound of 5e-324: the tangent curvature (‖y‖ − ρ)/(cρ) of a
    sliding node overflowed (an error under the warnings policy). Such a disc is its centre to the step: the
    friction traction is 0, so the answer is the frictionless one (its tangential force vanishes)."""
    depth = 5e-3
    scene = cc.Scene(name="tiny slip bound", body=cc.Body(cc.Rectangle(1.0, 0.5, 4, 2, origin=(-0.5, 0.0)), "P1"),
                     materials=cc.Material(1.0, 0.3), dirichlet=(cc.Dirichlet("top", ux=0.3 * depth, uy=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("flat", depth=depth), cc.Tresca(slip_bound=5e-324)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = cc.prepare(scene, "dual").solve("newton-cg")
        frictionless = cc.prepare(scene.with_law(cc.Signorini()), "dual").solve("clarabel")
    assert result.status == "solved" and result.certificate.worst < 1e-12
    assert np.abs(result.contact.friction).max() <= 1e-300
    assert np.allclose(result.contact.pressure, frictionless.contact.pressure, rtol=1e-8,
                       atol=1e-10 * frictionless.max_pressure)
