"""Adaptive refinement: solve → estimate → mark (Dörfler) → refine → solve again (docs/estimate.md).

Triangles and tetrahedra (P1, P2) are refined where the residual indicators say
(:func:`~convexcontact.fem.estimate.dorfler`, scikit-fem's local refinement), one body or several (each where its
own cells are marked; a pair's interface stays non-matching, as mortar takes it); quadrilateral and hexahedral
scenes refine uniformly, and say so. The named boundaries and the subdomains are carried to the new cells. Each level
is an ordinary certified solve of the scene on the new meshes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import skfem as fe
from scipy.spatial import cKDTree

from ..fem.estimate import dorfler
from ..results.result import ContactResult
from ..scene.bodies import Bodies, bodies_scene, straight_sided
from ..scene.description import Body, Scene, SceneError, of_type
from ..scene.meshing import build_mesh
from .solve import solve

LOCAL = (fe.MeshTri1, fe.MeshTet1)
"""The meshes scikit-fem refines locally (others refine uniformly)."""

CANDIDATES = 8
"""Old boundary facets (nearest by midpoint) tested as the parent of a new one."""


GROWTH = None
"""The default least factor by which each level's DOFs grow: none, Dörfler's cells alone. Measured (docs/estimate.md,
"Fewer, bigger levels"): a floor of 1.5 or 2 costs DOFs and time on the flat punch, whose edges need many levels of
local bisection, and changes nothing on Hertz, whose Dörfler levels already double."""


def check_adapt_options(target, max_dofs, fraction, growth=GROWTH) -> tuple[float, int, float, float | None]:
    """The options of :func:`adapt`, refused where they enter."""
    if isinstance(target, bool) or not isinstance(target, (int, float)) or not (0 < target < 1):
        raise ValueError(f"target: a relative energy error in (0, 1), got {target!r}; e.g. 1e-2 for 1 %")
    if isinstance(max_dofs, bool) or not isinstance(max_dofs, (int, np.integer)) or max_dofs <= 0:
        raise ValueError(f"max_dofs: a positive number of DOFs, got {max_dofs!r}; e.g. 200000")
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not (0 < fraction <= 1):
        raise ValueError(f"fraction: the share of η² to refine, in (0, 1], got {fraction!r}; 0.5 is usual")
    if growth is not None and (isinstance(growth, bool) or not isinstance(growth, (int, float))
                               or not (1 < growth < math.inf)):
        raise ValueError(f"growth: the least factor of DOFs from one level to the next, a finite number > 1, got "
                         f"{growth!r}; e.g. 2 (None: Dörfler's cells alone)")
    return float(target), int(max_dofs), float(fraction), None if growth is None else float(growth)


def check_adapt_scene(scene: Scene) -> list[fe.Mesh]:
    """The meshes of a scene the adaptive loop can refine (see :func:`adapt`), else a SceneError naming the field."""
    of_type(scene, Scene, "scene", "build cc.Scene(...) or read a file with cc.load_scene(path)")
    return body_meshes(scene)


def dofs_of(mesh: fe.Mesh, element: str) -> int:
    """The DOF count of ``element`` on ``mesh`` (before Dirichlet elimination), without building a basis."""
    nodes = mesh.nvertices
    if element in ("P2", "Q2"):
        nodes += (mesh.nfacets if mesh.dim() == 2 else mesh.nedges)
        if element == "Q2":
            nodes += mesh.nelements + (mesh.nfacets if mesh.dim() == 3 else 0)
    return mesh.dim() * nodes


def inside(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Whether each point (n, d) lies in its facet, given by its corners (n, d vertices, d), to round-off."""
    edges = corners[:, 1:] - corners[:, :1]  # (n, d − 1, d)
    offset = points - corners[:, 0]
    gram = np.einsum("fik,fjk->fij", edges, edges)
    local = np.linalg.solve(gram, np.einsum("fik,fk->fi", edges, offset)[..., None])[..., 0]
    distance = np.linalg.norm(offset - np.einsum("fi,fik->fk", local, edges), axis=1)
    size = np.sqrt(np.abs(np.linalg.det(gram))) ** (1 / edges.shape[1])
    return (distance <= 1e-9 * size) & (local >= -1e-9).all(axis=1) & (local.sum(axis=1) <= 1 + 1e-9)


def containing(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """For each point (n, d), the index of the simplex among ``corners`` (simplices, vertices, d: facets or cells) it
    lies in: among the nearest by centroid, more of them where a large coarse simplex lies among small ones (graded
    meshes: its centroid is not among the point's nearest)."""
    tree = cKDTree(corners.mean(axis=1))
    found = np.full(len(points), -1)
    todo, count = np.arange(len(points)), CANDIDATES
    while todo.size:
        count = min(count, len(corners))
        _, nearest = tree.query(points[todo], k=count)
        for column in nearest.reshape(todo.size, -1).T:
            hit = (found[todo] < 0) & inside(points[todo], corners[column])
            found[todo[hit]] = column[hit]
        todo = todo[found[todo] < 0]
        if todo.size and count == len(corners):
            raise RuntimeError(f"a point of the refined mesh ({points[todo[0]]}) lies in no facet or cell of the "
                               "coarse one")
        count *= 4
    return found


def parent_facets(new: fe.Mesh, old: fe.Mesh, facets: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """For each of ``new``'s boundary ``facets``, the one of ``old``'s ``candidates`` (boundary facets) it lies in.
    A quadrilateral facet (hexahedra) is the union of the triangles of any three of its corners (Carathéodory)."""
    midpoints = new.p[:, new.facets[:, facets]].mean(axis=1).T
    corners = old.p[:, old.facets[:, candidates]].transpose(2, 1, 0)  # (facets, vertices, d)
    simplices = list(itertools.combinations(range(corners.shape[1]), new.dim()))
    pieces = np.concatenate([corners[:, list(c)] for c in simplices])
    return np.tile(candidates, len(simplices))[containing(midpoints, pieces)]


def inherit_boundaries(new: fe.Mesh, old: fe.Mesh) -> fe.Mesh:
    """``new`` (a refinement of ``old``) with ``old``'s named boundaries: each new boundary facet gets the names of
    the coarse facet it lies in (scikit-fem's local refinement drops the names)."""
    facets = new.boundary_facets()
    parent = parent_facets(new, old, facets, old.boundary_facets())
    names = {}
    for name, old_facets in (old.boundaries or {}).items():
        member = np.zeros(old.nfacets, dtype=bool)
        member[old_facets] = True
        names[name] = facets[member[parent]]
    return contiguous(dataclasses.replace(new, _boundaries=names))


def inherit_subdomains(new: fe.Mesh, old: fe.Mesh) -> fe.Mesh:
    """``new`` (a local refinement of ``old``) with ``old``'s subdomains: each child cell in those of the coarse cell
    holding its centroid. Done by hand: scikit-fem's local refinement of tetrahedra keeps the coarse index arrays,
    which then name the wrong cells and miss the new ones (its triangles' are right, and found the same way here)."""
    if not old.subdomains:
        return new
    parent = containing(new.p[:, new.t].mean(axis=1).T, old.p[:, old.t].transpose(2, 1, 0))
    return dataclasses.replace(new, _subdomains={name: np.flatnonzero(np.isin(parent, cells))
                                                 for name, cells in old.subdomains.items()})


def contiguous(mesh: fe.Mesh) -> fe.Mesh:
    """``mesh`` with C-ordered arrays: scikit-fem's refinement leaves transposed (Fortran-ordered) ones, which every
    later mesh copies with a warning."""
    return dataclasses.replace(mesh, doflocs=np.ascontiguousarray(mesh.doflocs), t=np.ascontiguousarray(mesh.t))


def refine(meshes: Sequence[fe.Mesh], indicators: np.ndarray, fraction: float, growth: float = 1.0,
           element: str = "P1") -> list[fe.Mesh]:
    """The next meshes of the bodies (``indicators``: their cells in order, as one scene concatenates them): on
    triangles and tetrahedra the Dörfler cells of all bodies together refined locally, and more of the next largest
    indicators' cells while the ``element``'s DOFs would grow by less than ``growth`` (every cell at most); every
    cell otherwise. The marked set always holds Dörfler's, so each level keeps its error reduction."""
    if not isinstance(meshes[0], LOCAL):  # with their names: scikit-fem drops them on hexahedra too
        return [refined_uniformly(mesh, 1) for mesh in meshes]
    order = np.argsort(indicators)[::-1]  # dorfler's order: its cells are the first ``count``
    first = np.cumsum([0] + [mesh.nelements for mesh in meshes])
    cells, before = first[-1], sum(dofs_of(mesh, element) for mesh in meshes)
    count = dorfler(indicators, fraction).size
    with names_dropped_quietly():
        while True:
            marked = np.sort(order[:count])
            per_body = np.split(marked, np.searchsorted(marked, first[1:-1]))
            refined = [refined_locally(mesh, local - start) if local.size else mesh
                       for mesh, local, start in zip(meshes, per_body, first)]
            added = sum(dofs_of(mesh, element) for mesh in refined) - before
            if added >= (growth - 1) * before or count == cells:
                break
            # new DOFs grow about in proportion to the marked cells (plus the closure's): aim 10 % beyond the goal
            count = min(cells, max(count + 1, math.ceil(1.1 * count * (growth - 1) * before / max(added, 1))))
    return [new if new is old else inherit_subdomains(inherit_boundaries(new, old), old)
            for new, old in zip(refined, meshes)]


def refined_locally(mesh: fe.Mesh, marked: np.ndarray) -> fe.Mesh:
    """``mesh`` with its ``marked`` cells refined by scikit-fem (triangles: red-green-blue; tetrahedra: longest-edge
    bisection with its closure). scikit-fem's bisection allots room for 8 cells per cell and 9 nodes per node, which
    the closure of a small graded mesh exceeds (a quarter sphere cap of 60 cells became 800 in one step: numpy's "could
    not broadcast"); there it is given the room by isolated padding cells, dropped after: never marked and sharing no
    edge, they keep their indices while the new cells and nodes are appended."""
    room = 0
    while True:
        try:
            padded = mesh if room == 0 else with_padding(mesh, room)
            refined = padded.refined(marked)
            break
        except ValueError as error:  # numpy's, assigning past the room scikit-fem allotted
            if "could not broadcast" not in str(error) or not isinstance(mesh, fe.MeshTet1) or room > 64 * mesh.nelements:
                raise
            room = 4 * max(room, mesh.nelements)
    if room == 0:
        return refined
    cells, nodes, added = mesh.nelements, mesh.nvertices, 4 * room  # the padding: cells [cells, cells + room), nodes
    t = np.delete(refined.t, np.s_[cells:cells + room], axis=1)
    return dataclasses.replace(refined, doflocs=np.delete(refined.p, np.s_[nodes:nodes + added], axis=1),
                               t=np.where(t >= nodes + added, t - added, t))


def with_padding(mesh: fe.MeshTet1, count: int) -> fe.MeshTet1:
    """``mesh`` and ``count`` separate tetrahedra of its size beyond it (after its own cells and nodes)."""
    size = np.ptp(mesh.p, axis=1).max()
    corners = np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) * size
    shifts = mesh.p.max(axis=1)[:, None] + size * (2.0 + 2.0 * np.arange(count))
    p = (corners[:, :, None] + shifts[:, None, :]).reshape(3, -1, order="F")
    t = mesh.nvertices + np.arange(4 * count).reshape(count, 4).T
    return type(mesh)(np.hstack([mesh.p, p]), np.hstack([mesh.t, t]), validate=False)


def refined_uniformly(mesh: fe.Mesh, times: int) -> fe.Mesh:
    """``mesh`` refined uniformly ``times`` times with its named boundaries (scikit-fem drops them on tetrahedra)."""
    if times == 0:
        return mesh
    with names_dropped_quietly():
        return inherit_boundaries(mesh.refined(times), mesh)


@contextlib.contextmanager
def names_dropped_quietly():
    """Silences scikit-fem's log that a refinement drops the named boundaries: the callers carry them over."""
    logger = logging.getLogger("skfem.mesh.mesh")
    disabled, logger.disabled = logger.disabled, True
    try:
        yield
    finally:
        logger.disabled = disabled


def body_meshes(scene: Scene) -> list[fe.Mesh]:
    """The mesh of the scene's body, or of each of its bodies (in the order of its parts, placed)."""
    if isinstance(scene.body, Bodies):
        return [part.mesh() for part in scene.body.parts]  # linear: the parts are joined as linear meshes
    return [linear_mesh(build_mesh(scene.body))]


def linear_mesh(mesh: fe.Mesh) -> fe.Mesh:
    """A quadratic mesh with straight edges as its linear mesh (a P2/Q2 element adds the middle nodes back), since
    scikit-fem refines linear meshes; a curved one is refused: its refinement would lose the curve."""
    try:
        return straight_sided(mesh)
    except SceneError:
        raise SceneError("body.geometry", f"a {type(mesh).__name__} with curved edges: adaptive refinement splits "
                         "straight cells, and would lose the curve", "give a mesh with straight edges, finer where the "
                         "boundary curves (gmsh: element order 1; element = 'P2' adds the middle nodes), or solve it "
                         "without adaptive refinement") from None


def scene_on(scene: Scene, meshes: Sequence[fe.Mesh]) -> Scene:
    """``scene`` on new meshes of its body (one) or of its bodies (in the order of its parts, placed)."""
    if isinstance(scene.body, Bodies):
        parts = tuple(dataclasses.replace(part, geometry=contiguous(mesh), offset=None)
                      for part, mesh in zip(scene.body.parts, meshes))
        return bodies_scene(parts, scene.contact, scene.dirichlet, scene.tractions, scene.name, scene.body_force,
                            scene.history)
    return dataclasses.replace(scene, body=Body(contiguous(meshes[0]), scene.body.element, scene.body.plane))


def adapt(scene: Scene, target: float = 1e-2, max_dofs: int = 200_000, fraction: float = 0.5,
          solver: str = "auto", progress: Callable | None = None, growth: float | None = GROWTH,
          **options) -> list[ContactResult]:
    """Solve ``scene`` on meshes refined where the error indicators are largest, until the estimated relative
    discretization error (``result.error_budget["discretization"]``) is at most ``target`` or the next mesh would
    exceed ``max_dofs``. Each level marks Dörfler's cells (``fraction`` of η²) and more, by indicator, until its
    DOFs grow by ``growth`` at least (None: Dörfler's alone). Several bodies are marked together (one η² over all
    their cells) and each refined where its own cells are; the named boundaries, the contact pairs and the subdomains
    (with their materials) are carried to every level. Returns every level's certified result;
    ``progress(level, result)`` after each."""
    target, max_dofs, fraction, growth = check_adapt_options(target, max_dofs, fraction, growth)
    meshes = check_adapt_scene(scene)
    how = ("local (Dörfler)" if isinstance(meshes[0], LOCAL) else
           "uniform: quadrilaterals and hexahedra are not refined locally")
    levels: list[ContactResult] = []
    start = time.perf_counter()
    while True:
        result = solve(scene_on(scene, meshes), solver, **options)
        result.extra["refinement"] = how
        levels.append(result)
        budget = result.error_budget
        result.extra["adaptive_seconds"] = time.perf_counter() - start  # end to end: every solve, estimate, refinement
        if progress is not None:
            progress(len(levels) - 1, result)
        estimated = None if budget is None else budget["discretization"]
        if estimated is None or not math.isfinite(estimated) or estimated <= target:
            return levels
        refined = refine(meshes, result.error_estimate.indicators, fraction, growth or 1.0, scene.body.element)
        if sum(dofs_of(mesh, scene.body.element) for mesh in refined) > max_dofs:
            result.message = (f"adaptive refinement stopped before the target: the next mesh would exceed max_dofs "
                              f"{max_dofs} (estimated error {estimated:.2e} > target {target:.2e})")
            return levels
        meshes = refined


def plot_levels(levels: Sequence[ContactResult], path, errors: Sequence[float] | None = None, panels: int = 4) -> Path:
    """A PNG of the adaptive sequence: up to ``panels`` of its meshes (the first, the last and evenly between) and the
    estimated relative error (with the true one, ``errors`` relative to ‖u‖_E, where given) against DOFs and against
    the run time so far (``extra["adaptive_seconds"]``, end to end)."""
    from ..results.plots import plt, save_figure

    shown = sorted({round(k * (len(levels) - 1) / max(panels - 1, 1)) for k in range(min(panels, len(levels)))})
    fig = plt.figure(figsize=(3.2 * max(len(shown), 2), 6.4))
    grid = fig.add_gridspec(2, 2 * len(shown))
    meshes = [fig.add_subplot(grid[0, 2 * j:2 * j + 2]) for j in range(len(shown))]
    curves = [fig.add_subplot(grid[1, :len(shown)]), fig.add_subplot(grid[1, len(shown):])]
    for ax, k in zip(meshes, shown):
        mesh = levels[k].fem.mesh
        scale = levels[k].fem.scaling.length
        if mesh.dim() == 2:
            from matplotlib.collections import LineCollection

            ax.add_collection(LineCollection(mesh.p[:, mesh.facets].T * scale, colors="k", linewidths=0.2))
            ax.autoscale()
            ax.set_aspect("equal")
        ax.set_title(f"level {k}: {levels[k].ndof} DOFs", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    dofs = [r.ndof for r in levels]
    seconds = [r.extra.get("adaptive_seconds", math.nan) for r in levels]
    estimated = [(r.error_budget or {}).get("discretization") or math.nan for r in levels]
    for ax, x, label in ((curves[0], dofs, "DOFs"), (curves[1], seconds, "run time so far [s]")):
        ax.loglog(x, estimated, "o-", label="estimate (bound for 2-D P1)")
        if errors is not None:
            ax.loglog(x, errors, "s--", label="true error")
        ax.set_xlabel(label)
        ax.set_ylabel("relative energy error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"adaptive refinement: {levels[0].scene.name} ({levels[-1].extra.get('refinement', '')})", fontsize=10)
    return save_figure(fig, path)
