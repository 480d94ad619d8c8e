"""The 3-D mortar integrals of a pair: flat facets, triangles (P1 and P2 tetrahedra) or parallelograms (Q1 and
Q2 hexahedra).

Each master facet facing a slave facet is projected on the slave's plane along its normal and clipped by it
(Sutherland–Hodgman, vectorized over all facet pairs at once: a quadrilateral clipped by four half-planes
has at most eight vertices); the intersection is cut into a fan of triangles and integrated with a degree-4
rule (exact for the product of two bilinear functions on parallelograms), or of degree 8 on Q2 faces (two
biquadratic functions, the master's affine in the slave's coordinates on parallelograms). The dual basis of a slave facet
makes D diagonal as in 2-D (see :mod:`.mortar`): φ*_a = 4λ_a − 1 on a triangle, the tensor product of the
1-D duals 2 − 3t and 3t − 1 on a parallelogram (∫φ*_a ψ_b = δ_ab ∫ψ_b on both), on a Q2 face (9 nodes) the
tensor product of the quadratic 1-D duals (:func:`dual_coefficients`: its ∫ψ_a are all positive). A P2 triangle's vertex functions
integrate to zero, so no such dual exists for ψ: on P2 facets the slave's basis is the transformed ψ̃ = T ψ of
:func:`~convexcontact.fem.contact.multiplier_transform` (every ∫ψ̃_a > 0), and φ* is biorthogonal to ψ̃, φ* = A ψ̃
with A = D̃ M̃⁻¹ on each facet (Popp, Gitterle, Gee & Wall 2010, dual quadratic mortar in 3-D); the master keeps ψ.

The clipping is by hand: scikit-fem's ``skfem.supermeshing.intersect`` of two triangle meshes (shapely, not a
dependency) loops in Python over the pairs: 97 s for the intersections alone at 10⁴ slave facets, where this
module clips and integrates them in 7.8 s (docs/bodies.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfem as fe
from scipy.spatial import cKDTree

from ..scene.description import SceneError
from .contact import TRANSFORM

FACING = 1e-3
"""A master facet faces a slave facet when their normals make more than 90° + 0.06° (a facet seen edge-on
has no projection to integrate on)."""


@dataclass
class Facets:
    """Flat boundary facets (triangles or parallelograms), their vertices in cyclic order so that
    (B − A) × (C − A) is the outward normal; ``frame`` (facets, 2, 3) are two unit tangents of each facet's
    plane, the first along A→B."""

    nodes: np.ndarray  # (facets, corners[ + edges (+ 1)]) the basis's nodes: the vertices, then (P2, Q2) the
    # edges AB, BC, …, then (Q2) the face's centre
    points: np.ndarray  # (facets, corners, 3) the vertices
    measure: np.ndarray  # areas
    size: np.ndarray  # longest edges
    normal: np.ndarray
    frame: np.ndarray

    @property
    def shares(self) -> np.ndarray:
        """∫ψ_a / |e| of each node: a third (triangle), a quarter (parallelogram); on P2 triangles ∫ψ̃_a / |e|,
        2/15 at a vertex and 1/5 at an edge; on Q2 faces 1/36 at a corner, 1/9 at an edge, 4/9 at the centre."""
        if self.transformed:
            return np.repeat([2.0 * TRANSFORM / 3.0, (1.0 - 2.0 * TRANSFORM) / 3.0], 3)
        if self.quadratic:
            shares = dual_coefficients(2)[1]
            return np.array([shares[i] * shares[j] for i, j in TENSOR])
        return np.full(self.nodes.shape[1], 1.0 / self.nodes.shape[1])

    @property
    def quadratic(self) -> bool:
        return self.nodes.shape[1] > self.points.shape[1]

    @property
    def transformed(self) -> bool:
        """P2 triangles: the multipliers are dual to ψ̃ = T ψ, not ψ (:func:`transformed_dual`)."""
        return self.quadratic and self.points.shape[1] == 3


def facets_3d(mesh: fe.Mesh, facets: np.ndarray, field_name: str, basis: fe.Basis | None = None) -> Facets:
    """The ``facets`` of a tetrahedral or hexahedral mesh, numbered outwards; warped or non-parallelogram
    quadrilaterals are refused (their bilinear map and dual basis are not built). With a P2 or Q2 ``basis`` each
    facet also holds its edges' nodes, and on Q2 its own (centre) node (a node is a DOF's index over 3)."""
    nodes = mesh.facets[:, facets].T.copy()  # scikit-fem keeps a quadrilateral's vertices in cyclic order
    centroid = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1).T
    points = mesh.p[:, nodes].transpose(1, 2, 0)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    inward = ((centroid - points[:, 0]) * turned).sum(axis=1) > 0
    nodes[inward] = nodes[inward][:, [0, *range(nodes.shape[1] - 1, 0, -1)]]
    points = mesh.p[:, nodes].transpose(1, 2, 0)
    edges = np.linalg.norm(points - np.roll(points, 1, axis=1), axis=2).max(axis=1)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, -1] - points[:, 0])
    if nodes.shape[1] == 4:
        skew = np.linalg.norm(points[:, 0] + points[:, 2] - points[:, 1] - points[:, 3], axis=1)
        if (skew > 1e-8 * edges).any():
            raise SceneError(field_name, f"{np.count_nonzero(skew > 1e-8 * edges)} quadrilateral facets are not "
                             "parallelograms (warped or tapered hexahedra)", "use P1 tetrahedra for this body, "
                             "or hexahedra whose contact faces are parallelograms (a Box, graded or not)")
    doubled = np.linalg.norm(turned, axis=1)
    normal = turned / doubled[:, None]
    first = points[:, 1] - points[:, 0]
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    measure = doubled / 2 if nodes.shape[1] == 3 else doubled
    if basis is not None and basis.elem.elem.edge_dofs > 0:
        nodes = np.column_stack([nodes, edge_nodes(mesh, nodes)])
    if basis is not None and basis.elem.elem.facet_dofs > 0:
        nodes = np.column_stack([nodes, basis.facet_dofs[0, facets] // mesh.dim()])
    return Facets(nodes, points, measure, edges, normal, np.stack([first, np.cross(normal, first)], axis=1))


def edge_nodes(mesh: fe.Mesh, corners: np.ndarray) -> np.ndarray:
    """The P2/Q2 nodes of the edges AB, BC, … of facets with ``corners`` A, B, … in cyclic order: the mesh's vertex
    count + the edge's index (scikit-fem numbers a P2 or Q2 basis's edge DOFs after the vertices'). The bodies of a pair are joined as
    straight-sided meshes (``scene.bodies.straight_sided``), so these nodes are the edges' midpoints."""
    ends = np.sort(np.stack([corners, np.roll(corners, -1, axis=1)], axis=-1), axis=-1).reshape(-1, 2)
    n = mesh.nvertices
    known = np.sort(mesh.edges, axis=0)
    codes = known[0] * n + known[1]
    order = np.argsort(codes)
    return (n + order[np.searchsorted(codes[order], ends[:, 0] * n + ends[:, 1])]).reshape(corners.shape)


def plane_axes(normal: np.ndarray) -> np.ndarray:
    """Two unit tangents (2, 3) of the plane normal to ``normal``."""
    axis = np.eye(3)[np.argmin(np.abs(normal))]
    first = axis - (axis @ normal) * normal
    first /= np.linalg.norm(first)
    return np.array([first, np.cross(normal, first)])


def across(points: np.ndarray, normals: np.ndarray, master_points: np.ndarray, mean_normal: np.ndarray) -> np.ndarray:
    """How far, seen along Γ_C's mean normal N, the projection of each slave facet (or node: ``points`` (n, corners,
    d)) along its own normal ``normals`` can land from it on the master: a point x + d n_e lies |d| |n_e − (n_e·N) N|
    aside, and |d| is at most |Δν| / (n_e·N), Δν the difference of the two points' heights along N (bounded by the
    facet's and the master's ranges), and at most the diameter of both boundaries. Zero where n_e = N; across a wide
    gap with tilted normals (a curved Γ_C's open ends) it is larger than any facet."""
    heights, master_heights = points @ mean_normal, master_points @ mean_normal
    depth = np.maximum(master_heights.max() - heights.min(axis=1), heights.max(axis=1) - master_heights.min())
    both = np.concatenate([points.reshape(-1, points.shape[-1]), master_points.reshape(-1, points.shape[-1])])
    diameter = np.linalg.norm(both.max(axis=0) - both.min(axis=0))
    along = normals @ mean_normal
    aside = np.linalg.norm(normals - np.outer(along, mean_normal), axis=1)
    distance = np.full(along.shape, diameter)
    np.divide(depth, along, out=distance, where=along * diameter > depth)  # |d| ≤ depth / (n_e·N) where that is less
    return aside * distance


def candidates(slave: Facets, master: Facets, mean_normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Facet pairs whose centroids, seen along Γ_C's mean normal, lie closer than the slave facet's radius, the
    largest master radius and how far the slave facet's normal carries it across the gap (:func:`across`; a
    KD-tree), kept where the master facet's centroid, projected on the slave's plane, lies within both facets' radii
    (the projection only shortens; the windows are wide where the normals tilt). The slave's own radius, not the
    largest, as the 2-D search (:func:`~.mortar.transfer_matrix`) takes its own size: graded meshes' largest facets
    lie far from the contact."""
    centre = [facets.points.mean(axis=1) for facets in (slave, master)]
    radius = [np.linalg.norm(facets.points - c[:, None], axis=2).max(axis=1) for facets, c in zip((slave, master), centre)]
    axes = plane_axes(mean_normal)
    trees = [cKDTree(c @ axes.T) for c in centre]
    reach = radius[0] + radius[1].max() + across(slave.points, slave.normal, master.points, mean_normal)
    found = trees[1].query_ball_point(trees[0].data, reach)
    e, f = np.repeat(np.arange(len(found)), [len(j) for j in found]), np.concatenate([*found, []]).astype(int)
    offset = centre[1][f] - centre[0][e]
    aside = offset - (offset * slave.normal[e]).sum(axis=1)[:, None] * slave.normal[e]
    near = np.linalg.norm(aside, axis=1) <= (radius[0][e] + radius[1][f]) * (1 + 1e-9)
    return e[near], f[near]


def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def clip(polygon: np.ndarray, count: np.ndarray, start: np.ndarray, end: np.ndarray):
    """Each polygon (counter-clockwise, ``count`` vertices) cut to the left of its line start → end: a vertex
    is kept when inside, followed by the crossing of its outgoing edge when that edge crosses."""
    n, size = polygon.shape[:2]
    index = np.arange(size)
    valid = index < count[:, None]
    following = np.where(index + 1 < count[:, None], index + 1, 0)
    nxt = np.take_along_axis(polygon, following[..., None], axis=1)
    edge = (end - start)[:, None]
    here, there = cross2(edge, polygon - start[:, None]), cross2(edge, nxt - start[:, None])
    keep = valid & (here >= 0)
    crossing = valid & ((here >= 0) != (there >= 0))
    fraction = np.where(crossing, here / np.where(crossing, here - there, 1.0), 0.0)
    outputs = keep.astype(int) + crossing
    position = np.cumsum(outputs, axis=1) - outputs
    out = np.zeros((n, size + 1, 2))
    rows = np.broadcast_to(np.arange(n)[:, None], (n, size))
    out[rows[keep], position[keep]] = polygon[keep]
    out[rows[crossing], (position + keep)[crossing]] = (polygon + fraction[..., None] * (nxt - polygon))[crossing]
    return out, outputs.sum(axis=1)


DUNAVANT = (np.array([[0.445948490915965, 0.445948490915965, 0.108103018168070],
                      [0.445948490915965, 0.108103018168070, 0.445948490915965],
                      [0.108103018168070, 0.445948490915965, 0.445948490915965],
                      [0.091576213509771, 0.091576213509771, 0.816847572980459],
                      [0.091576213509771, 0.816847572980459, 0.091576213509771],
                      [0.816847572980459, 0.091576213509771, 0.091576213509771]]),
            np.array([0.223381589678011] * 3 + [0.109951743655322] * 3))
"""Points (barycentric) and weights (fractions of the area) of Dunavant's degree-4 rule on a triangle."""


def lagrange(degree: int, t: np.ndarray) -> np.ndarray:
    """The Lagrange shape functions of a straight facet of ``degree`` 1 or 2 at ``t`` ∈ [0, 1] (start → end),
    stacked last in the order of :attr:`.mortar.Segments.nodes`: start, end[, middle]."""
    if degree == 1:
        return np.stack([1 - t, t], axis=-1)
    return np.stack([(1 - t) * (1 - 2 * t), t * (2 * t - 1), 4 * t * (1 - t)], axis=-1)


def gauss(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points on [0, 1] and weights summing to 1 (exact for degree 2·points − 1)."""
    t, w = np.polynomial.legendre.leggauss(points)
    return (t + 1) / 2, w / 2


def dual_coefficients(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """A = D M⁻¹ of the reference facet (φ*_a = Σ_b A_ab ψ_b, so that ∫φ*_a ψ_b = δ_ab ∫ψ_b) and the
    fractions ∫ψ_a / |e| (D's diagonal): [[2, −1], [−1, 2]] and ½, ½ for degree 1; 1/6, 1/6, 2/3 for 2."""
    t, w = gauss(degree + 1)
    psi = lagrange(degree, t)
    mass = psi.T @ (w[:, None] * psi)
    shares = mass.sum(axis=1)
    return shares[:, None] * np.linalg.inv(mass), shares


def collapsed(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre squared and collapsed onto a triangle (Duffy: L₁ = u, L₂ = (1 − u) v, Jacobian 1 − u), as
    barycentric points and fractions of the area: exact to degree 2·points − 2."""
    t, w = gauss(points)
    u, v = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    L = np.column_stack([(1 - u) * (1 - v), u, (1 - u) * v])
    return L, 2 * np.outer(w, w).ravel() * (1 - u)


DEGREE_8 = collapsed(5)
"""The rule of Q2 faces: 25 points, exact for the degree-8 product of two biquadratic functions."""

TENSOR = ((0, 0), (1, 0), (1, 1), (0, 1), (2, 0), (1, 2), (2, 1), (0, 2), (2, 2))
"""A parallelogram's nodes as pairs of 1-D nodes (0: start, 1: end, 2: middle; along A→B, then A→D): the corners
A, B, C, D, then (Q2) the edges' middles AB, BC, CD, DA, then the centre."""


def quadratic_shapes(L: np.ndarray) -> np.ndarray:
    """P2 shape functions (..., 6) of barycentric coordinates L (..., 3): the vertices, then the edges AB, BC, CA."""
    return np.concatenate([L * (2 * L - 1), 4 * L * np.roll(L, -1, axis=-1)], axis=-1)


def transformed_dual() -> tuple[np.ndarray, np.ndarray]:
    """T and A of a P2 triangle: ψ̃ = T ψ (:func:`~convexcontact.fem.contact.multiplier_transform` on one facet) and
    the dual basis φ* = A ψ̃, A = D̃ M̃⁻¹ with M̃ = ∫ψ̃ψ̃ᵀ and D̃ = diag(∫ψ̃) (Dunavant's rule: exact for M̃)."""
    T = np.diag(np.repeat([1.0, 1.0 - 2.0 * TRANSFORM], 3))
    for vertex, edges in enumerate(((3, 5), (3, 4), (4, 5))):
        T[vertex, list(edges)] = TRANSFORM
    points, fractions = DUNAVANT
    psi = quadratic_shapes(points) @ T.T
    mass = psi.T @ (fractions[:, None] * psi)
    return T, np.diag(mass.sum(axis=1)) @ np.linalg.inv(mass)


TRANSFORMED, DUAL_P2 = transformed_dual()


def shapes(polygon: np.ndarray, points: np.ndarray, quadratic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(shape functions, dual basis) (n, q, nodes) at ``points`` (n, q, 2) of the 2-D triangle or parallelogram
    ``polygon`` (n, corners, 2); ``quadratic``: P2 on the triangle, the dual that of ψ̃ (:func:`transformed_dual`),
    Q2 on the parallelogram (the nodes of :data:`TENSOR`)."""
    origin, first, last = polygon[:, 0][:, None], polygon[:, 1][:, None], polygon[:, -1][:, None]
    area = cross2(first - origin, last - origin)
    xi = cross2(points - origin, last - origin) / area
    eta = cross2(first - origin, points - origin) / area
    if polygon.shape[1] == 3:
        shape = np.stack([1 - xi - eta, xi, eta], axis=-1)
        if quadratic:
            psi = quadratic_shapes(shape)
            return psi, psi @ (DUAL_P2 @ TRANSFORMED).T
        return shape, 4 * shape - 1
    degree = 2 if quadratic else 1
    coefficients = dual_coefficients(degree)[0]
    one, two = ((psi, psi @ coefficients.T) for psi in (lagrange(degree, xi), lagrange(degree, eta)))
    nodes = TENSOR[:(degree + 1) ** 2]
    return tuple(np.stack([one[k][..., i] * two[k][..., j] for i, j in nodes], axis=-1) for k in (0, 1))


def mortar_3d(slave: Facets, master: Facets, mean_normal: np.ndarray):
    """Entries (slave facet, its node a, master facet, its node b, ∫φ*_a ψ_b) and each slave facet's covered
    fraction, as :func:`convexcontact.fem.mortar.mortar` in 2-D."""
    e, f = candidates(slave, master, mean_normal)
    facing = (slave.normal[e] * master.normal[f]).sum(axis=1) < -FACING
    e, f = e[facing], f[facing]
    origin, frame = slave.points[e, 0], slave.frame[e]  # (n, 3), (n, 2, 3)
    flat = np.einsum("nkc,njc->nkj", slave.points[e] - origin[:, None], frame)  # slave vertices in its plane
    projected = np.einsum("nkc,njc->nkj", master.points[f] - origin[:, None], frame)
    corners = slave.points.shape[1]
    polygon, count = projected[:, ::-1], np.full(len(e), master.points.shape[1])  # the master runs clockwise here
    for k in range(corners):
        polygon, count = clip(polygon, count, flat[:, k], flat[:, (k + 1) % corners])
    overlap = count >= 3
    e, f, flat, projected, polygon, count = (a[overlap] for a in (e, f, flat, projected, polygon, count))
    # fan triangles (0, k, k + 1) of each intersection, Dunavant's points in each
    fan = np.arange(1, polygon.shape[1] - 1)
    vertices = np.stack([np.broadcast_to(polygon[:, :1], (len(e), fan.size, 2)), polygon[:, fan], polygon[:, fan + 1]],
                        axis=2)  # (n, fan, 3, 2)
    area = np.where(fan + 1 < count[:, None], cross2(vertices[:, :, 1] - vertices[:, :, 0],
                                                     vertices[:, :, 2] - vertices[:, :, 0]) / 2, 0.0)
    points, fractions = DEGREE_8 if slave.quadratic and corners == 4 else DUNAVANT
    at = np.einsum("qk,nfkc->nfqc", points, vertices).reshape(len(e), fan.size * len(fractions), 2)
    weight = (area[:, :, None] * fractions).reshape(len(e), fan.size * len(fractions))  # sizes given: e may be empty
    dual = shapes(flat, at, slave.quadratic)[1]
    shape = shapes(projected, at, master.quadratic)[0]
    values = np.einsum("nq,nqa,nqb->abn", weight, dual, shape, optimize=True)
    a, b, n = np.indices(values.shape).reshape(3, -1)
    covered = np.bincount(e, weights=area.sum(axis=1), minlength=slave.measure.size) / slave.measure
    return [e[n], a, f[n], b, values.ravel()], covered
