"""Meshes and finite element bases from a scene's body."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import skfem as fe

from ..scene.model import Body, Box, MeshFile, Rectangle, SceneError

_ELEMENTS = {  # (element name, dimension) → (element, meshes it fits, quadrature order)
    ("P1", 2): (fe.ElementTriP1, (fe.MeshTri1,), 1),
    ("P2", 2): (fe.ElementTriP2, (fe.MeshTri1, fe.MeshTri2), 2),
    ("Q1", 2): (fe.ElementQuad1, (fe.MeshQuad1,), 2),
    ("Q2", 2): (fe.ElementQuad2, (fe.MeshQuad1, fe.MeshQuad2), 4),
    ("P1", 3): (fe.ElementTetP1, (fe.MeshTet1,), 1),
    ("P2", 3): (fe.ElementTetP2, (fe.MeshTet1, fe.MeshTet2), 2),
    ("Q1", 3): (fe.ElementHex1, (fe.MeshHex1,), 2),
    ("Q2", 3): (fe.ElementHex2, (fe.MeshHex1, fe.MeshHex2), 4),
}
"""The quadrature order (degree integrated exactly) is chosen on purpose rather than scikit-fem's
default 2·maxdeg: the stiffness integrand ∇φ·∇ψ has degree 2(p−1) on simplices and, on
parallelepipeds, 2p per variable with ∂ lowering one of them — Gauss with p+1 points per
direction (order 2p) is exact; loads ∫b·v need degree p. So P1: 1 point, P2: order 2,
Q1: 2×2(×2), Q2: 3×3(×3) points — the default spends 64 points on a Q1 hex, 343 on Q2.
On distorted quadrilaterals/hexahedra no rule is exact; these are the standard ones."""

BOUNDARY_NAMES = {  # per dimension: the (low, high) sides of each axis
    2: (("left", "right"), ("bottom", "top")),
    3: (("left", "right"), ("front", "back"), ("bottom", "top")),
}


def _outward(length: float, cells: int, ratio: float) -> np.ndarray:
    """Distances of cells+1 nodes from 0 over ``length``, sizes growing geometrically to ``ratio``."""
    sizes = ratio ** (np.arange(cells) / max(cells - 1, 1))
    return np.concatenate([[0.0], np.cumsum(sizes)]) * length / sizes.sum()


def graded(start: float, length: float, cells: int, ratio: float, focus: float | None) -> np.ndarray:
    """Node coordinates of ``cells`` cells on [start, start+length], finest at ``focus``.

    Cell sizes grow geometrically away from the focus, the largest ``ratio`` times
    the smallest (per side). ``focus=None`` gives uniform cells.
    """
    if focus is None or ratio == 1:
        return np.linspace(start, start + length, cells + 1)
    left = float(np.clip(focus - start, 0.0, length))
    n_left = round(cells * left / length)
    n_right = cells - n_left
    x_left = start + left - _outward(left, n_left, ratio)[::-1] if n_left else np.array([start + left])
    x_right = start + left + _outward(length - left, n_right, ratio)[1:] if n_right else np.array([])
    return np.concatenate([x_left, x_right])


def tensor_mesh(*axes: np.ndarray, quads: bool = False) -> fe.Mesh:
    """Tensor-product mesh on the nodes x × y [× z], named sides (see :data:`BOUNDARY_NAMES`).

    Triangles/tetrahedra, or with ``quads`` quadrilaterals/hexahedra. The sides are
    found by their exact coordinates: scikit-fem's ``with_defaults`` uses a tolerance of a
    hundredth of the smallest element, which tags every facet of a row of elements of
    aspect ratio ≳ 50 as "top" or "bottom".
    """
    dim = len(axes)
    kind = {(2, False): fe.MeshTri1, (2, True): fe.MeshQuad1, (3, False): fe.MeshTet1, (3, True): fe.MeshHex1}
    mesh = kind[dim, bool(quads)].init_tensor(*axes)
    tol = 1e-9 * max(np.ptp(axis) for axis in axes)  # of the body size, not of the smallest element
    sides = {}
    for i, (axis, names) in enumerate(zip(axes, BOUNDARY_NAMES[dim])):
        for name, value in zip(names, (axis.min(), axis.max())):
            sides[name] = lambda p, i=i, value=value: np.abs(p[i] - value) < tol
    return mesh.with_boundaries(sides)


def rectangle(geometry: Rectangle, quads: bool) -> fe.Mesh:
    """Structured rectangle with boundaries left, right, bottom, top."""
    x0, y0 = geometry.origin
    gx, gy = geometry.grading
    focus_y = y0 + geometry.height if geometry.refine_y == "top" else y0
    x = graded(x0, geometry.width, geometry.nx, gx, geometry.refine_x)
    y = graded(y0, geometry.height, geometry.ny, gy, focus_y if gy > 1 else None)
    return tensor_mesh(x, y, quads=quads)


def box(geometry: Box, hexes: bool) -> fe.Mesh:
    """Structured box with boundaries left/right (x), front/back (y), bottom/top (z)."""
    axes = [graded(*args) for args in zip(geometry.origin, geometry.size, geometry.cells, geometry.grading,
                                          geometry.refine)]
    return tensor_mesh(*axes, quads=hexes)


def load_mesh(geometry: MeshFile) -> fe.Mesh:
    """Read a mesh file with meshio (through scikit-fem); physical groups become names."""
    import meshio

    try:
        raw = meshio.read(geometry.path)
        mesh = fe.Mesh.load(str(geometry.path))
    except Exception as error:  # meshio raises many types; the user needs the file and the cause
        raise SceneError("body.mesh", f"could not read {geometry.path}: {error}") from error
    if mesh.dim() == 2 and raw.points.shape[1] == 3 and np.ptp(raw.points[:, 2]) > 0:
        raise SceneError("body.mesh", f"{geometry.path}: 2-D cells with z from {raw.points[:, 2].min():g} to "
                         f"{raw.points[:, 2].max():g}: the body would be flattened without a word",
                         "put the 2-D mesh in a plane z = const, or mesh the body in 3-D (tetrahedra, hexahedra)")
    return mesh


BYTES_PER_DOF = {2: 5.5e3, 3: 6.0e4}
"""Peak memory of a solve per free DOF, measured (issue 12): 5.5 GB at 10⁶ DOFs in 2-D, 9.1 GB at 1.6·10⁵
in 3-D — the sparse factorization's fill-in grows faster in 3-D."""


def available_memory() -> float:
    """Bytes the machine can still give (MemAvailable), or infinity where it does not say."""
    try:
        lines = Path("/proc/meminfo").read_text().splitlines()
    except OSError:
        return float("inf")
    return next((float(line.split()[1]) * 1024 for line in lines if line.startswith("MemAvailable:")), float("inf"))


def check_size(body: Body) -> None:
    """Refuse a built-in mesh too large for this machine before building it, with the estimate and the fix
    (nx = ny = 10⁵ died in a 74 GiB MemoryError after minutes)."""
    geometry = body.geometry
    cells = (geometry.nx, geometry.ny) if isinstance(geometry, Rectangle) else geometry.cells
    per_cell = 2 if body.element in ("P2", "Q2") else 1
    dofs = len(cells) * float(np.prod([per_cell * n + 1 for n in cells]))
    need, have = dofs * BYTES_PER_DOF[len(cells)], available_memory()
    if need > have:
        names = "nx, ny" if len(cells) == 2 else "cells"
        fit = have / BYTES_PER_DOF[len(cells)]
        raise SceneError(f"body.{names.split(',')[0]}", f"{names} = {list(cells)} make about {dofs:.2g} DOFs, which need "
                         f"about {need / 2**30:.3g} GiB; this machine has {have / 2**30:.3g} GiB available",
                         f"use fewer cells (about {fit:.2g} DOFs fit), or grading to refine only where contact is")


def build_mesh(body: Body) -> fe.Mesh:
    """The body's mesh in user units."""
    geometry = body.geometry
    if isinstance(geometry, (Rectangle, Box)):
        check_size(body)
    if isinstance(geometry, Rectangle):
        return rectangle(geometry, quads=body.element in ("Q1", "Q2"))
    if isinstance(geometry, Box):
        return box(geometry, hexes=body.element in ("Q1", "Q2"))
    if isinstance(geometry, MeshFile):
        return check_mesh(load_mesh(geometry), str(geometry.path))
    if isinstance(geometry, fe.Mesh):
        return check_mesh(geometry, "the mesh given")
    raise SceneError("body.mesh", f"unsupported geometry {type(geometry).__name__}")


DEGENERATE = 1e-10
"""Cells whose measure is below this fraction of the mean cell's are degenerate (collapsed nodes, slivers)."""


def check_mesh(mesh: fe.Mesh, source: str) -> fe.Mesh:
    """A user's mesh as it is, or an error saying what is wrong with it and how to fix it: nodes in no cell,
    nodes that share coordinates (the mesh is cut there: a hidden crack), degenerate cells. Built-in meshes
    are right by construction and not checked."""
    nodes = mesh.p.shape[1]
    used = np.zeros(nodes, bool)
    used[mesh.t.ravel()] = True
    if not used.all():
        raise SceneError("body.mesh", f"{source}: {np.count_nonzero(~used)} of {nodes} nodes belong to no cell "
                         f"(the first: node {np.flatnonzero(~used)[0]})",
                         "remove them (meshio: mesh.remove_orphaned_nodes(); gmsh: Coherence Mesh)")
    extent = np.ptp(mesh.p, axis=1).max()
    keys = np.round(mesh.p / (1e-10 * extent)).T
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        where = mesh.p[:, first[np.argmax(counts > 1)]]
        raise SceneError("body.mesh", f"{source}: {np.count_nonzero(counts > 1)} places hold two or more nodes (the "
                         f"first at {np.round(where, 12).tolist()}): the cells on either side are not connected — "
                         "a crack the solver would not see", "merge duplicate nodes (gmsh: Coherence Mesh; meshio: "
                         "merge points within a tolerance) or, if the crack is meant, model it as a contact pair")
    measure = cell_measures(mesh)
    small = measure <= DEGENERATE * measure.mean()
    if small.any():
        cell = np.flatnonzero(small)[0]
        raise SceneError("body.mesh", f"{source}: {np.count_nonzero(small)} degenerate cells (zero or near-zero "
                         f"area/volume; the first: cell {cell} with nodes {mesh.t[:, cell].tolist()})",
                         "remesh, or remove collapsed nodes and slivers")
    return mesh


def cell_measures(mesh: fe.Mesh) -> np.ndarray:
    """Area (2-D) or volume (3-D) of each cell, from the linear element's quadrature."""
    linear = {fe.MeshTri: fe.ElementTriP1, fe.MeshQuad: fe.ElementQuad1, fe.MeshTet: fe.ElementTetP1,
              fe.MeshHex: fe.ElementHex1}
    element = next(element for kind, element in linear.items() if isinstance(mesh, kind))
    return fe.CellBasis(mesh, element(), intorder=2).dx.sum(axis=1)


def vector_basis(mesh: fe.Mesh, element: str, intorder: int | None = None) -> fe.Basis:
    """Vector-valued basis of ``element`` on ``mesh`` with the quadrature of :data:`_ELEMENTS`
    (``intorder`` overrides it); refuses mismatched cell types."""
    dim = mesh.dim()
    if (element, dim) not in _ELEMENTS:
        raise SceneError("body.element", f"{element} has no {dim}-D version")
    element_type, mesh_types, order = _ELEMENTS[element, dim]
    if not isinstance(mesh, mesh_types):
        raise SceneError(
            "body.element",
            f"{element} does not fit a {type(mesh).__name__} mesh",
            "use P1/P2 on triangles or tetrahedra and Q1/Q2 on quadrilaterals or hexahedra",
        )
    return fe.Basis(mesh, fe.ElementVector(element_type()), intorder=order if intorder is None else intorder)


def check_boundary(mesh: fe.Mesh, name: str, field_name: str) -> np.ndarray:
    """Facet indices of the named boundary, or an error listing the names there are."""
    boundaries = mesh.boundaries or {}
    if name not in boundaries:
        raise SceneError(field_name, f"unknown boundary {name!r}", f"the mesh has {sorted(boundaries)}")
    facets = np.asarray(boundaries[name])
    if facets.size == 0:
        raise SceneError(field_name, f"boundary {name!r} has no facets")
    return facets
