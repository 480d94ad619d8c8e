"""Several contacts in one scene, each with its own law: pairs of bodies and rigid obstacles (docs/bodies.md).

A frictionless contact among frictional ones is the frictional law with a zero coefficient there — the same
problem, posed without its tangential unknowns — so each mixed scene is checked against that independent
program; a rigid ground under a stack of blocks against the closed-form patch pressure and the balance of
forces.
"""

from pathlib import Path

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.drivers.prepared import prepare
from convexcontact.scene.bodies import Pair, Part, bodies_scene

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
GROUND = cc.Obstacle("flat", gap=0.0)
TOL = 1e-10
"""Picard's tolerance here: the friction law's residual is of the order of the last change of the slip bounds."""


def stack(laws, ground=None, shear=0.004, pressure=0.01):
    """Three blocks of 5, 7 and 6 cells across (E = 1, 3, 1) under pressure and shear on top, rollers on the left
    sides; the bottom block clamped, or on a rigid ``ground`` (a third contact, law ``laws[2]``)."""
    parts = [Part(name, cc.Rectangle(1.0, 1.0, n, n, origin=(0.0, y)), cc.Material(E=E, nu=0.3))
             for name, n, y, E in (("top", 5, 2.0, 1.0), ("middle", 7, 1.0, 3.0), ("bottom", 6, 0.0, 1.0))]
    contact = [Pair("top.bottom", master="middle.top", law=laws[0]), Pair("middle.bottom", master="bottom.top",
                                                                          law=laws[1])]
    supports = [cc.Dirichlet(f"{name}.left", ux=0.0) for name in ("top", "middle", "bottom")]
    if ground is None:
        supports.append(cc.Dirichlet("bottom.bottom", ux=0.0, uy=0.0))
    else:
        contact.append(cc.Contact("bottom.bottom", ground, laws[2]))
    return bodies_scene(parts, contact, dirichlet=supports, tractions=[cc.Traction("top.top", vector=(shear, -pressure))])


def lower_interface(value):
    """A field that is ``value`` on the lower interface (y = 1) and 0 on the upper one (y = 2)."""
    return lambda x, y: value * (y < 1.5)


@pytest.mark.parametrize("mixed, uniform", [
    ((cc.Signorini(), cc.Coulomb(0.3, tol=TOL)), cc.Coulomb(lower_interface(0.3), tol=TOL)),
    ((cc.Signorini(), cc.Tresca(0.002)), cc.Tresca(lower_interface(0.002))),
    ((cc.Coulomb(0.5, tol=TOL), cc.Coulomb(0.1, tol=TOL)), cc.Coulomb(lambda x, y: np.where(y < 1.5, 0.1, 0.5), tol=TOL)),
])
def test_contacts_with_their_own_laws_solve_the_problem_of_one_law_with_fields(mixed, uniform):
    """Each pair's law against one law whose coefficient is a field that takes each pair's value: the same
    answer (u to 1e-8 of its size), certified, with tangential unknowns only at the frictional pairs' nodes."""
    scenes = stack(mixed), stack((uniform, uniform))
    # Clarabel's default tol leaves friction_law at 4e-8 on this stack (the primal's polish does not settle
    # the pairs' active set): the comparison needs each inner solve tighter than the difference it checks
    answers = [cc.solve(scene, formulation="primal", tol=1e-12) for scene in scenes]
    for answer in answers:
        assert answer.status == "solved" and answer.certificate.worst < 1e-8
        assert answer.certificate.residuals["pair_balance"] < 1e-12
    u = [answer.displacement for answer in answers]
    assert np.abs(u[0] - u[1]).max() <= 1e-8 * np.abs(u[1]).max()
    friction = [answer.contact.friction for answer in answers]
    assert np.abs(friction[1]).max() > 1e-4  # friction matters in this scene
    # tractions as accurate as the certificate measures them: relative to the pressure scale p_ref
    np.testing.assert_allclose(friction[0], friction[1], atol=1e-7 * answers[1].contact.pressure.max())
    counts = [prepare(scene).friction.count for scene in scenes]
    frictionless = isinstance(mixed[0], cc.Signorini)
    assert counts == ([8, 14] if frictionless else [14, 14])  # the upper pair has 6 slave nodes, the lower 8


def test_a_rigid_ground_among_pairs_carries_the_patch_pressure():
    """The stack on frictionless rigid ground instead of a clamp, under a uniform pressure: every interface and
    the ground carry it exactly; the ground's reaction goes to no body, so only the pairs balance."""
    result = cc.solve(stack((cc.Signorini(),) * 3, ground=GROUND, shear=0.0))
    assert result.status == "solved" and result.certificate.worst < 1e-10
    np.testing.assert_allclose(result.contact.pressure, 0.01, rtol=1e-10)
    assert result.fem.contact.m == 6 + 8 + 7
    assert result.certificate.residuals["pair_balance"] < 1e-12


def test_the_ground_under_a_punch_on_its_foundation_carries_the_punch():
    """examples/scenes/punch_on_ground.toml: Coulomb between punch and foundation, Signorini on the ground. The
    foundation has no vertical support but the ground, so the ground's resultant is the punch's load; the
    ground's nodes get no tangential unknowns and no friction."""
    scene = cc.scene.load_scene(EXAMPLES / "punch_on_ground.toml")
    result = cc.solve(scene)
    assert result.status == "solved" and result.certificate.worst < 1e-8
    punch, ground = (rows for rows, *_ in result.fem.contact.pieces)
    forces = result.contact.forces  # nodal contact forces on the slave nodes
    load = forces[punch].sum(axis=0)
    assert abs(forces[ground].sum(axis=0)[1] - load[1]) <= 1e-10 * abs(load[1])  # both push their slave up
    assert np.abs(result.contact.friction[ground]).max() == 0.0
    assert np.abs(result.contact.friction[punch]).max() > 0.1 * result.contact.pressure[punch].max() * 0.3
    model = prepare(scene)
    assert model.friction.count == punch.stop - punch.start


def test_with_law_gives_every_contact_that_law():
    mixed = stack((cc.Signorini(), cc.Coulomb(0.3), cc.Signorini()), ground=GROUND)
    one = mixed.with_law(cc.Tresca(0.001))
    assert all(contact.law == cc.Tresca(0.001) for contact in one.contact.pairs)
    assert prepare(one).friction.count == 6 + 8 + 7


@pytest.mark.parametrize("laws, ground, field", [
    ((cc.Tresca(0.001), cc.Coulomb(0.3)), None, "contact[1].law"),
    ((cc.Coulomb(0.3), cc.Coulomb(0.3, tol=1e-6)), None, "contact[1].tol"),
    ((cc.Tresca(0.001), cc.Tresca(0.001, regularization=1e-4)), None, "contact[1].regularization"),
    ((cc.Signorini(), cc.NormalCompliance(1e3)), None, "contact[1].law"),
    ((cc.Signorini(), cc.Signorini(), cc.Signorini()), cc.Obstacle("flat", force=0.01), "contact[2].obstacle"),
    ((cc.Signorini(), cc.Signorini(), cc.Signorini("weak")), GROUND, "contact[2].non_penetration"),
])
def test_what_one_program_cannot_vary_between_contacts_is_refused(laws, ground, field):
    with pytest.raises(cc.SceneError) as error:
        stack(laws, ground=ground)
    assert error.value.field == field


def test_a_scene_file_table_of_several_needs_a_master_or_an_obstacle():
    tables = {"bodies": [], "dirichlet": [], "contact": [{"boundary": "a.b", "master": "c.d"}, {"boundary": "c.e"}]}
    with pytest.raises(cc.SceneError, match=r"contact\[1\]\.master") as error:
        cc.scene.scene_from_dict(tables)
    assert "obstacle" in str(error.value)
    assert tables["contact"][1] == {"boundary": "c.e"}  # the user's tables are not changed


def test_what_pairs_each_node_with_friction_refuses_frictionless_contacts_among_frictional_ones(tmp_path):
    """FClib's contacts and the enumeration of every solution pair each node's normal and tangential unknowns."""
    from convexcontact.interop.fclib_scene import export

    base = cc.bodies_library.punch_on_foundation(0.05)  # both bodies clamped at their backs: K is regular
    scene = bodies_scene(base.body.parts, [Pair("upper.face", master="lower.face", law=cc.Coulomb(0.3)),
                                           cc.Contact("lower.right", cc.Obstacle("flat", gap=0.01))], base.dirichlet)
    for attempt in (lambda: export(scene, tmp_path / "mixed.hdf5"), lambda: cc.all_solutions(scene)):
        with pytest.raises(cc.SceneError) as error:
            attempt()
        assert error.value.field == "contact.law" and "friction = 0" in str(error.value)
