"""Friction on symmetry planes (issue 25; fem/contact.py, ``symmetry_planes``): a quarter or half model's contact node
on a mirror plane gets the full model's normal (in the plane) and no friction along the plane's normal (its rows
empty), so the model answers as its full model does. Checked against the larger model itself, on a 3-D pair of
spheres and a 2-D pair of cylinders, Tresca and Coulomb; and rollers that are no symmetry plane are left alone."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.scene.bodies import Pair, Part, bodies_scene
from convexcontact.scene.bodies_library import cylinder_mesh, patch_pair, two_spheres

LAWS = {"tresca": cc.Tresca(slip_bound=0.002), "coulomb": cc.Coulomb(friction=0.3)}


def solved(scene: cc.Scene):
    """The model, its result (certified) and the friction traction at each node as a vector (m × d)."""
    model = cc.prepare(scene)
    result = model.solve()
    assert result.status == "solved" and result.certificate.passes(1e-9)
    friction = result.contact.friction.reshape(model.fem.contact.m, -1)
    return model, result, sum(friction[:, [j]] * t for j, t in enumerate(model.fem.contact.frame))


def matched(small: np.ndarray, large: np.ndarray) -> np.ndarray:
    """For each node of the smaller model, the index of the larger model's node at the same place."""
    distance = np.linalg.norm(small[:, None] - large[None], axis=2)
    assert distance.min(axis=1).max() < 1e-12
    return distance.argmin(axis=1)


def agree(small, large, on_plane: np.ndarray, axis: int):
    """The smaller model's pressure and friction are the larger's at the same nodes (relative to the peaks; measured
    3e-12 at most, on the former trace 2e-4 to 7e-3 and the friction along x at the plane's nodes 0.7 to 2.1 times the
    peak friction), and on the plane its friction along the plane's normal is exactly 0 (the larger's is 0 by
    symmetry, to the solve)."""
    (_, result, friction), (_, big, big_friction) = small, large
    at = matched(result.contact.coords, big.contact.coords)
    p_max, t_max = big.contact.pressure.max(), np.abs(big_friction).max()
    assert t_max > 0.01 * p_max  # friction that matters
    assert np.abs(result.contact.pressure - big.contact.pressure[at]).max() < 1e-10 * p_max
    assert np.abs(friction - big_friction[at]).max() < 1e-9 * t_max
    assert on_plane.any() and not friction[on_plane, axis].any()
    assert np.abs(big_friction[at[on_plane], axis]).max() < 1e-9 * t_max


@pytest.mark.parametrize("law", LAWS)
def test_a_quarter_pair_of_spheres_answers_as_its_half_model(law):
    """The quarter (rollers on x = 0 and y = 0) against the half model (its mirror image across x = 0 added, rollers
    on y = 0): both backs' x held, which the mirror keeps (u_x = 0 is its own image). The upper cap 10 times stiffer,
    so the normal load shears the interface. Before the planes were found, the quarter's nodes on x = 0 leaned out of
    the plane (one-sided normals) and their friction along x was the dual's free choice."""
    def scene(half):
        base = two_spheres(4, moduli=(10.0, 1.0), law=LAWS[law], half=half)
        backs = {"upper.top", "lower.bottom"}
        return dataclasses.replace(base, dirichlet=tuple(dataclasses.replace(d, ux=0.0) if d.boundary in backs else d
                                                         for d in base.dirichlet))
    quarter, half = solved(scene(False)), solved(scene(True))
    contact = quarter[0].fem.contact
    on_plane = np.abs(contact.coords[:, 0]) < 1e-12
    agree(quarter, half, on_plane, axis=0)
    axis = np.flatnonzero(on_plane & (np.abs(contact.coords[:, 1]) < 1e-12))
    assert axis.size == 1 and contact.symmetric.reshape(2, -1)[:, axis].all()  # both tangential rows empty
    assert not quarter[2][axis].any()


def cylinders(law, half: bool, h: float = 0.05) -> cc.Scene:
    """Two cylinders' faces (R = 1 above, 10 times stiffer; flat below), Q1 (the triangles' one diagonal breaks the
    mirror symmetry), matching meshes across x = 0, pressed by 0.01; ``half``: x ≥ 0 only, rollers on x = 0."""
    parts = []
    for name, radius, modulus in (("upper", 1.0, 10.0), ("lower", np.inf, 1.0)):
        mesh = cylinder_mesh(h, radius, 1.0, 1.0, name == "upper", quads=True)
        if half:
            mesh = mesh.restrict(mesh.p[0, mesh.t].mean(axis=0) > 0)
            mesh = mesh.with_boundaries({"left": lambda x: np.abs(x[0]) < 1e-9})
        parts.append(Part(name, mesh, cc.Material(E=modulus, nu=0.3), "Q1"))
    rollers = [cc.Dirichlet(f"{name}.left", ux=0.0) for name in ("upper", "lower")] if half else []
    return bodies_scene(parts, Pair("upper.face", master="lower.face", law=law),
                        dirichlet=[cc.Dirichlet("upper.back", ux=0.0, uy=-0.005),
                                   cc.Dirichlet("lower.back", ux=0.0, uy=0.005), *rollers], name="cylinders")


@pytest.mark.parametrize("law", LAWS)
def test_a_half_pair_of_cylinders_answers_as_its_full_model(law):
    """2-D: the half model's node on x = 0 has the full model's normal (0, −1) and its only tangential row empty."""
    half, full = solved(cylinders(LAWS[law], True)), solved(cylinders(LAWS[law], False))
    contact = half[0].fem.contact
    on_plane = np.abs(contact.coords[:, 0]) < 1e-12
    agree(half, full, on_plane, axis=0)
    assert contact.symmetric[on_plane].all() and contact.symmetric.sum() == 1
    assert np.array_equal(contact.normals[on_plane], [[0.0, -1.0]])


def test_a_roller_that_is_no_symmetry_plane_is_left_alone():
    """The patch test's blocks with rollers on both left sides: x = 0 is a symmetry plane (its slave node's friction
    row empty). Not where the lower block's side is free along x (held at its bottom instead: the friction along x
    moves the master there), nor where the upper block's side is clamped (the node has no free DOF: not a roller)."""
    def held(dirichlet):
        scene = dataclasses.replace(patch_pair(4, 4, law=LAWS["tresca"]), dirichlet=dirichlet)
        return cc.prepare(scene).fem.contact.symmetric

    bottom = cc.Dirichlet("lower.bottom", uy=0.0)
    assert held((bottom, cc.Dirichlet("lower.left", ux=0.0), cc.Dirichlet("upper.left", ux=0.0))).sum() == 1
    assert not held((cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0), cc.Dirichlet("upper.left", ux=0.0))).any()
    assert not held((bottom, cc.Dirichlet("lower.left", ux=0.0), cc.Dirichlet("upper.left", ux=0.0, uy=0.0))).any()


def test_a_rigid_obstacle_must_mirror_too():
    """One body, the quarter box under a sphere (Hertz 3-D, rollers on x = 0 and y = 0): the sphere on the z axis
    mirrors across both planes, one moved to x = 0.2 across y = 0 only (x = 0 keeps its rows as they were)."""
    def held(center):
        scene = cc.library.punch_3d(cells=3, law=LAWS["tresca"], element="Q1")
        scene = dataclasses.replace(scene, contact=dataclasses.replace(
            scene.contact, obstacle=dataclasses.replace(scene.contact.obstacle, center=center)))
        contact = cc.prepare(scene).fem.contact
        return contact.symmetric.reshape(2, -1), contact.coords

    (along_x, along_y), coords = held((0.0, 0.0, 0.0))  # the first tangent is x, the second y
    assert np.array_equal(along_x, np.abs(coords[:, 0]) < 1e-12)
    assert np.array_equal(along_y, np.abs(coords[:, 1]) < 1e-12)
    (along_x, along_y), coords = held((0.2, 0.0, 0.0))
    assert not along_x.any() and np.array_equal(along_y, np.abs(coords[:, 1]) < 1e-12)
