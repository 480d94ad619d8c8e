"""sfepy's penalty contact as a real peer: the scene run by sfepy, its output file against the exact answer.

sfepy (``pip install "convexcontact[peer]"``) penalizes penetration at the Gauss points of Γ_C with a
force k·d along the obstacle's normal (``dw_contact_sphere``, ``dw_contact_plane``) and solves by Newton.
:func:`run_sfepy` writes the scene's mesh, builds the same body, supports and obstacle as an sfepy
problem, solves it at one stiffness k and returns sfepy's own output file; :func:`penalty_study` reads
each file back through :func:`.peer.compare_peer` (the route any peer's file takes) and fits the energy
error against k: it falls like 1/k until the two discretizations of the contact condition (sfepy's
Gauss points and current-configuration sphere, our nodes and linearized gap) differ more than the
penalty does. Each row also compares sfepy with our own solve of the same penalty at the same Gauss
points (:class:`~convexcontact.scene.description.NormalCompliance` with ``non_penetration = "gauss"``): two
penalty solvers, cross-validated at every k. ::

    convexcontact study sfepy --cells 8 --stiffness 1e0 1e1 1e2 1e3 1e4 --out out/sfepy

Scenes sfepy can be given: 3-D built-in boxes (P1, Q1), one material, Dirichlet data on the box's named
faces, no tractions, Signorini contact on a face against a sphere (``normal = "obstacle"``: sfepy's
sphere term measures along the sphere's normal) or a flat plane.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...drivers.prepared import prepare
from ...results.output import check_new_files
from ...scene.description import Box, Material, NormalCompliance, Obstacle, Scene, Signorini
from ...scene.library import quarter_box
from ...scene.meshing import BOUNDARY_NAMES
from .peer import compare_peer
from .sweeps import Sweep, plot_sweep, table

TOLERANCE = 1e-6
"""Relative distance (to the box size) within which sfepy's regions select a face's vertices."""


def check_scene(scene: Scene) -> None:
    """Refuse, naming the field, what the translation to sfepy does not cover."""
    problems = [
        (not isinstance(scene.body.geometry, Box), "body.mesh", "a built-in box (sfepy's contact terms are 3-D)"),
        (scene.body.element not in ("P1", "Q1"), "body.element", "P1 or Q1 (sfepy's field of order 1)"),
        (not isinstance(scene.materials, Material), "material", "one material for the whole body"),
        (bool(scene.tractions), "traction", "no tractions (press with the obstacle's depth)"),
        (type(scene.contact.law) is not Signorini, "contact.law", "signorini (sfepy's terms are frictionless)"),
        (scene.contact.obstacle.shape not in ("sphere", "flat"), "obstacle.shape", "sphere or flat"),
        (scene.contact.obstacle.shape == "sphere" and scene.contact.obstacle.normal != "obstacle", "obstacle.normal",
         "'obstacle' (sfepy's sphere term measures along the sphere's normal)"),
        (scene.contact.obstacle.depth is None, "obstacle.depth", "a depth (sfepy's obstacle does not move)"),
        (scene.history is not None, "history", "a static scene"),
    ]
    for wrong, field, fix in problems:
        if wrong:
            raise ValueError(f"{field}: not translated to sfepy; use {fix}")


def face_regions(lower: np.ndarray, upper: np.ndarray) -> dict[str, tuple[str, str]]:
    """sfepy region definitions of the box's named faces (vertices within TOLERANCE of the face)."""
    tol = TOLERANCE * (upper - lower).max()
    regions = {}
    for axis, (low, high) in enumerate(BOUNDARY_NAMES[3]):
        coordinate = "xyz"[axis]
        # sfepy's region grammar reads plain decimals (no exponent in lower case, no numpy repr)
        regions[low] = (f"vertices in ({coordinate} < {lower[axis] + tol:.15f})", "facet")
        regions[high] = (f"vertices in ({coordinate} > {upper[axis] - tol:.15f})", "facet")
    return regions


def contact_term(obstacle: Obstacle, face: str, lower: np.ndarray, upper: np.ndarray, stiffness: float):
    """(material, term) of sfepy's penalty against ``obstacle`` on ``face`` (f = k·d: f₀ = 0, no smoothing)."""
    axis = next(a for a, names in enumerate(BOUNDARY_NAMES[3]) if face in names)
    side = BOUNDARY_NAMES[3][axis].index(face)
    normal = np.zeros(3)
    normal[axis] = 1.0 if side else -1.0
    on_face = (upper if side else lower)[axis]
    if obstacle.shape == "sphere":
        axis_point = np.array(obstacle.axis(3), dtype=float)
        axis_point[axis] = on_face
        centre = axis_point + (obstacle.radius - obstacle.depth) * normal
        return ({"f": [stiffness, 0.0], ".c": centre.tolist(), ".r": obstacle.radius},
                "dw_contact_sphere.6.Contact(obstacle.f, obstacle.c, obstacle.r, v, u)")
    anchor = np.where(np.arange(3) == axis, on_face + (obstacle.gap - obstacle.depth) * normal[axis], 0.0)
    span = 10.0 * (upper - lower).max()  # a polygon far larger than the face: a plane
    square = ((1, 1), (-1, 1), (-1, -1), (1, -1))  # the polygon (in order) on which the plane acts
    corners = [anchor + span * np.insert(np.array(c, float), axis, 0.0) for c in square]
    return ({"f": [stiffness, 0.0], ".n": normal.tolist(), ".a": anchor.tolist(),
             ".bs": [c.tolist() for c in corners]},
            "dw_contact_plane.6.Contact(obstacle.f, obstacle.n, obstacle.a, obstacle.bs, v, u)")


def run_sfepy(scene: Scene, stiffness: float, folder, fem=None) -> Path:
    """Solve ``scene`` with sfepy's penalty contact of stiffness k; the path of sfepy's output (VTK)."""
    check_scene(scene)
    try:
        from sfepy.base.base import output
        from sfepy.base.conf import ProblemConf
        from sfepy.discrete import Problem
    except ImportError as error:
        raise ImportError("sfepy is not installed: pip install \"convexcontact[peer]\"") from error
    output.set_output(quiet=True)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fem = fem or prepare(scene, "primal").fem
    mesh_file = folder / "mesh.vtk"
    type(fem.mesh)(fem.mesh.p * fem.scaling.length, fem.mesh.t).save(mesh_file)  # scikit-fem orders the cells
    lower, upper = fem.mesh.p.min(axis=1) * fem.scaling.length, fem.mesh.p.max(axis=1) * fem.scaling.length
    material = scene.materials
    lame = material.E * material.nu / ((1 + material.nu) * (1 - 2 * material.nu)), material.E / (2 * (1 + material.nu))
    obstacle, term = contact_term(scene.contact.obstacle, scene.contact.boundary, lower, upper, stiffness)
    faces = face_regions(lower, upper)
    regions = {"Omega": "all", "Contact": faces[scene.contact.boundary]}
    ebcs = {}
    for k, support in enumerate(scene.dirichlet):
        if support.boundary not in faces:
            raise ValueError(f"dirichlet[{k}].boundary: {support.boundary!r} is not a face of the box "
                             f"({', '.join(faces)})")
        regions[f"Support{k}"] = faces[support.boundary]
        ebcs[f"support{k}"] = (f"Support{k}", {f"u.{i}": value for i, value in
                                               enumerate((support.ux, support.uy, support.uz)) if value is not None})
    conf = {
        "filename_mesh": str(mesh_file),
        "fields": {"displacement": ("real", 3, "Omega", 1)},
        "materials": {"solid": ({"lam": lame[0], "mu": lame[1]},), "obstacle": (obstacle,)},
        "variables": {"u": ("unknown field", "displacement", 0), "v": ("test field", "displacement", "u")},
        "regions": regions,
        "ebcs": ebcs,
        "equations": {"balance": f"dw_lin_elastic_iso.2.Omega(solid.lam, solid.mu, v, u) + {term} = 0"},
        "solvers": {"ls": ("ls.scipy_direct", {}),
                    "newton": ("nls.newton", {"i_max": 50, "eps_a": 1e-12, "eps_r": 1e-10})},
        "options": {"nls": "newton", "ls": "ls", "output_format": "vtk", "output_dir": str(folder)},
    }
    problem = Problem.from_conf(ProblemConf.from_dict(conf, sys.modules[__name__]))
    problem.ofn_trunk = f"sfepy_k{stiffness:g}"
    from sfepy.base.base import IndexedStruct
    status = IndexedStruct()
    problem.solve(save_results=True, status=status)
    return folder / f"{problem.ofn_trunk}.vtk"


def penalty_study(scene: Scene, stiffness: Sequence[float], folder, solver: str = "auto") -> Sweep:
    """sfepy at each k against the exact answer (``error``: energy error, fitted slope) and against our own
    solve of the same penalty at the same Gauss points (``same_penalty_error``: the two penalty solvers
    cross-validated at every k, what separates them being sfepy's current-configuration geometry)."""
    reference = prepare(scene, "auto").solve(solver)
    if not reference.solved:
        raise ValueError(f"the exact solve ended {reference.status}: {reference.message}")
    rows = []
    for k in stiffness:
        start = time.perf_counter()
        path = run_sfepy(scene, k, folder, reference.fem)
        elapsed = time.perf_counter() - start
        report = compare_peer(reference, path, displacement="u")
        penalty = prepare(scene.with_law(NormalCompliance(k, non_penetration="gauss")), "primal").solve(solver)
        rows.append({"parameter": float(k), "error": report["energy_error"], "status": "solved", "time": elapsed,
                     "same_penalty_error": compare_peer(penalty, path, displacement="u")["energy_error"],
                     "l2_displacement_error": report["l2_displacement_error"], "file": str(path)})
    return Sweep("k", "energy error of sfepy's penalty answer", -1.0, rows)


RADIUS = 0.8
"""The sphere's radius in :func:`sphere_scene`, sfepy's example's."""


def sphere_scene(cells: int = 8, radius: float = RADIUS, depth: float = 0.05, non_penetration: str = "gauss") -> Scene:
    """sfepy's sphere indentation (its example elastic_contact_sphere.py) as a quarter model: a unit box,
    E = 1, ν = 0.3, a sphere of radius 0.8 pressed ``depth`` into the middle of its top face, the cells
    graded 8:1 towards the contact (a ≈ sqrt(R d) = 0.2 spans a few cells). Non-penetration at the Gauss
    points of the faces (scikit-fem's rule for Q1 faces is sfepy's order 6, 16 points) is what sfepy's
    penalty converges to, up to its current-configuration geometry; ``"nodal"`` to compare."""
    obstacle = Obstacle("sphere", radius=radius, center=(0.0, 0.0, 0.0), depth=depth, normal="obstacle")
    return quarter_box(cells, "Q1", 8.0, obstacle, Signorini(non_penetration), "sfepy_sphere")


OUTPUTS = ("mesh.vtk", "sfepy_k*.vtk", "sfepy_penalty.png")
"""What the study writes into --out: the names it would replace."""


def main(argv=None) -> Sweep:
    """``convexcontact study sfepy [--cells N] [--stiffness K …]``: sfepy's penalty sphere at each k against the
    exact answer; sfepy's files and sfepy_penalty.png in --out."""
    from ...scene.meshing import check_size
    from ..arguments import SECONDS_PER_DOF, check_duration, integer, named, number

    parser = argparse.ArgumentParser(prog="convexcontact study sfepy", description=main.__doc__)
    parser.add_argument("--cells", type=integer(1, 8), default=8, help="cells per edge of the quarter box (default 8)")
    parser.add_argument("--depth", type=number("0.05"), default=0.05,
                        help="the sphere's indentation, below its radius 0.8 (default 0.05)")
    parser.add_argument("--non-penetration", choices=["gauss", "nodal"], default="gauss",
                        help="the exact law compared with: at the Gauss points (sfepy's limit, default) or nodes")
    parser.add_argument("--stiffness", type=number("1e3"), nargs="+", default=[1e0, 1e1, 1e2, 1e3, 1e4],
                        help="sfepy's penalty stiffnesses k")
    parser.add_argument("--out", type=Path, default=Path("out/sfepy"), help="folder for sfepy's files and the plot")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    args = parser.parse_args(argv)
    if args.depth >= RADIUS:
        raise ValueError(f"--depth: {args.depth:g} sinks the whole sphere (radius {RADIUS:g}); give a depth below "
                         "it, e.g. 0.05")
    scene = sphere_scene(args.cells, depth=args.depth, non_penetration=args.non_penetration)
    with named("--cells"):
        check_size(scene.body)
    check_duration("--cells/--stiffness", 2 * len(args.stiffness) + 1, SECONDS_PER_DOF * 3 * (args.cells + 1) ** 3,
                   "solves (sfepy's and ours at each k)", "give fewer --cells or --stiffness values")
    check_new_files(args.out, OUTPUTS, "--out", args.overwrite)
    sweep = penalty_study(scene, args.stiffness, args.out)
    print(table(sweep))
    print("against our solve of the same penalty at the same Gauss points (energy error): " +
          ", ".join(f"k = {row['parameter']:g}: {row['same_penalty_error']:.2e}" for row in sweep.rows))
    print("wrote", plot_sweep(sweep, args.out / "sfepy_penalty.png", title="sfepy's penalty sphere against the exact answer"))
    return sweep
