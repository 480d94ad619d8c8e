"""The contact trace: nodes of Γ_C, normals, tangents, weights, operators N and T, gap (2-D and 3-D)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import skfem as fe

from ..scene.description import COVERED, Contact, SceneError, check_order
from ..scene.meshing import check_boundary
from .scaling import Scaling


@dataclass
class ContactPoints:
    """The Gauss points of Γ_C where non-penetration holds (``non_penetration = "gauss"``), scaled units.

    ``interpolation`` G (points × contact nodes) takes nodal values to the points, ``weights`` ω_q are
    the quadrature weights, ``gap`` the obstacle's gap at each point (evaluated there, not interpolated)
    and ``C`` = diag(ω) G the rows that weigh u_N: Σ_i C_qi (u_N,i − …) ≤ ω_q g_q.
    """

    interpolation: sp.csr_matrix
    weights: np.ndarray
    coords: np.ndarray
    gap: np.ndarray
    C: sp.csr_matrix = field(init=False)

    def __post_init__(self):
        self.C = sp.csr_matrix(sp.diags(self.weights) @ self.interpolation)


@dataclass
class ContactTrace:
    """Contact nodes i = 1..m of Γ_C in scaled units, in d = 2 or 3 dimensions.

    ``N`` (m × free DOFs) and ``T`` (m(d−1) × free DOFs) give u_N = N u + normal_offset
    and u_T = T u + tangent_offset, the offsets coming from Dirichlet data. T stacks
    its rows component-major: all nodes along the first tangents ``tangents``, then
    (3-D) all along the second tangents ``bitangents`` = n × t. In 2-D the tangents
    point towards increasing ``coordinate`` (the position along Γ_C projected on
    its mean tangent); in 3-D the first tangent is the global axis most orthogonal
    to the mean normal, projected on each node's tangent plane, and ``coordinate``
    is the position along the mean first tangent. ``weights`` are w_i = ∫ψ_i ds,
    ``mass`` the consistent boundary mass M of the trace space. ``obstacle_coupling``
    (force control only) is how much a unit advance of the obstacle closes the gap at
    each node; ``tangential_coupling`` (tangential force only, 2-D) is the tangential
    motion of each node's obstacle point for a unit tangential translation of the obstacle.
    """

    facets: np.ndarray
    dofs: np.ndarray  # (m, d) full DOF indices (x, y[, z] components)
    coords: np.ndarray  # (m, d)
    normals: np.ndarray  # (m, d)
    tangents: np.ndarray  # (m, d)
    coordinate: np.ndarray  # (m,)
    weights: np.ndarray
    mass: sp.csr_matrix
    N: sp.csr_matrix
    T: sp.csr_matrix
    normal_offset: np.ndarray
    tangent_offset: np.ndarray
    gap: np.ndarray
    obstacle_coupling: np.ndarray | None
    obstacle_force: float
    tangential_coupling: np.ndarray | None = None
    obstacle_tangential_force: float = 0.0
    bitangents: np.ndarray | None = None  # (m, 3) in 3-D
    points: ContactPoints | None = None  # Gauss-point non-penetration only
    multiplier_transform: sp.csr_matrix | None = None  # ψ̃ = T ψ of weak rows (P2 tetrahedra)
    symmetric: np.ndarray | None = None  # rows of T held by a symmetry plane, left empty (:func:`symmetry_planes`)

    def in_displacement_units(self, scale: float) -> ContactTrace:
        """This trace with displacements measured in units ``scale`` times as large: gaps, offsets and the
        obstacle's forces (a force scale is a displacement scale times a stiffness) divided by ``scale``, the
        only fields the displacement scale enters."""
        points = None if self.points is None else replace(self.points, gap=self.points.gap / scale)
        return replace(self, gap=self.gap / scale, normal_offset=self.normal_offset / scale,
                       tangent_offset=self.tangent_offset / scale, obstacle_force=self.obstacle_force / scale,
                       obstacle_tangential_force=self.obstacle_tangential_force / scale, points=points)

    @property
    def m(self) -> int:
        return self.coords.shape[0]

    @property
    def dim(self) -> int:
        return self.coords.shape[1]

    def at_points(self, C: sp.spmatrix) -> bool:
        """Whether ``C`` is the Gauss points' rows (:class:`ContactPoints`), not the nodes'."""
        return self.points is not None and C is self.points.C

    def weighted_gap(self, C: sp.spmatrix) -> np.ndarray:
        """C g, the gap weighted as the rows of ``C`` weigh u_N; at Gauss points, ω_q g_q with the gap
        evaluated at each point (C interpolates the displacement, not the obstacle)."""
        if self.at_points(C):
            return self.points.weights * self.points.gap
        return C @ self.gap

    def row_weights(self, C: sp.spmatrix) -> np.ndarray:
        """The length (area) each row of ``C`` stands for, which turns C(u_N − g) back into a gap: w_i = ∫ψ_i (∫ψ̃_i
        for P2 tetrahedra: :func:`multiplier_transform`); ω_q at Gauss points."""
        if self.at_points(C):
            return self.points.weights
        return self.weights

    def nodal_pressure(self, C: sp.spmatrix, multipliers: np.ndarray) -> np.ndarray:
        """The pressure at the contact nodes: the multipliers themselves (weak rows on P2 tetrahedra: the nodal values
        Tᵀλ̃ of p = Σ λ̃_k ψ̃_k), or from Gauss-point multipliers the nodal force Cᵀλ over w_i (unique where the
        point multipliers are not: more points than nodes; on P2 tetrahedra ∫p ψ̃_i / ∫ψ̃_i, ψ's vertex moments
        being ~0 for a smooth p)."""
        transform = self.multiplier_transform
        if self.at_points(C):
            forces = C.T @ multipliers
            return (forces if transform is None else transform @ forces) / self.weights
        if transform is not None and C is self.mass:
            return transform.T @ multipliers
        return multipliers

    @property
    def frame(self) -> list[np.ndarray]:
        """The d − 1 tangent fields, in the order of T's row blocks."""
        return [self.tangents] if self.bitangents is None else [self.tangents, self.bitangents]


def _rows(vectors: np.ndarray, dofs: np.ndarray, ndofs: int) -> sp.csr_matrix:
    """m × ndofs matrix whose row i takes the dot product of vectors[i] with node i's displacement."""
    m, dim = dofs.shape
    return sp.csr_matrix((vectors.ravel(), (np.repeat(np.arange(m), dim), dofs.ravel())), shape=(m, ndofs))


ROUNDOFF = 1e-14
"""Components of a unit normal below this are round-off of the quadrature and set to zero."""


def tangent_frame(normals: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Unit tangents (and in 3-D bitangents n × t) at each node, and the mean first tangent.

    2-D: t = (n_y, −n_x), oriented so that the mean tangent's largest component is
    positive. 3-D: the global axis most orthogonal to the mean normal, projected on each
    node's tangent plane (x before y before z on ties) — one smooth choice for a plane or
    gently curved Γ_C, so the friction cone's components mean the same direction at
    neighbouring nodes.
    """
    mean_normal = weights @ normals
    mean_normal /= np.linalg.norm(mean_normal)
    if normals.shape[1] == 2:
        tangents = np.column_stack([normals[:, 1], -normals[:, 0]])
        mean = weights @ tangents
        sign = 1.0 if mean[np.argmax(np.abs(mean))] >= 0 else -1.0
        return sign * tangents, None, sign * mean / np.linalg.norm(mean)
    alignment = np.abs(mean_normal)  # ties (a plane Γ_C normal to an axis) go to the first axis: x before y
    reference = np.eye(3)[np.flatnonzero(alignment <= alignment.min() + 1e-9)[0]]
    tangents = reference - (normals @ reference)[:, None] * normals
    norm = np.linalg.norm(tangents, axis=1, keepdims=True)
    if norm.min() < 1e-3:
        raise SceneError("contact.boundary", "Γ_C turns by about 90° (its normal meets every tangent axis)",
                         "split it into contact boundaries that are each roughly flat or gently curved")
    tangents /= norm
    mean = reference - (mean_normal @ reference) * mean_normal
    return tangents, np.cross(normals, tangents), mean / np.linalg.norm(mean)


def axis_offset(obstacle, coords: np.ndarray, coordinate: np.ndarray, mean_normal: np.ndarray,
                mean_tangent: np.ndarray) -> np.ndarray:
    """Each node's offset (m × d, user units) from the punch axis in Γ_C's mean plane: along the mean
    tangent from ``obstacle.center`` in 2-D; from the axis through the point ``center`` along the mean
    normal in 3-D. Its length is the r of the shaped obstacles, signed in 2-D (the coordinate minus the
    centre)."""
    if coords.shape[1] == 2:
        obstacle.axis(2)
        return np.outer(coordinate - obstacle.center, mean_tangent)
    offset = coords - obstacle.axis(3)
    return offset - np.outer(offset @ mean_normal, mean_normal)


def axis_distance(offset: np.ndarray, mean_tangent: np.ndarray) -> np.ndarray:
    """r from :func:`axis_offset`: signed along the mean tangent in 2-D, the distance in 3-D."""
    return offset @ mean_tangent if offset.shape[1] == 2 else np.linalg.norm(offset, axis=1)


PLANE = 1e-9
"""Distance, relative to the mesh's size, within which a point lies on a coordinate plane."""

TILT = np.sqrt(0.5)
"""The most a node's normal may lean out of a symmetry plane (|n·e|, 45°) for the node to be treated as on it."""


def symmetry_planes(mesh: fe.Mesh, basis: fe.Basis, dofs: np.ndarray, normals: np.ndarray, free: np.ndarray,
                    prescribed: np.ndarray) -> np.ndarray:
    """(m, d) mask: contact node i (``dofs``, its full DOFs) lies on a mirror-symmetry plane normal to axis e_a.

    A quarter or half model's roller stands for the mirror image beyond it, where n_i and the friction along e_a are
    what the full model's symmetry makes them: n_i in the plane, no friction along e_a (u·e_a is odd across the
    plane, the shape functions of a node on it even). The rule, conservative (a roller that is no symmetry keeps its
    rows as they are):

    - the plane x_a = c bounds the whole mesh (every body lies on one side: c is the mesh's least or largest x_a) and
      holds a boundary facet of it (a face, not a corner or an edge touching it);
    - every node of the mesh on the plane holds u_a = 0: a roller over all of it, so on a pair the master's nodes
      there too (a master free along e_a there is moved by the friction along e_a, which the full model then has);
    - node i lies on it, holds u_a = 0 and has a free component (a clamped node's rows are empty anyway), and its
      normal leans at most :data:`TILT` out of the plane.

    A rigid obstacle must be symmetric about the plane too: :func:`contact_trace` checks its gap.
    """
    dim = mesh.dim()
    held = prescribed == 0.0
    held[free] = False
    candidates = ~held[dofs].all(axis=1)[:, None] & held[dofs] & (np.abs(normals) <= TILT)
    planes = np.zeros(dofs.shape, bool)
    if not candidates.any():  # no roller on Γ_C: the mesh's boundary is not needed
        return planes
    tolerance = PLANE * np.ptp(mesh.p, axis=1).max()
    boundary = mesh.p[:, mesh.facets[:, mesh.boundary_facets()]]  # (d, vertices, facets)
    coords = basis.doflocs[:, dofs[:, 0]].T
    for a in np.flatnonzero(candidates.any(axis=0)):
        located = basis.doflocs[a, a::dim]  # component a's DOFs are a, a + d, … (scikit-fem interleaves them)
        for c in np.unique([located.min(), located.max()]):
            on = np.abs(located - c) <= tolerance
            if held[a::dim][on].all() and (np.abs(boundary[a] - c) <= tolerance).all(axis=0).any():
                planes[:, a] |= candidates[:, a] & (np.abs(coords[:, a] - c) <= tolerance)
    return planes


def in_plane(normals: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """The normals with their components along the symmetry planes' normals dropped: the full model's normal at a
    node on its mirror plane (n_i ∝ ∫ψ_i n over both sides, the images' e_a-components cancelling)."""
    kept = np.where(planes, 0.0, normals)
    return kept / np.linalg.norm(kept, axis=1, keepdims=True)


def held_by_symmetry(frame: list[np.ndarray], planes: np.ndarray) -> np.ndarray:
    """Mask of T's rows (component-major) along a symmetry plane's normal: with the normal in the plane, one frame
    vector of a node on it is ±e_a (:func:`tangent_frame` keeps exact zeros), both on two planes (3-D) and the only
    one in 2-D."""
    return np.concatenate([(planes & (np.abs(t) > TILT)).any(axis=1) for t in frame])


def emptied(rows: sp.csr_matrix, held: np.ndarray) -> sp.csr_matrix:
    """``rows`` with the ``held`` ones exactly empty (no stored zeros: :func:`~convexcontact.formulations.primal.carrying`
    reads an empty row's multiplier as 0)."""
    if not held.any():
        return rows
    kept = sp.csr_matrix(sp.diags((~held).astype(float)) @ rows)
    kept.eliminate_zeros()
    return kept


@dataclass
class _Nodes:
    """The nodes of a set of facets of Γ_C: DOFs, scaled coordinates, normals, boundary mass, weights."""

    dofs: np.ndarray
    coords: np.ndarray
    normals: np.ndarray
    mass: sp.csr_matrix
    weights: np.ndarray
    transform: sp.csr_matrix | None = None


def _nodes(facets: np.ndarray, mesh: fe.Mesh, basis: fe.Basis, boundary: str) -> _Nodes:
    dim = mesh.dim()
    view = basis.get_dofs(facets)
    dofs = np.column_stack([view.all(f"u^{i + 1}") for i in range(dim)])
    if dofs.shape[0] == 0:
        raise SceneError("contact.boundary", f"{boundary!r} carries no nodes")
    # integrals over Γ_C of the scalar element: scikit-fem's vector DOF d·s + a carries component a of
    # scalar DOF s, and the scalar basis holds a quarter (2-D) of the vector one's pairs of shape functions
    scalar = fe.FacetBasis(mesh, basis.elem.elem, facets=facets, disable_doflocs=True)
    nodes = dofs[:, 0] // dim
    mass = fe.asm(fe.BilinearForm(lambda u, v, w: u * v), scalar).tocsr()[nodes][:, nodes]
    # weak rows on P2 triangles test with ψ̃ = T ψ (multiplier_transform): their masses, weights and normals
    transform = multiplier_transform(mesh, nodes) if isinstance(basis.elem.elem, fe.ElementTetP2) else None
    if transform is not None:
        mass = sp.csr_matrix(transform @ mass)
    # n_i ∝ ∫ ψ_i n ds: the outward normal averaged with the shape function's weight,
    # well defined for any Lagrange element and for curved facets
    weighted_normal = np.column_stack([fe.asm(fe.LinearForm(lambda v, w, a=a: w.n[a] * v), scalar)[nodes]
                                       for a in range(dim)])
    if transform is not None:
        weighted_normal = transform @ weighted_normal
    normals = weighted_normal / np.linalg.norm(weighted_normal, axis=1, keepdims=True)
    # the quadrature leaves round-off (~1e-17) in components that are zero on a plane face; through the
    # tangents it would couple a roller's eliminated direction to its friction multiplier (an empty row of
    # T becoming 1e-53: a rank-deficient instead of an empty column of the dual's W)
    normals[np.abs(normals) < ROUNDOFF] = 0.0
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    weights = np.asarray(mass.sum(axis=1)).ravel()  # partition of unity: Σ_j ∫ψ_iψ_j = ∫ψ_i
    return _Nodes(dofs, basis.doflocs[:, dofs[:, 0]].T, normals, mass, weights, transform)


TRANSFORM = 0.2
"""α of the P2 triangles' transformed multiplier basis (:func:`multiplier_transform`)."""


def multiplier_transform(mesh: fe.Mesh, nodes: np.ndarray) -> sp.csr_matrix:
    """T with ψ̃ = T ψ for the P2 trace on the triangles of a tetrahedral Γ_C (``nodes``: scalar DOFs, vertices
    first, then edges, scikit-fem's order): ψ̃_v = ψ_v + α Σ_{edges e ∋ v} ψ_e, ψ̃_e = (1 − 2α) ψ_e, α = TRANSFORM.
    A P2 triangle's vertex functions integrate to zero, so weak rows ∫ψ_v (u_N − g) ≤ 0 test with a sign-changing
    weight and the multipliers oscillate between vertices and edges; ψ̃ keeps the partition of unity and gives every
    function a positive mean (2|E|/15 per facet at a vertex, |E|/5 at an edge: the transformed quadratic basis of
    Wohlmuth's and Popp's quadratic mortar methods)."""
    nverts = mesh.nvertices  # not p's columns: a quadratic mesh's (MeshTet2) hold its edge nodes too
    local = np.full(nverts + mesh.edges.shape[1], -1)
    local[nodes] = np.arange(nodes.size)
    edge = np.flatnonzero(nodes >= nverts)
    ends = local[mesh.edges[:, nodes[edge] - nverts]]  # (2, edges): both on Γ_C
    rows = np.concatenate([np.arange(nodes.size), ends[0], ends[1]])
    columns = np.concatenate([np.arange(nodes.size), edge, edge])
    values = np.concatenate([np.where(nodes >= nverts, 1.0 - 2.0 * TRANSFORM, 1.0), np.full(2 * edge.size, TRANSFORM)])
    return sp.csr_matrix((values, (rows, columns)), shape=(nodes.size, nodes.size))


def _mean_frame(nodes: _Nodes) -> tuple[np.ndarray, np.ndarray]:
    """Γ_C's mean normal and mean (first) tangent."""
    mean_normal = nodes.weights @ nodes.normals
    return mean_normal / np.linalg.norm(mean_normal), tangent_frame(nodes.normals, nodes.weights)[2]


def gauss_interpolation(mesh: fe.Mesh, basis: fe.Basis, facets: np.ndarray, dofs: np.ndarray,
                        order: int | None = None):
    """G (points × contact nodes), weights ω_q and coordinates of the Gauss points of ``facets`` (the rule
    integrating degree ``order`` exactly; scikit-fem's default for the element when None)."""
    # scikit-fem locates every DOF of the mesh unless told not to; only the facets' are needed here
    scalar = fe.FacetBasis(mesh, basis.elem.elem, facets=facets, intorder=order, disable_doflocs=True)
    # scalar DOF j carries vector DOFs dj, …, dj + d − 1 (scikit-fem interleaves components; tests/test_stiffness.py)
    m, dim = dofs.shape
    node_of_dof = np.full(scalar.N, -1)
    node_of_dof[dofs[:, 0] // dim] = np.arange(m)
    nfacets, nqp = scalar.dx.shape
    rows = np.arange(nfacets * nqp).reshape(nfacets, nqp)
    entries = [
        (np.asarray(scalar.basis[j][0]).ravel(), rows.ravel(), np.repeat(node_of_dof[scalar.element_dofs[j]], nqp))
        for j in range(scalar.Nbfun)
    ]
    values, i, k = (np.concatenate(parts) for parts in zip(*entries))
    on_facet = k >= 0  # the element's other DOFs vanish on the facet
    assert np.allclose(values[~on_facet], 0.0)
    values, i, k = values[on_facet], i[on_facet], k[on_facet]
    G = sp.csr_matrix((values, (i, k)), shape=(nfacets * nqp, m))  # duplicates are summed
    coords = np.asarray(scalar.global_coordinates()).reshape(dim, -1).T
    return G, scalar.dx.ravel(), coords


def obstacle_gap(obstacle, user_coords: np.ndarray, user_coordinate: np.ndarray, mean_normal: np.ndarray,
                 mean_tangent: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The gap (user units, the indentation included) at points of Γ_C and, with ``normal = "obstacle"``,
    the obstacle's normals there (None: the body's)."""
    offset = axis_offset(obstacle, user_coords, user_coordinate, mean_normal, mean_tangent)
    if obstacle.normal == "obstacle":
        gap, normals = obstacle.closest_point(offset, mean_normal)
    else:
        gap = obstacle.shape_gap(user_coords, axis_distance(offset, mean_tangent)) - (obstacle.depth or 0.0)
        normals = None
    if not np.isfinite(gap).all():  # r²/2R with a radius of 1e-300
        point = np.flatnonzero(~np.isfinite(gap))[0]
        far = np.abs(axis_distance(offset, mean_tangent)).max() > 1e6 * np.ptp(user_coords, axis=0).max()
        raise SceneError(gap_field(obstacle, far), f"the gap at {np.round(user_coords[point], 12).tolist()} on "
                         f"Γ_C is {gap[point]}, beyond the floats",
                         "give a radius, centre, gap and depth on the body's scale")
    return gap, normals


def gap_field(obstacle, far: bool = False) -> str:
    """The obstacle's field that sets its gap: its gap, its formula, or a punch's radius (``far``: its centre, far
    from Γ_C)."""
    return {"flat": "obstacle.gap", "expression": "obstacle.expression"}.get(
        obstacle.shape, "obstacle.center" if far else "obstacle.radius")


def under_punch(contact: Contact, facets: np.ndarray, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling):
    """The facets of Γ_C whose vertices all lie under a flat punch (within round-off of its edge)."""
    mean_normal, mean_tangent = _mean_frame(_nodes(facets, mesh, basis, contact.boundary))
    vertices = mesh.p[:, mesh.facets[:, facets]].T * scaling.length  # (facets, vertices, d)
    flat = vertices.reshape(-1, mesh.dim())
    offset = axis_offset(contact.obstacle, flat, flat @ mean_tangent, mean_normal, mean_tangent)
    r = np.abs(axis_distance(offset, mean_tangent)).reshape(vertices.shape[:2])
    kept = facets[(r <= contact.obstacle.radius * (1.0 + COVERED)).all(axis=1)]
    if kept.size == 0:
        raise SceneError("obstacle.radius", f"no facet of {contact.boundary!r} lies entirely under the flat punch "
                         f"(radius {contact.obstacle.radius})", "use a larger radius or a finer mesh under the punch")
    return kept


def symmetric_obstacle(obstacle, coords: np.ndarray, gap: np.ndarray, planes: np.ndarray, scaling: Scaling,
                       mean_normal: np.ndarray, mean_tangent: np.ndarray) -> np.ndarray:
    """``planes`` (:func:`symmetry_planes`) where they mirror the rigid obstacle too: its gap at the mirror image of
    every node is the node's, and it moves only along the plane (force control along Γ_C's mean normal, no
    tangential force)."""
    kept = np.zeros_like(planes)
    if obstacle.tangential_force is not None:
        return kept
    for a in np.flatnonzero(planes.any(axis=0)):
        if obstacle.force_controlled and abs(mean_normal[a]) > PLANE:
            continue
        for c in np.unique(coords[planes[:, a], a]):  # nodes on one plane share c: symmetry_planes reads the mesh's
            image = coords.copy()
            image[:, a] = 2.0 * c - coords[:, a]
            mirrored, _ = obstacle_gap(obstacle, image * scaling.length, image @ mean_tangent * scaling.length,
                                       mean_normal, mean_tangent)
            if np.allclose(mirrored / scaling.displacement, gap, rtol=PLANE, atol=PLANE * np.abs(gap).max()):
                kept[:, a] |= planes[:, a] & (coords[:, a] == c)
    return kept


def contact_trace(
    contact: Contact, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling, free: np.ndarray, prescribed: np.ndarray
) -> ContactTrace:
    """Build the trace of Γ_C from the named boundary and the obstacle."""
    facets = check_boundary(mesh, contact.boundary, "contact.boundary")
    obstacle = contact.obstacle
    if obstacle.shape == "flat_punch":
        facets = under_punch(contact, facets, mesh, basis, scaling)
    nodes = _nodes(facets, mesh, basis, contact.boundary)
    dim = mesh.dim()
    dofs, coords, normals, weights = nodes.dofs, nodes.coords, nodes.normals, nodes.weights
    mean_normal, mean_tangent = _mean_frame(nodes)
    coordinate = coords @ mean_tangent
    gap, obstacle_normals = obstacle_gap(obstacle, coords * scaling.length, coordinate * scaling.length,
                                         mean_normal, mean_tangent)
    gap = gap / scaling.displacement
    normals = normals if obstacle_normals is None else obstacle_normals
    planes = symmetry_planes(mesh, basis, dofs, normals, free, prescribed)
    planes = symmetric_obstacle(contact.obstacle, coords, gap, planes, scaling, mean_normal, mean_tangent)
    normals = in_plane(normals, planes)
    points = None
    if getattr(contact.law, "non_penetration", None) == "gauss":
        if contact.law.order is not None:  # before the rule is built: its size grows with the order
            element = type(basis.elem.elem).__name__.removeprefix("Element")
            check_order(contact.law.order, basis.elem.elem.maxdeg, f"a {dim}-D {element} body")
        G, weights_q, coords_q = gauss_interpolation(mesh, basis, facets, dofs, contact.law.order)
        gap_q, _ = obstacle_gap(obstacle, coords_q * scaling.length, coords_q @ mean_tangent * scaling.length,
                                mean_normal, mean_tangent)
        points = ContactPoints(G, weights_q, coords_q, gap_q / scaling.displacement)
    tangents, bitangents, _ = tangent_frame(normals, weights)
    frame = [tangents] if bitangents is None else [tangents, bitangents]
    N_full = _rows(normals, dofs, basis.N)
    symmetric = held_by_symmetry(frame, planes)
    T_full = emptied(sp.vstack([_rows(t, dofs, basis.N) for t in frame]).tocsr(), symmetric)

    coupling = normals @ mean_normal if obstacle.force_controlled else None
    tangential = None
    if obstacle.tangential_force is not None:
        if dim == 3:
            raise SceneError("obstacle.tangential_force", "a tangential obstacle force is 2-D only",
                             "drop it (a 3-D tangential force needs a 2-vector of obstacle shifts, not implemented)")
        tangential = tangents @ mean_tangent

    return ContactTrace(
        facets=facets,
        dofs=dofs,
        coords=coords,
        normals=normals,
        tangents=tangents,
        coordinate=coordinate,
        weights=weights,
        mass=nodes.mass,
        multiplier_transform=nodes.transform,
        N=N_full[:, free],
        T=T_full[:, free],
        normal_offset=N_full @ prescribed,
        tangent_offset=T_full @ prescribed,
        gap=gap,
        obstacle_coupling=coupling,
        obstacle_force=(obstacle.force or 0.0) / scaling.force,
        tangential_coupling=tangential,
        obstacle_tangential_force=(obstacle.tangential_force or 0.0) / scaling.force,
        bitangents=bitangents,
        points=points,
        symmetric=symmetric,
    )
