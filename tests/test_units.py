"""Units: a scene in SI with millimetre geometry and its unit-free twin give the same relative answer.

Lengths ×1e-3 (a 4 mm × 2 mm block, a 1 mm punch), E = 2.1e11 Pa, and forces per unit
thickness ×E·L, so that displacement / length and pressure / E are the same numbers as for
E = 1, R = 1. Internally both are scaled to the same program (fem/scaling.py): they must
agree to 1e-8 relative (DESIGN.md, Conventions).
"""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.scene.library import HERTZ_FORCE, frictional_punch, hertz_punch

E_SI = 2.1e11  # Pa
LENGTH = 1e-3  # metres per unit-free length
TOL = 1e-8


def in_si(scene: cc.Scene, obstacle: cc.Obstacle) -> cc.Scene:
    """The scene with lengths ×LENGTH and E = E_SI (one material); ``obstacle`` already in SI."""
    geometry = scene.body.geometry
    if isinstance(geometry, cc.Rectangle):
        geometry = dataclasses.replace(
            geometry,
            width=geometry.width * LENGTH,
            height=geometry.height * LENGTH,
            origin=tuple(np.multiply(geometry.origin, LENGTH)),
            refine_x=geometry.refine_x * LENGTH,
        )
    else:  # a scikit-fem mesh
        geometry = geometry.scaled(LENGTH)
    return dataclasses.replace(
        scene,
        body=dataclasses.replace(scene.body, geometry=geometry),
        materials=dataclasses.replace(scene.materials, E=scene.materials.E * E_SI),
        contact=dataclasses.replace(scene.contact, obstacle=obstacle),
    )


def assert_same_relative_answer(unit_free: cc.ContactResult, si: cc.ContactResult):
    """u / L and λ / E agree to TOL relative to their largest value; the statuses are identical."""
    assert unit_free.status == si.status == "solved"

    def close(a, b):
        np.testing.assert_allclose(b, a, rtol=0, atol=TOL * np.abs(a).max())

    close(unit_free.displacement, si.displacement / LENGTH)
    close(unit_free.contact.pressure, si.contact.pressure / E_SI)
    if unit_free.contact.friction is not None:
        close(unit_free.contact.friction, si.contact.friction / E_SI)
        close(unit_free.contact.slip, si.contact.slip / LENGTH)
    np.testing.assert_array_equal(unit_free.contact.status, si.contact.status)
    np.testing.assert_allclose(si.contact.coords / LENGTH, unit_free.contact.coords, rtol=1e-14, atol=1e-14)


def test_hertz_force_control_in_si_and_unit_free():
    """Force P per unit thickness scales as E·L: P_SI = HERTZ_FORCE × 2.1e11 × 1e-3 N/m."""
    unit_free = hertz_punch(nx=24)
    si = in_si(unit_free, cc.Obstacle("parabolic", radius=LENGTH, force=HERTZ_FORCE * E_SI * LENGTH))
    a, b = cc.solve(unit_free), cc.solve(si)
    assert_same_relative_answer(a, b)
    assert b.obstacle_advance / LENGTH == pytest.approx(a.obstacle_advance, rel=TOL)
    assert b.normal_force / (E_SI * LENGTH) == pytest.approx(HERTZ_FORCE, rel=1e-8)


@pytest.mark.parametrize("indentation", ["depth", "in the formula"])
def test_gap_expression_in_si_and_unit_free(indentation):
    """g = x²/(2R) − d written as a formula in the user's coordinates (metres for SI)."""
    base = hertz_punch(nx=24)
    if indentation == "depth":
        obstacles = (cc.Obstacle("expression", expression="x**2/2", depth=0.02),
                     cc.Obstacle("expression", expression="x**2/(2*0.001)", depth=0.02 * LENGTH))
    else:
        obstacles = (cc.Obstacle("expression", expression="x**2/2 - 0.02"),
                     cc.Obstacle("expression", expression="x**2/(2*0.001) - 0.02*0.001"))
    unit_free = dataclasses.replace(base, contact=dataclasses.replace(base.contact, obstacle=obstacles[0]))
    assert_same_relative_answer(cc.solve(unit_free), cc.solve(in_si(unit_free, obstacles[1])))


def test_coulomb_punch_in_si_and_unit_free():
    """Oden's punch with F = 0.6 (dimensionless): same fields, same zones, same Picard iterations."""
    unit_free = frictional_punch(h=0.02, friction=0.6, element="Q1")
    obstacle = dataclasses.replace(unit_free.contact.obstacle, radius=LENGTH, depth=0.02 * LENGTH)
    a, b = cc.solve(unit_free), cc.solve(in_si(unit_free, obstacle))
    assert a.extra["picard"]["outcome"] == b.extra["picard"]["outcome"] == "converged"
    assert a.extra["picard"]["iterations"] == b.extra["picard"]["iterations"]
    assert_same_relative_answer(a, b)
    assert {"stick", "slip+", "slip-"} <= set(a.contact.status)


@pytest.mark.parametrize("formulation", ["primal", "dual"])
def test_a_load_of_round_off_size_does_not_set_the_scale(formulation):
    """A lone imposed 4e-290 m (found by the fuzz suite) once made the scaled gap 1e287 and the dual fail:
    the displacement scale is at least 1e-12 of the body size, and the answer is u ≈ 0, no contact."""
    base = cc.library.pressure_patch(nx=4)
    scene = dataclasses.replace(base, tractions=(), dirichlet=(cc.Dirichlet("top", ux=4e-290, uy=0.0),),
                                contact=cc.Contact("bottom", cc.Obstacle("flat", gap=1e-3), cc.Signorini()))
    result = cc.solve(scene, formulation=formulation)
    assert result.status == "solved" and result.certificate.passes(1e-12)
    # the body translates rigidly by 4e-290; its free nodes come from a factorization, to round-off
    assert np.abs(result.displacement).max() <= 4e-290 * (1.0 + 1e-12) and not result.closed.any()


def _same(ours, fresh, name="trace"):
    """Equal to round-off, field by field (arrays, sparse matrices, nested traces and tuples)."""
    if dataclasses.is_dataclass(ours):
        for item in dataclasses.fields(ours):
            _same(getattr(ours, item.name), getattr(fresh, item.name), f"{name}.{item.name}")
    elif isinstance(ours, (tuple, list)):
        assert len(ours) == len(fresh), name
        for i, (a, b) in enumerate(zip(ours, fresh)):
            _same(a, b, f"{name}[{i}]")
    elif hasattr(ours, "toarray"):
        assert abs(ours - fresh).max() <= 1e-14 * max(abs(fresh).max(), 1.0), name
    elif isinstance(ours, (np.ndarray, float)):
        np.testing.assert_allclose(ours, fresh, rtol=1e-13, atol=1e-14 * np.abs(fresh).max(initial=1.0), err_msg=name)
    else:
        assert ours == fresh or (ours is None and fresh is None), name


def _rescaled_scenes():
    from convexcontact.scene.bodies_library import patch_pair
    from convexcontact.scene.library import hertz_sphere

    pulled = cc.Obstacle("parabolic", radius=1.0, force=HERTZ_FORCE, tangential_force=0.1 * HERTZ_FORCE)
    return {
        "force and tangential force": dataclasses.replace(
            hertz_punch(nx=16), contact=cc.Contact("top", pulled, cc.Tresca(slip_bound=0.01))),
        "gauss points": hertz_punch(nx=16, law=cc.Signorini(non_penetration="gauss")),
        "contact nodes prescribed": dataclasses.replace(  # the top left corner moves: nonzero offsets
            hertz_punch(nx=16, law=cc.Tresca(slip_bound=0.01)),
            dirichlet=(cc.Dirichlet("left", ux=1e-3, uy=-2e-3),)),
        "two bodies": patch_pair(),
        "3-D": hertz_sphere(cells=5),
    }


@pytest.mark.parametrize("name", list(_rescaled_scenes()))
def test_the_trace_in_scaled_units_is_the_trace_built_in_them(name):
    """The assembly takes the contact trace in user displacement units (the overlap sets the scale) and rescales
    it: every field equals the trace built in the scaled units from the start."""
    from convexcontact.fem.assembly import assemble, build_trace

    scene = _rescaled_scenes()[name]
    fem = assemble(scene)
    assert not np.isclose(fem.scaling.displacement, 1.0)
    fresh = build_trace(scene.contact, fem.mesh, fem.basis, fem.scaling, fem.free, fem.prescribed)
    _same(fem.contact, fresh)
