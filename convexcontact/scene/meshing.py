"""A body's mesh: the built-in rectangles and boxes, mesh files read with meshio, the checks of a user's mesh,
its named boundaries, and the memory its problem needs (refused before anything is built)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import skfem as fe

from .description import Body, Box, MeshFile, Rectangle, SceneError

ELEMENT_TYPES = {  # (element name, dimension) → (element, meshes it fits, quadrature order)
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
direction (order 2p) is exact; loads ∫b·v need degree p. So P1: 1 point (on triangles the centroid,
:data:`~convexcontact.fem.basis.CENTROID`: scikit-fem's lowest rule there has 3 points), P2: order 2,
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
    # among the boundary facets only: with_boundaries' tests take the midpoint of every facet (0.8 s at 10⁶ DOFs)
    boundary = mesh.boundary_facets()
    midpoints = mesh.p[:, mesh.facets[:, boundary]].mean(axis=1)
    sides = {}
    for i, (axis, names) in enumerate(zip(axes, BOUNDARY_NAMES[dim])):
        for name, value in zip(names, (axis.min(), axis.max())):
            sides[name] = boundary[np.abs(midpoints[i] - value) < tol]
    return same_topology(mesh.with_boundaries(sides), mesh)


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
    """Read a mesh file with meshio (through scikit-fem); physical groups become names. Nodes that no cell of
    the body uses (gmsh's geometry points, arc centres) are dropped, and said in :func:`mesh_warnings`."""
    import meshio
    from skfem.io.meshio import from_meshio

    try:
        raw = meshio.read(geometry.path)
        kept, note = without_unused_nodes(raw, geometry.path)
        mesh = from_meshio(kept)
    except SceneError:
        raise
    except (Exception, SystemExit) as error:  # meshio raises many types (and exits on a bad VTK header)
        raise SceneError("body.mesh", f"could not read {geometry.path}: {error or type(error).__name__}",
                         "give a mesh file meshio reads (gmsh .msh, .vtk, .vtu, .xdmf, …) with the body's cells") \
            from error
    if mesh.dim() == 2 and raw.points.shape[1] == 3 and np.ptp(kept.points[:, 2]) > 0:
        raise SceneError("body.mesh", f"{geometry.path}: 2-D cells with z from {kept.points[:, 2].min():g} to "
                         f"{kept.points[:, 2].max():g}: the body would be flattened without a word",
                         "put the 2-D mesh in a plane z = const, or mesh the body in 3-D (tetrahedra, hexahedra)")
    if note:
        mesh.convexcontact_warnings = (note,)  # read by the assembly into the result's warnings
    return mesh


def mesh_warnings(mesh: fe.Mesh) -> tuple[str, ...]:
    """What reading the mesh changed (:func:`load_mesh`), for the result's warnings."""
    return getattr(mesh, "convexcontact_warnings", ())


def without_unused_nodes(raw, source) -> tuple:
    """The meshio mesh ``raw`` without the points that no cell of the body (the cells of the highest dimension)
    uses, and a sentence saying what went, or None. The cells that name such points (gmsh's vertex cells of
    geometry points) go with them; cells, their data and sets, and point data are renumbered consistently."""
    import meshio

    top = max(block.dim for block in raw.cells)
    used = np.zeros(len(raw.points), bool)
    for block in raw.cells:
        if block.dim == top:
            used[block.data.ravel()] = True
    if used.all():
        return raw, None
    number = np.cumsum(used) - 1  # the new index of each kept point
    kept_cells = [used[block.data].reshape(len(block.data), -1).all(axis=1) for block in raw.cells]
    blocks = [index for index, keep in enumerate(kept_cells) if keep.any()]
    cells = [meshio.CellBlock(raw.cells[i].type, number[raw.cells[i].data[kept_cells[i]]]) for i in blocks]
    cell_data = {name: [np.asarray(data[i])[kept_cells[i]] for i in blocks] for name, data in raw.cell_data.items()}
    renumbered = [np.cumsum(keep) - 1 for keep in kept_cells]
    members = {name: [np.asarray(indices, dtype=int) for indices in of] for name, of in raw.cell_sets.items()}
    cell_sets = {name: [renumbered[i][of[i][kept_cells[i][of[i]]]] for i in blocks] for name, of in members.items()}
    kept = meshio.Mesh(raw.points[used], cells, point_data={name: data[used] for name, data in raw.point_data.items()},
                       cell_data=cell_data, field_data=raw.field_data, cell_sets=cell_sets)
    unused = np.flatnonzero(~used)
    dropped = sum(len(keep) - keep.sum() for keep in kept_cells)
    note = (f"body.mesh: {source}: {unused.size} of {used.size} nodes belong to no cell of the body (the first: "
            f"node {unused[0]} at {np.round(raw.points[unused[0]], 12).tolist()}; gmsh writes its geometry points "
            f"so): dropped{f', with the {dropped} lower-dimensional cells that name them' if dropped else ''}, and "
            "the nodes renumbered")
    return kept, note


BYTES_PER_DOF = {2: 5.5e3, 3: 6.1e3}
"""2-D: peak memory of a contact solve per free DOF, measured 4.4 kB at 2.6·10⁴ DOFs, 3.7 kB at 10⁵, 5.5 kB at
10⁶ (issue 12; the 2-D separators are small). 3-D: a linear solve's, besides the separator term."""
BYTES_PER_SEPARATOR = 47.0
"""3-D: the factorization's fill grows with the square of the largest nested-dissection separator (its dense
front), s DOFs across the body's smallest section. Fitted to the linear solve's peak of a Q1 cube (the 3-D
punch, 2.8·10⁵ DOFs, s = 6348: 3.57 GB) and a flat block (2.75·10⁵ DOFs, s = 3366: 2.18 GB); it predicts a
third, 1.5·10⁵ DOFs and s = 2376, to 3 % (1.2 GB, measured 1.17 GB). A constant per DOF fitted to a dense
contact solve (60 kB) refused a 1.1·10⁶-DOF flat block that needs about 8 GB."""
CONTACT_FACTOR = 2.0
"""3-D: a contact solve's peak over its linear solve's: 1.1–1.5 on the matrix-free dual, up to 2.3 on a dense W."""


def available_memory() -> float:
    """Bytes the machine can still give (MemAvailable), or infinity where it does not say."""
    try:
        lines = Path("/proc/meminfo").read_text().splitlines()
    except OSError:
        return float("inf")
    return next((float(line.split()[1]) * 1024 for line in lines if line.startswith("MemAvailable:")), float("inf"))


def check_memory(dofs: float, dim: int, field_name: str, what: str, fix: str, separator: float | None = None) -> None:
    """Refuse a problem of ``dofs`` unknowns that would not fit in this machine's memory, with the estimate and
    the fix (nx = ny = 10⁵ died in a 74 GiB MemoryError after minutes). ``separator``: DOFs across the body's
    smallest section (3-D; a cube's where unknown)."""
    need, have = memory_need(dofs, dim, separator), available_memory()
    if need > have:
        raise SceneError(field_name, f"{what} make about {dofs:.2g} DOFs, which need about {need / 2**30:.3g} GiB; "
                         f"this machine has {have / 2**30:.3g} GiB available",
                         f"{fix} (about {dofs * have / need:.2g} DOFs of this shape fit)")


def memory_need(dofs: float, dim: int, separator: float | None = None) -> float:
    """Bytes a contact solve of ``dofs`` unknowns needs at its peak (:data:`BYTES_PER_DOF`,
    :data:`BYTES_PER_SEPARATOR`, :data:`CONTACT_FACTOR`)."""
    if dim == 2:
        return dofs * BYTES_PER_DOF[2]
    separator = separator if separator is not None else 3 * (dofs / 3) ** (2 / 3)  # a cube's
    return CONTACT_FACTOR * (dofs * BYTES_PER_DOF[3] + BYTES_PER_SEPARATOR * separator**2)


def check_size(body: Body) -> None:
    """Refuse a built-in mesh too large for this machine before building it."""
    geometry = body.geometry
    cells = (geometry.nx, geometry.ny) if isinstance(geometry, Rectangle) else geometry.cells
    per_cell = 2 if body.element in ("P2", "Q2") else 1
    nodes = sorted(per_cell * n + 1 for n in cells)
    dofs = len(cells) * float(np.prod(nodes))
    names = "nx, ny" if len(cells) == 2 else "cells"
    check_memory(dofs, len(cells), f"body.{names.split(',')[0]}", f"{names} = {list(cells)}",
                 "use fewer cells, or grading to refine only where contact is",
                 3.0 * nodes[0] * nodes[1] if len(cells) == 3 else None)


def check_mesh_size(mesh: fe.Mesh, element: str, source: str) -> fe.Mesh:
    """Refuse a user's mesh whose problem would not fit in memory, before anything is assembled on it."""
    if (element, mesh.dim()) in ELEMENT_TYPES and isinstance(mesh, ELEMENT_TYPES[element, mesh.dim()][1]):
        dofs = mesh.dim() * fe.Dofs(mesh, ELEMENT_TYPES[element, mesh.dim()][0]()).N
        check_memory(dofs, mesh.dim(), "body.mesh", f"{source}: {mesh.t.shape[1]} cells of {element}",
                     "use a coarser mesh, refined only where contact is")
    return mesh


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
        source = str(geometry.path)
        return check_mesh_size(check_mesh(load_mesh(geometry), source), body.element, source)
    if isinstance(geometry, fe.Mesh):
        return check_mesh_size(check_mesh(geometry, "the mesh given"), body.element, "the mesh given")
    raise SceneError("body.mesh", f"unsupported geometry {type(geometry).__name__}")


DEGENERATE = 1e-10
"""Cells whose measure is below this fraction of the mean cell's are degenerate (collapsed nodes, slivers);
nodes closer than this fraction of the mesh's size are one place."""


def check_mesh(mesh: fe.Mesh, source: str) -> fe.Mesh:
    """A user's mesh as it is, or a SceneError saying what is wrong with it and how to fix it (the first of
    :data:`MESH_CHECKS` that fails). Built-in meshes are right by construction and not checked."""
    for check in MESH_CHECKS:
        found = check(mesh)
        if found is not None:
            problem, fix = found
            raise SceneError("body.mesh", f"{source}: {problem}", fix)
    return mesh


def not_a_body(mesh: fe.Mesh):
    """Cells of one dimension (lines): a wire, not a body of plane or 3-D elasticity."""
    if mesh.dim() not in (2, 3):
        return (f"its cells are {mesh.dim()}-D ({type(mesh).__name__})",
                "mesh the body with triangles or quadrilaterals (2-D), tetrahedra or hexahedra (3-D)")


def out_of_plane(mesh: fe.Mesh):
    """Nodes with more coordinates than the cells have dimensions (triangles in 3-D space)."""
    if mesh.p.shape[0] != mesh.dim():
        problem = f"{mesh.dim()}-D cells with {mesh.p.shape[0]} coordinates per node"
        return problem, "give a 2-D body's nodes as x and y only (rows of mesh.p), or mesh the body in 3-D"


def orphan_nodes(mesh: fe.Mesh):
    """Nodes (vertices or, on quadratic meshes, edge and face nodes) that no cell uses."""
    nodes, cell_nodes = mesh.doflocs.shape[1], mesh.dofs.element_dofs
    if cell_nodes.max() >= nodes:  # e.g. scikit-fem's MeshTri2(p, t) given the vertices alone
        problem = (f"the cells use node {cell_nodes.max()} but the mesh has {nodes} nodes (a quadratic mesh given "
                   "its vertices only?)")
        return problem, "read quadratic meshes from a file that holds their edge nodes, or give scikit-fem their doflocs"
    used = np.zeros(nodes, bool)
    used[cell_nodes.ravel()] = True
    if not used.all():
        problem = f"{np.count_nonzero(~used)} of {used.size} nodes belong to no cell (the first: node " \
                  f"{np.flatnonzero(~used)[0]})"
        return problem, "remove them (meshio: mesh.remove_orphaned_nodes(); gmsh: Coherence Mesh)"


def coincident_nodes(mesh: fe.Mesh):
    """Nodes at one place: the cells on either side of them are not connected (a hidden crack)."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(mesh.p.T).query_pairs(DEGENERATE * np.ptp(mesh.p, axis=1).max(), output_type="ndarray")
    if len(pairs):
        where = np.round(mesh.p[:, pairs[0, 0]], 12).tolist()
        problem = f"{len(np.unique(pairs))} nodes share their place with another (the first: nodes " \
                  f"{pairs[0].tolist()} at {where}): the cells on either side are not connected — a crack the " \
                  "solver would not see"
        return problem, ("merge duplicate nodes (gmsh: Coherence Mesh; meshio: merge points within a tolerance) "
                         "or, if the crack is meant, model it as a contact pair")


def degenerate_cells(mesh: fe.Mesh):
    """Cells of (near) zero area or volume: collapsed nodes, slivers."""
    measure = cell_measures(mesh)
    small = measure <= DEGENERATE * measure.mean()
    if small.any():
        cell = np.flatnonzero(small)[0]
        problem = f"{np.count_nonzero(small)} degenerate cells (zero or near-zero area/volume; the first: cell " \
                  f"{cell} with nodes {mesh.t[:, cell].tolist()})"
        return problem, "remesh, or remove collapsed nodes and slivers"


def inverted_cells(mesh: fe.Mesh):
    """Cells turned inside out: a Jacobian that changes sign inside a cell (a twisted quadrilateral or hexahedron),
    or two neighbours on the same side of the facet they share (a fold). Neither depends on the orientation the
    mesh numbers its cells in, which scikit-fem leaves free."""
    jacobian = mesh.mapping().detDF(mesh.refdom.p)  # at the corners of each cell
    twisted = (jacobian.min(axis=1) < 0) & (jacobian.max(axis=1) > 0)
    folded = np.zeros(mesh.t.shape[1], bool)
    folded[mesh.f2t[:, folded_facets(mesh)].ravel()] = True
    bad = twisted | folded
    if bad.any():
        cell = np.flatnonzero(bad)[0]
        problem = f"{np.count_nonzero(bad)} inverted cells (turned inside out, overlapping a neighbour; the first: " \
                  f"cell {cell} with nodes {mesh.t[:, cell].tolist()})"
        return problem, ("remesh, or move the nodes back so that no cell folds over its neighbour "
                         "(quadrilaterals and hexahedra must be convex)")


def folded_facets(mesh: fe.Mesh) -> np.ndarray:
    """Interior facets whose two cells lie on the same side of the facet (centroids of the cells' vertices)."""
    interior = np.flatnonzero(mesh.f2t[1] >= 0)
    corners = mesh.p[:, mesh.facets[:, interior]]  # (dim, nodes per facet, facets)
    a = corners[:, 0]
    if mesh.dim() == 2:
        normal = np.array([corners[1, 1] - a[1], a[0] - corners[0, 1]])
    else:
        normal = np.cross(corners[:, 1] - a, corners[:, 2] - a, axis=0)
    centroid = mesh.p[:, mesh.t].mean(axis=1)
    side = [np.einsum("ij,ij->j", normal, centroid[:, mesh.f2t[k, interior]] - a) for k in (0, 1)]
    return interior[side[0] * side[1] > 0]


MESH_CHECKS = (not_a_body, out_of_plane, orphan_nodes, coincident_nodes, degenerate_cells, inverted_cells)


def cell_measures(mesh: fe.Mesh) -> np.ndarray:
    """Area (2-D) or volume (3-D) of each cell, from the linear element's quadrature."""
    linear = {fe.MeshTri: fe.ElementTriP1, fe.MeshQuad: fe.ElementQuad1, fe.MeshTet: fe.ElementTetP1,
              fe.MeshHex: fe.ElementHex1}
    element = next(element for kind, element in linear.items() if isinstance(mesh, kind))
    return fe.CellBasis(mesh, element(), intorder=2).dx.sum(axis=1)


TOPOLOGY = ("_facets", "_t2f", "_f2t", "_edges", "_t2e")
"""skfem's cached connectivity of a mesh (built on first use; private names, so each is copied only if present)."""


def same_topology(new: fe.Mesh, old: fe.Mesh) -> fe.Mesh:
    """``new`` (``old`` scaled, or with boundaries named) given the connectivity skfem already built for ``old``:
    skfem's ``scaled`` and ``with_boundaries`` make a mesh that builds its facets again — 0.7 s each at 10⁶
    DOFs in 2-D, twice in an assembly of 8.7 s — though neither changes the cells."""
    for name in TOPOLOGY:
        if name in vars(old):
            setattr(new, name, vars(old)[name])
    return new


def scaled(mesh: fe.Mesh, factor: float) -> fe.Mesh:
    """``mesh`` with its coordinates times ``factor``."""
    return same_topology(mesh.scaled([factor] * mesh.dim()), mesh)


def check_boundary(mesh: fe.Mesh, name: str, field_name: str) -> np.ndarray:
    """Facet indices of the named boundary, or an error listing the names there are."""
    boundaries = mesh.boundaries or {}
    if name not in boundaries:
        raise SceneError(field_name, f"unknown boundary {name!r}", f"the mesh has {sorted(boundaries)}")
    facets = np.asarray(boundaries[name])
    if facets.size == 0:
        raise SceneError(field_name, f"boundary {name!r} has no facets")
    return facets
