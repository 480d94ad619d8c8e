"""Adaptive against uniform refinement: the discretization axis of the work-precision study (docs/work_precision.md).

Uniform: the scene's mesh refined 0 … levels − 1 times, each level solved from scratch (its time is that one solve
and its estimate: a user who knew the mesh in advance). Adaptive: :func:`~convexcontact.drivers.adapt.adapt` from the
scene's mesh until the next mesh would exceed the finest uniform level's DOFs (its time is end to end: every level's
solve, estimate and refinement so far). The true error of a level is ‖u_ref − u_h‖_E / ‖u_ref‖_E against a reference
:data:`REFERENCE_LEVELS` uniform refinements finer than the finest mesh of its own family (the meshes of a family are
nested in it, so u_h is prolonged exactly); the estimate is the result's ``error_budget["discretization"]``. ::

    from convexcontact.studies.precision import refinement, work_precision
    rows = refinement.compare(scene, levels=4)
    front = work_precision.pareto(rows)
    print(refinement.table(rows, front)); refinement.plot(rows, "refinement.png", front)
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import skfem as fe
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ...drivers.adapt import (
    GROWTH,
    adapt,
    body_meshes,
    check_adapt_options,
    check_adapt_scene,
    refined_uniformly,
    scene_on,
)
from ...drivers.solve import solve
from ...results.result import ContactResult
from ...scene.description import Scene

REFERENCE_LEVELS = 2
"""Uniform refinements between a family's finest mesh and its reference (the true error then reads ≈ 3 % small for
the rate h¹, ≈ 13 % for the rate h^½ of a singular scene)."""

FIELDS = ("scene", "method", "level", "ndof", "time", "error", "estimate", "effectivity", "reference")


def timed_solve(scene: Scene) -> tuple[ContactResult, float]:
    """The result and the wall time of its solve and its error budget."""
    start = time.perf_counter()
    result = solve(scene)
    result.error_budget  # noqa: B018 -- the estimate is part of what a level costs
    return result, time.perf_counter() - start


def locate(mesh: fe.Mesh, points: np.ndarray, candidates: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The cell of ``mesh`` holding each point (d, n) and the point's reference coordinates (n, d) in it, among its
    nearest cells by centroid, more of them where a thin cell hides (scikit-fem's finder tests every point against the
    union of all candidates: (points × cells) memory on a fine reference). Simplices: the barycentric λ₁ … λ_d;
    quadrilaterals and hexahedra: the (bi-, tri-)linear map's (ξ, η[, ζ]) ∈ [0, 1]^d."""
    tree = cKDTree(mesh.p[:, mesh.t].mean(axis=1).T)
    simplex = mesh.t.shape[0] == mesh.dim() + 1
    cell = np.full(points.shape[1], -1)
    coordinates = np.zeros((points.shape[1], mesh.dim()))
    todo = np.arange(points.shape[1])
    while todo.size:
        k = min(candidates, mesh.nelements)
        _, near = tree.query(points[:, todo].T, k=k)
        near = near.reshape(todo.size, k)
        b = (barycentric if simplex else tensor_coordinates)(mesh, points[:, todo], near)  # (points, k, d)
        tol = 1e-10
        inside = (b >= -tol).all(axis=-1) & ((b.sum(axis=-1) if simplex else b.max(axis=-1)) <= 1 + tol)
        found = inside.any(axis=1)
        column = inside.argmax(axis=1)[found]
        rows = np.flatnonzero(found)
        cell[todo[found]] = near[rows, column]
        coordinates[todo[found]] = b[rows, column]
        if k == mesh.nelements and not found.all():
            raise ValueError("a reference node lies in no cell of the coarse mesh: the meshes are not nested")
        todo, candidates = todo[~found], 4 * candidates
    return cell, coordinates


def barycentric(mesh: fe.Mesh, points: np.ndarray, near: np.ndarray) -> np.ndarray:
    """The coordinates λ₁ … λ_d (points, k, d) of each point (d, points) in each of its candidate simplices ``near``."""
    corners = mesh.p[:, mesh.t[:, near]]  # (d, d + 1, points, k)
    edges = np.moveaxis(corners[:, 1:] - corners[:, :1], (0, 1), (-2, -1))  # (points, k, d, d): edges as columns
    offset = np.moveaxis(points[:, :, None] - corners[:, 0], 0, -1)[..., None]  # (points, k, d, 1)
    return np.linalg.solve(edges, offset)[..., 0]


def tensor_coordinates(mesh: fe.Mesh, points: np.ndarray, near: np.ndarray, steps: int = 6) -> np.ndarray:
    """The reference coordinates (points, k, d) of each point in each candidate quadrilateral or hexahedron ``near``
    by Newton on its (bi-, tri-)linear map (exact in one step on a tensor grid's boxes); a candidate whose map misses
    the point after ``steps`` (a point far outside it) gets NaN, which no inside-test accepts."""
    mapping = fe.MappingIsoparametric(mesh, mesh.elem())
    out = np.empty(near.shape + (mesh.dim(),))
    x = points[:, :, None]
    scale = np.ptp(mesh.p, axis=1).max()
    for j in range(near.shape[1]):
        X = np.full(x.shape, 0.5)
        for _ in range(steps):
            X = X + np.einsum("ijkl,jkl->ikl", mapping.invDF(X, near[:, j]), x - mapping.F(X, near[:, j]))
        missed = np.abs(mapping.F(X, near[:, j]) - x).max(axis=(0, 2)) > 1e-10 * scale
        X[:, missed] = np.nan
        out[:, j] = X[:, :, 0].T
    return out


def bodies_of(mesh: fe.Mesh) -> np.ndarray:
    """The body (connected component, numbered from the lowest vertex) of each vertex."""
    n, t = mesh.nvertices, mesh.t
    edges = sp.coo_matrix((np.ones(t[1:].size), (np.broadcast_to(t[0], t[1:].shape).ravel(), t[1:].ravel())), (n, n))
    return connected_components(edges, directed=False)[1]


def scalar_dofs(fem) -> tuple[np.ndarray, np.ndarray]:
    """The locations (d, n) of the scalar element's DOFs (u_h's nodes, in the order of ``u.reshape(-1, d)``) and
    each cell's DOFs (shape functions × cells)."""
    dofs = fe.assembly.Dofs(fem.mesh, fem.basis.elem.elem)
    return fe.CellBasis(fem.mesh, fem.basis.elem.elem, intorder=1).doflocs, dofs.element_dofs


def prolong(result: ContactResult, points: np.ndarray, body: np.ndarray) -> np.ndarray:
    """The P1, P2, Q1 or Q2 displacement of ``result`` (scaled) at ``points`` (d, n), each point looked for in the
    cells of its own ``body`` (two bodies touch at their contact: a point there lies in both); the element's own shape
    functions at the point's reference coordinates (exact for a finer nested mesh's nodes)."""
    fem = result.fem
    mesh, element = fem.mesh, fem.basis.elem.elem
    label = bodies_of(mesh)
    cell_dofs = fe.assembly.Dofs(mesh, element).element_dofs
    u = (result.displacement / fem.scaling.displacement).reshape(-1, fem.dim)  # (scalar DOFs, d)
    out = np.zeros((points.shape[1], fem.dim))
    for b in np.unique(label):
        at = np.flatnonzero(body == b)
        cells = np.flatnonzero(label[mesh.t[0]] == b)
        cell, local = locate(type(mesh)(np.ascontiguousarray(mesh.p), mesh.t[:, cells]), points[:, at])
        local = local.T
        dofs = cell_dofs[:, cells[cell]]  # (shape functions, points)
        out[at] = sum(element.lbasis(local, k)[0][:, None] * u[dofs[k]] for k in range(dofs.shape[0]))
    return out.ravel()


def true_errors(results: Sequence[ContactResult], reference: ContactResult) -> list[float]:
    """‖u_ref − u_h‖_E / ‖u_ref‖_E of each P1, P2, Q1 or Q2 result, u_h interpolated at the reference's nodes (exact on
    nested meshes; one body or several, each in its own cells)."""
    fine = reference.fem
    u_ref = reference.displacement / fine.scaling.displacement
    norm = np.sqrt(u_ref @ (fine.K_full @ u_ref))
    points, cell_dofs = scalar_dofs(fine)
    body = np.zeros(points.shape[1], dtype=int)
    body[cell_dofs] = bodies_of(fine.mesh)[fine.mesh.t[0]]
    out = []
    for result in results:
        error = u_ref - prolong(result, points, body)
        out.append(float(np.sqrt(error @ (fine.K_full @ error)) / norm))
    return out


def rows_of(method: str, results, seconds, errors, reference: str) -> list[dict]:
    out = []
    for level, (result, spent, error) in enumerate(zip(results, seconds, errors)):
        estimate = (result.error_budget or {}).get("discretization")
        out.append({"scene": result.scene.name, "method": method, "level": level, "ndof": result.ndof,
                    "time": spent, "error": error, "estimate": estimate,
                    "effectivity": None if estimate is None or error == 0 else estimate / error,
                    "reference": reference})
    return out


def compare(scene: Scene, levels: int = 4, fraction: float = 0.5, progress: Callable | None = None,
            growth: float | None = GROWTH, adaptive_dofs: int | None = None) -> list[dict]:
    """Rows (:data:`FIELDS`) of uniform and adaptive refinement of ``scene`` (P1 or P2 triangles or tetrahedra: the
    true error interpolates them); the adaptive loop (Dörfler ``fraction``, DOFs growing by ``growth`` per level) until the
    next mesh would exceed ``adaptive_dofs`` (default: the finest uniform level's); ``progress(text)`` after each
    solve."""
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or levels < 2:
        raise ValueError(f"levels: the number of uniform levels, an integer ≥ 2, got {levels!r}; e.g. 4")
    mesh = check_adapt_scene(scene)[0]  # what the adaptive family will refuse, refused before any solve
    if scene.body.element not in ("P1", "P2") or mesh.t.shape[0] != mesh.dim() + 1:
        raise ValueError(f"scene: the comparison measures P1 or P2 simplices (their true error is interpolated "
                         f"exactly), got {scene.body.element} on {type(mesh).__name__}; give a P1 or P2 scene on "
                         "triangles or tetrahedra")
    if adaptive_dofs is not None and (isinstance(adaptive_dofs, bool) or not isinstance(adaptive_dofs, (int, np.integer))
                                      or adaptive_dofs <= 0):
        raise ValueError(f"adaptive_dofs: a positive number of DOFs, got {adaptive_dofs!r}; e.g. 100000 (None: the "
                         "finest uniform level's)")
    check_adapt_options(0.5, 1, fraction, growth)  # fraction and growth, before any solve
    say = progress or (lambda text: None)
    coarse = body_meshes(scene)
    solve(scene).error_budget  # noqa: B018 -- warm-up: the first solve of a process pays its imports, not timed
    uniform, seconds = [], []
    for k in range(levels):
        result, spent = timed_solve(scene_on(scene, [refined_uniformly(mesh, k) for mesh in coarse]))
        uniform.append(result)
        seconds.append(spent)
        say(f"uniform level {k}: {result.ndof} DOFs, {spent:.2f} s")
    reference, _ = timed_solve(scene_on(scene, [refined_uniformly(mesh, levels - 1 + REFERENCE_LEVELS)
                                                   for mesh in coarse]))
    say(f"uniform reference: {reference.ndof} DOFs")
    adaptive = adapt(scene, target=1e-9, max_dofs=adaptive_dofs or uniform[-1].fem.basis.N, fraction=fraction,
                     growth=growth, progress=lambda k, r: say(f"adaptive level {k}: {r.ndof} DOFs, "
                                                              f"{r.extra['adaptive_seconds']:.2f} s so far"))
    finest = body_meshes(adaptive[-1].scene)
    adaptive_reference, _ = timed_solve(scene_on(scene, [refined_uniformly(mesh, REFERENCE_LEVELS) for mesh in finest]))
    say(f"adaptive reference: {adaptive_reference.ndof} DOFs")
    label = f"{REFERENCE_LEVELS} uniform refinements finer ({{}} DOFs)"
    return (rows_of("uniform", uniform, seconds, true_errors(uniform, reference), label.format(reference.ndof))
            + rows_of("adaptive", adaptive, [r.extra["adaptive_seconds"] for r in adaptive],
                      true_errors(adaptive, adaptive_reference), label.format(adaptive_reference.ndof)))


def table(rows: Sequence[dict], front: Sequence[dict] = ()) -> str:
    """Aligned text table; ``*`` marks the rows of ``front`` (the Pareto front of true error against run time,
    :func:`.work_precision.pareto`)."""
    front = {id(r) for r in front}
    header = f"{'':2}{'method':<10}{'level':>6}{'DOFs':>9}{'time [s]':>10}{'error':>10}{'estimate':>10}{'η/error':>9}"
    lines = [header]
    for r in rows:
        effectivity = "" if r["effectivity"] is None else f"{r['effectivity']:.2f}"
        estimate = "" if r["estimate"] is None else f"{r['estimate']:.3e}"
        lines.append(f"{'*' if id(r) in front else '':2}{r['method']:<10}{r['level']:>6}{r['ndof']:>9}"
                     f"{r['time']:>10.3f}{r['error']:>10.3e}{estimate:>10}{effectivity:>9}")
    lines += [f"reference ({method}): {next(r['reference'] for r in rows if r['method'] == method)}"
              for method in ("uniform", "adaptive") if any(r["method"] == method for r in rows)]
    return "\n".join(lines)


def plot(rows: Sequence[dict], path, front: Sequence[dict] = (), title: str | None = None, optimal: float = 0.5) -> Path:
    """True error and estimate against DOFs (left, with the ``optimal`` rate N^−optimal: for P1 1/2 in 2-D, 1/3 in 3-D;
    P2 twice that)
    and against run time (right, with the Pareto ``front``)."""
    from ...results.plots import plt, save_figure

    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.4))
    for method, color in (("uniform", "tab:blue"), ("adaptive", "tab:red")):
        group = [r for r in rows if r["method"] == method]
        if not group:
            continue
        for ax, key in zip(axes, ("ndof", "time")):
            x = [r[key] for r in group]
            ax.loglog(x, [r["error"] for r in group], "o-", color=color, label=f"{method}: true error")
            ax.loglog(x, [r["estimate"] or np.nan for r in group], "^--", color=color, mfc="none",
                      label=f"{method}: estimate")
    if front:
        axes[1].step([r["time"] for r in front], [r["error"] for r in front], "k-", where="post", lw=1.0,
                     label="Pareto front (true error)")
    ndof = np.array([r["ndof"] for r in rows], dtype=float)
    axes[0].loglog(np.sort(ndof), rows[0]["error"] * (ndof.min() / np.sort(ndof)) ** optimal, "k:", lw=0.8,
                   label=f"N^(−{Fraction(optimal).limit_denominator(6)}) (optimal)")
    for ax, label in zip(axes, ("DOFs", "wall time, end to end [s]")):
        ax.set_xlabel(label)
        ax.set_ylabel("relative energy error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title or f"uniform against adaptive refinement: {rows[0]['scene']}", fontsize=10)
    return save_figure(fig, path)
