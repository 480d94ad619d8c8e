"""The 3-D mortar integrals of a pair: flat triangular facets (P1 tetrahedra).

Each master triangle facing a slave triangle is projected on the slave's plane along its normal and
clipped by it (Sutherland–Hodgman, vectorized over all facet pairs at once: a triangle clipped by three
half-planes has at most six vertices); the intersection is cut into a fan of triangles, integrated with
the edge-midpoint rule (exact for the quadratic integrand). The dual basis of a slave triangle is
φ*_a = 4λ_a − 1: ∫φ*_a λ_b = δ_ab ∫λ_b, so D is diagonal as in 2-D (see :mod:`.mortar`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfem as fe
from scipy.spatial import cKDTree

FACING = 1e-3
"""A master facet faces a slave facet when their normals make more than 90° + 0.06° (a facet seen edge-on
has no projection to integrate on)."""


@dataclass
class Triangles:
    """Flat boundary facets, numbered so that (B − A) × (C − A) is the outward normal; ``frame`` (facets, 2, 3)
    are two unit tangents of each facet's plane, the first along A→B."""

    nodes: np.ndarray  # (facets, 3) vertex indices
    points: np.ndarray  # (facets, 3, 3): vertex × coordinate
    measure: np.ndarray  # areas
    size: np.ndarray  # longest edges
    normal: np.ndarray
    frame: np.ndarray


def triangles(mesh: fe.Mesh, facets: np.ndarray) -> Triangles:
    """The ``facets`` of a tetrahedral mesh as outward-numbered triangles."""
    nodes = mesh.facets[:, facets].T.copy()
    centroid = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1).T
    points = mesh.p[:, nodes].transpose(1, 2, 0)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    inward = ((centroid - points[:, 0]) * turned).sum(axis=1) > 0
    nodes[inward] = nodes[inward][:, [0, 2, 1]]
    points = mesh.p[:, nodes].transpose(1, 2, 0)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    twice = np.linalg.norm(turned, axis=1)
    normal = turned / twice[:, None]
    first = points[:, 1] - points[:, 0]
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    edges = np.linalg.norm(points - np.roll(points, 1, axis=1), axis=2)
    return Triangles(nodes, points, twice / 2, edges.max(axis=1), normal,
                     np.stack([first, np.cross(normal, first)], axis=1))


def plane_axes(normal: np.ndarray) -> np.ndarray:
    """Two unit tangents (2, 3) of the plane normal to ``normal``."""
    axis = np.eye(3)[np.argmin(np.abs(normal))]
    first = axis - (axis @ normal) * normal
    first /= np.linalg.norm(first)
    return np.array([first, np.cross(normal, first)])


def candidates(slave: Triangles, master: Triangles, mean_normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Facet pairs whose centroids, seen along Γ_C's mean normal, lie closer than their sizes (a KD-tree)."""
    axes = plane_axes(mean_normal)
    trees = [cKDTree(facets.points.mean(axis=1) @ axes.T) for facets in (slave, master)]
    reach = (slave.size.max() + master.size.max()) / np.sqrt(3)  # a vertex lies within edge/√3 of the centroid
    pairs = trees[0].sparse_distance_matrix(trees[1], reach, output_type="ndarray")
    return pairs["i"].astype(int), pairs["j"].astype(int)


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


def barycentric(triangle: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, q, 3) of ``points`` (n, q, 2) in the 2-D ``triangle`` (n, 3, 2)."""
    origin, first, second = (triangle[:, k][:, None] for k in range(3))
    area = cross2(first - origin, second - origin)
    along_first = cross2(points - origin, second - origin) / area
    along_second = cross2(first - origin, points - origin) / area
    return np.stack([1 - along_first - along_second, along_first, along_second], axis=-1)


def mortar_3d(slave: Triangles, master: Triangles, mean_normal: np.ndarray):
    """Entries (slave facet, its node a, master facet, its node b, ∫φ*_a λ_b) and each slave facet's covered
    fraction, as :func:`convexcontact.fem.mortar.mortar` in 2-D."""
    e, f = candidates(slave, master, mean_normal)
    facing = (slave.normal[e] * master.normal[f]).sum(axis=1) < -FACING
    e, f = e[facing], f[facing]
    origin, frame = slave.points[e, 0], slave.frame[e]  # (n, 3), (n, 2, 3)
    flat = np.einsum("nkc,njc->nkj", slave.points[e] - origin[:, None], frame)  # slave vertices in its plane
    projected = np.einsum("nkc,njc->nkj", master.points[f] - origin[:, None], frame)
    polygon, count = projected[:, ::-1], np.full(len(e), 3)  # the master runs clockwise seen from the slave
    for k in range(3):
        polygon, count = clip(polygon, count, flat[:, k], flat[:, (k + 1) % 3])
    overlap = count >= 3
    e, f, flat, projected, polygon, count = (a[overlap] for a in (e, f, flat, projected, polygon, count))
    # fan triangles (0, k, k + 1) of each intersection, their edge midpoints
    fan = np.arange(1, polygon.shape[1] - 1)
    corners = [np.broadcast_to(polygon[:, :1], (len(e), fan.size, 2)), polygon[:, fan], polygon[:, fan + 1]]
    area = np.where(fan + 1 < count[:, None], cross2(corners[1] - corners[0], corners[2] - corners[0]) / 2, 0.0)
    midpoints = np.concatenate([(corners[i] + corners[(i + 1) % 3]) / 2 for i in range(3)], axis=1)
    weight = np.tile(area / 3, 3)  # (n, 3·fan)
    dual = 4 * barycentric(flat, midpoints) - 1
    shape = barycentric(projected, midpoints)
    entries = [(e, np.full_like(e, a), f, np.full_like(f, b), (weight * dual[..., a] * shape[..., b]).sum(axis=1))
               for a in range(3) for b in range(3)]
    covered = np.bincount(e, weights=area.sum(axis=1), minlength=slave.measure.size) / slave.measure
    return [np.concatenate(parts) for parts in zip(*entries)], covered
