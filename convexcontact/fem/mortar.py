"""The contact trace of a pair of bodies: mortar (segment-to-segment; 3-D in :mod:`.mortar3d`) or node-to-segment.

Slave node i (non-mortar side, which carries the multipliers), its averaged outward normal n_i and
tangent t_i; master nodes k:

    u_N,i = n_i·(u_i − Σ_k Π_ik u_k),   u_T,i = t_i·(u_i − Σ_k Π_ik u_k),   g_i = n_i·(Σ_k Π_ik x_k − x_i).

- ``mortar``: Π = D⁻¹M with the dual (biorthogonal) multiplier basis of the slave facets, φ*_a = Σ_b A_ab ψ_b
  with A = D_e M_e⁻¹ on each facet (P1/Q1, a facet A→B: φ*_A = 2ψ_A − ψ_B; P2/Q2 in 2-D: the three nodes of a
  straight quadratic facet, whose ∫ψ = h/6, h/6, 2h/3 are positive): D_ij = ∫φ*_i ψ_j = δ_ij w_i with
  w_i = ∫ψ_i, and M_ik = ∫φ*_i (φ_k∘π) over the intersections of each slave facet with the master facets
  projected on it along its normal (Gauss with p + 1 points per intersection: the integrand has degree 2p
  for elements of degree p). C(u_N − g) ≤ 0 with
  C = diag(w) is then ∫φ*_i ([u]·n_i − g) ds ≤ 0, a weak non-penetration; the slave nodes get
  the forces w_i λ_i n_i, the master nodes −Σ_i M_ik λ_i n_i. As Σ_k M_ik = w_i the resultants
  balance, and a linear field is reproduced exactly: the contact patch test passes.
- ``node_to_segment``: Π_ik = φ_k(π(x_i)), x_i projected on the master along n_i.

Slave nodes whose facets are not all covered by the master are left out (with a warning). In 3-D
(P1/P2 tetrahedra, Q1/Q2 hexahedra with parallelogram faces) the multipliers are the dual basis of the slave facets
(:mod:`.mortar3d`), t_i and the second tangent b_i = n_i × t_i as
:func:`~convexcontact.fem.contact.tangent_frame` chooses them.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe

from ..scene.bodies import Pair, Pairs
from ..scene.description import Contact, SceneError
from ..scene.meshing import check_boundary
from .contact import (
    ContactTrace,
    contact_trace,
    emptied,
    held_by_symmetry,
    in_plane,
    multiplier_transform,
    symmetry_planes,
    tangent_frame,
)
from .mortar3d import Facets, across, dual_coefficients, facets_3d, gauss, lagrange, mortar_3d
from .scaling import Scaling

COVERED = 1e-9
"""Relative round-off by which the master's projections may fall short of (or exceed) a slave facet."""


def quadratic(basis: fe.Basis) -> bool:
    """Whether the basis has nodes besides the vertices on the facets (P2, Q2), a mesh's vertices or not (a
    quadratic mesh's ``p`` holds its edge nodes too)."""
    element = basis.elem.elem
    return element.facet_dofs + getattr(element, "edge_dofs", 0) > 0


@dataclass
class PairTrace(ContactTrace):
    """A trace whose rows couple the slave nodes ``dofs`` to the master nodes ``master_dofs`` through
    ``transfer`` Π (m × master nodes); ``N_full`` and ``T_full`` are N and T on every DOF. Several pairs
    stack their rows: ``pieces`` holds each pair's (rows, slave DOFs, master DOFs)."""

    master_dofs: np.ndarray | None = None
    master_coords: np.ndarray | None = None
    transfer: sp.csr_matrix | None = None
    N_full: sp.csr_matrix | None = None
    T_full: sp.csr_matrix | None = None
    warnings: tuple[str, ...] = ()
    pieces: tuple = ()

    def forces(self, normal: np.ndarray, tangential: np.ndarray | None = None, rows=slice(None)) -> np.ndarray:
        """Contact forces on the bodies at every DOF, from the weighted multipliers Cλ_N and w·λ_T (of ``rows``;
        λ_T component-major, as T)."""
        force = -(self.N_full[rows].T @ normal[rows])
        if tangential is None:
            return force
        picked = np.arange(self.m)[rows]
        tangent_rows = np.concatenate([picked + component * self.m for component in range(self.dim - 1)])
        return force + self.T_full[tangent_rows].T @ tangential[tangent_rows]

    def imbalance(self, normal: np.ndarray, tangential: np.ndarray | None = None) -> float:
        """The largest ‖R_slave + R_master‖ of a pair of bodies, relative to ‖R_slave‖ (at least the force of a unit
        pressure)."""
        worst = 0.0
        for rows, slave, master in self.pieces:
            if not master.size:  # a rigid obstacle: its reaction goes to no body
                continue
            force = self.forces(normal, tangential, rows)
            resultants = force[slave].sum(axis=0), force[master].sum(axis=0)
            scale = max(np.linalg.norm(resultants[0]), self.weights[rows].sum())
            worst = max(worst, np.linalg.norm(resultants[0] + resultants[1]) / scale)
        return worst


def stack(traces: list[PairTrace]) -> PairTrace:
    """One trace of several pairs: their rows one after the other."""
    def joined(name):
        return np.concatenate([getattr(trace, name) for trace in traces])

    def by_component(name, join):  # T's rows are component-major: every node's first tangent, then the second
        return join([getattr(t, name)[c * t.m:(c + 1) * t.m] for c in range(traces[0].dim - 1) for t in traces])

    starts = np.cumsum([0] + [trace.m for trace in traces])
    arrays = ("facets", "dofs", "coords", "normals", "tangents", "coordinate", "weights", "normal_offset", "gap",
              "master_dofs", "master_coords")
    return PairTrace(
        **{name: joined(name) for name in arrays}, obstacle_coupling=None, obstacle_force=0.0,
        bitangents=None if traces[0].bitangents is None else joined("bitangents"),
        tangent_offset=by_component("tangent_offset", np.concatenate), symmetric=by_component("symmetric", np.concatenate),
        **{name: sp.block_diag([getattr(t, name) for t in traces], format="csr") for name in ("mass", "transfer")},
        **{name: sp.vstack([getattr(t, name) for t in traces]).tocsr() for name in ("N", "N_full")},
        **{name: by_component(name, lambda blocks: sp.vstack(blocks).tocsr()) for name in ("T", "T_full")},
        warnings=sum((trace.warnings for trace in traces), ()),
        pieces=tuple((slice(start, start + t.m), t.dofs, t.master_dofs) for start, t in zip(starts, traces)),
    )


@dataclass
class Segments:
    """Straight boundary facets, oriented so that the outward normal is the tangent turned clockwise."""

    nodes: np.ndarray  # (facets, 2 or 3) the basis's nodes: start, end[, middle] (P2/Q2)
    start: np.ndarray  # (facets, 2)
    end: np.ndarray
    measure: np.ndarray  # lengths
    tangent: np.ndarray
    normal: np.ndarray

    @property
    def size(self) -> np.ndarray:
        return self.measure

    @property
    def points(self) -> np.ndarray:
        """(facets, 2, 2): start and end."""
        return np.stack([self.start, self.end], axis=1)

    @property
    def degree(self) -> int:
        return self.nodes.shape[1] - 1

    @property
    def shares(self) -> np.ndarray:
        """∫ψ_a / |e| of each node of a facet."""
        return dual_coefficients(self.degree)[1]


CANDIDATES = 1_000_000
"""Candidate pairs of facets (or nodes and facets) clipped at a time (:func:`overlapping`): ~200 MB of arrays."""

STRAIGHT = 1e-9
"""How far (relative to its facet's length) a quadratic facet's middle node may lie from the midpoint."""


def segments(mesh: fe.Mesh, facets: np.ndarray, basis: fe.Basis, field_name: str) -> Segments:
    """The ``facets`` of a 2-D mesh as oriented segments (their cell on the left of start → end). A node is the
    basis's (a DOF's index over d): a vertex, or on P2/Q2 facets the middle node, which must lie at the
    midpoint (a curved quadratic facet is refused: its projection and its Jacobian are not built)."""
    dim = mesh.dim()
    nodes = mesh.facets[:, facets].T.copy()
    centroid = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1).T
    start, end = mesh.p[:, nodes[:, 0]].T, mesh.p[:, nodes[:, 1]].T
    turned = np.column_stack([end[:, 1] - start[:, 1], start[:, 0] - end[:, 0]])
    inward = ((centroid - start) * turned).sum(axis=1) > 0
    nodes[inward] = nodes[inward, ::-1]
    start, end = mesh.p[:, nodes[:, 0]].T, mesh.p[:, nodes[:, 1]].T
    length = np.linalg.norm(end - start, axis=1)
    if quadratic(basis):  # P2/Q2: one node in the middle of each facet
        middle = basis.facet_dofs[0, facets] // dim
        offset = np.linalg.norm(basis.doflocs[:, dim * middle].T - (start + end) / 2, axis=1) / length
        if offset.max() > STRAIGHT:
            raise SceneError(field_name, f"{np.count_nonzero(offset > STRAIGHT)} quadratic facets are curved (a "
                             f"middle node up to {offset.max():.2g} of its facet's length off the midpoint): a "
                             "pair's facets must be straight", "give the body a straight-sided mesh (a linear "
                             "mesh: P2/Q2 add the middle nodes), finer where the boundary curves")
        nodes = np.column_stack([nodes, middle])
    tangent = (end - start) / length[:, None]
    return Segments(nodes, start, end, length, tangent, np.column_stack([tangent[:, 1], -tangent[:, 0]]))


def tangent_of(mean_normal: np.ndarray) -> np.ndarray:
    """Γ_C's mean tangent in 2-D: its mean normal turned clockwise (the facets' own tangent and normal are so)."""
    return np.array([mean_normal[1], -mean_normal[0]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def overlapping(lo_s, hi_s, lo_m, hi_m, margin) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Pairs (slave, master) of intervals along Γ_C's mean tangent that overlap within ``margin`` (one, or one per
    slave), in chunks of at most CANDIDATES candidates: the masters sorted once, each slave's candidates a contiguous
    run found by bisection.

    Chunked because a wide margin takes many pairs: across a curved Γ_C's open ends :func:`across` exceeds any facet
    (the former margin, twice the largest facet, took 3.6·10⁶ of 2272 × 1759 facets at 2.8·10⁵ DOFs, bench two-body,
    and past 13 GB at 1.4·10⁶ DOFs, all at once)."""
    order = np.argsort(lo_m)
    lo_s, hi_s = lo_s - margin, hi_s + margin
    first = np.searchsorted(lo_m[order], lo_s - (hi_m - lo_m).max())
    counts = np.maximum(np.searchsorted(lo_m[order], hi_s, side="right") - first, 0)
    bounds = np.unique(np.r_[0, np.searchsorted(np.cumsum(counts), np.arange(CANDIDATES, counts.sum(), CANDIDATES)),
                             lo_s.size])
    for begin, stop in itertools.pairwise(bounds):
        run = counts[begin:stop]
        slave = np.repeat(np.arange(begin, stop), run)
        master = order[np.repeat(first[begin:stop], run) + np.arange(run.sum()) - np.repeat(np.cumsum(run) - run, run)]
        keep = (hi_m[master] >= lo_s[slave]) & (lo_m[master] <= hi_s[slave])
        yield slave[keep], master[keep]


def clipped(slave: Segments, master: Segments, e: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, ...]:
    """Of candidate pairs (slave facet ``e``, master facet ``f``), those that face each other and overlap along the
    slave's normal: e, f, the overlap [lo, hi] and the master's ends in the slave's coordinate ξ, the slave's length."""
    t, length = slave.tangent[e], slave.measure[e]
    xi_start = ((master.start[f] - slave.start[e]) * t).sum(axis=1) / length
    xi_end = ((master.end[f] - slave.start[e]) * t).sum(axis=1) / length
    lo = np.maximum(np.minimum(xi_start, xi_end), 0.0)
    hi = np.minimum(np.maximum(xi_start, xi_end), 1.0)
    keep = ((slave.normal[e] * master.normal[f]).sum(axis=1) < 0) & (hi > lo + COVERED)
    return tuple(a[keep] for a in (e, f, lo, hi, xi_start, xi_end, length))


def mortar(slave: Segments, master: Segments, mean_normal: np.ndarray, margin: float):
    """Entries (slave facet, its node a, master facet, its node b, ∫φ*_a φ_b) and each slave facet's covered
    fraction: one Gauss rule on every intersection, exact for the product of the slave's dual and the master's
    shape functions (degree 2 for P1/Q1, 4 for P2/Q2). Candidates are searched along Γ_C's mean tangent
    within ``margin`` plus how far each slave facet's normal carries it across the gap (:func:`across`: at a curved
    Γ_C's open ends more than any facet; without it the facets covered there changed with the mesh).

    Clipped by hand rather than by scikit-fem's ``skfem.supermeshing.intersect`` (measured, docs/bodies.md): that
    one intersects 1-D meshes of one common coordinate (no projection along each slave facet's normal, so no
    curved Γ_C), rounds the nodes to 10 decimals (the patch test then fails by 1.5e-7 at 10⁴ slave facets, 4e-16
    here) and finds elements by comparing all with all (3.4 s at 10⁴ slave facets, 73 ms here)."""
    along = tangent_of(mean_normal)
    ends = [np.column_stack([s.start @ along, s.end @ along]) for s in (slave, master)]
    margin = margin + across(slave.points, slave.normal, master.points, mean_normal)
    chunks = [clipped(slave, master, e, f)
              for e, f in overlapping(ends[0].min(1), ends[0].max(1), ends[1].min(1), ends[1].max(1), margin)]
    e, f, lo, hi, xi_start, xi_end, length = (np.concatenate(parts) for parts in zip(*chunks))
    points, fractions = gauss((slave.degree + master.degree) // 2 + 1)
    xi = lo[:, None] + np.outer(hi - lo, points)
    eta = (xi - xi_start[:, None]) / (xi_end - xi_start)[:, None]
    weight = np.outer((hi - lo) * length, fractions)
    dual = lagrange(slave.degree, xi) @ dual_coefficients(slave.degree)[0].T  # (pairs, points, slave nodes)
    values = np.einsum("nq,nqa,nqb->nab", weight, dual, lagrange(master.degree, eta))
    a, b = np.indices(values.shape[1:]).reshape(2, -1)
    covered = np.bincount(e, weights=hi - lo, minlength=slave.measure.size)
    return [np.repeat(e, a.size), np.tile(a, e.size), np.repeat(f, a.size), np.tile(b, e.size), values.ravel()], covered


def node_to_segment(coords, normals, master: Segments, mean_normal: np.ndarray, margin: float):
    """Entries (slave node, master facet, its node b, φ_b(π(x_i))): x_i projected along n_i on the nearest
    facing master facet; each node once at most (candidates as :func:`mortar` finds them)."""
    along = tangent_of(mean_normal)
    s = coords @ along
    margin = margin + across(coords[:, None], normals, master.points, mean_normal)
    ends = np.column_stack([master.start @ along, master.end @ along])
    chunks = [projected(coords, normals, master, i, f) for i, f in overlapping(s, s, ends.min(1), ends.max(1), margin)]
    i, f, eta, distance = (np.concatenate(parts) for parts in zip(*chunks))
    nearest = np.lexsort((np.abs(distance), i))
    first = nearest[np.r_[True, i[nearest][1:] != i[nearest][:-1]]]
    i, f, eta = i[first], f[first], eta[first]
    values = lagrange(master.degree, eta)
    b = np.arange(values.shape[1])
    return np.repeat(i, b.size), np.repeat(f, b.size), np.tile(b, i.size), values.ravel()


def projected(coords, normals, master: Segments, i: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, ...]:
    """Of candidate pairs (slave node ``i``, master facet ``f``), those where the node's normal meets the facet from
    its front: i, f, the point's coordinate η on the facet and the distance to it along the normal."""
    n, chord = normals[i], master.end[f] - master.start[f]
    eta = cross(coords[i] - master.start[f], n) / cross(chord, n)
    distance = cross(master.start[f] - coords[i], chord) / cross(n, chord)
    keep = ((n * master.normal[f]).sum(axis=1) < 0) & (eta >= -COVERED) & (eta <= 1 + COVERED)
    return i[keep], f[keep], np.clip(eta[keep], 0.0, 1.0), distance[keep]


def relative_rows(vectors, dofs, transfer: sp.coo_matrix, master_dofs, ndofs: int,
                  slave: sp.coo_matrix | None = None) -> sp.csr_matrix:
    """Rows v_i·(ũ_i − Σ_k Π_ik u_k) on every DOF, ũ = S u the slave's coefficients in its multipliers' basis
    (``slave``: S, rows × the nodes of ``dofs``, the identity where None; P2 facets in 3-D:
    :func:`transformed_coefficients`)."""
    slave = sp.identity(dofs.shape[0], format="coo") if slave is None else slave
    m, dim = slave.shape[0], dofs.shape[1]
    rows = np.concatenate([np.repeat(slave.row, dim), np.repeat(transfer.row, dim)])
    cols = np.concatenate([dofs[slave.col].ravel(), master_dofs[transfer.col].ravel()])
    values = np.concatenate([(slave.data[:, None] * vectors[slave.row]).ravel(),
                             -(transfer.data[:, None] * vectors[transfer.row]).ravel()])
    return sp.csr_matrix((values, (rows, cols)), shape=(m, ndofs))


def transformed_coefficients(mesh: fe.Mesh, nodes: np.ndarray) -> sp.csr_matrix:
    """S = T⁻ᵀ for the P2 slave ``nodes`` (vertices first, as :func:`numpy.unique` sorts them): a displacement
    Σ u_b ψ_b is Σ ũ_a ψ̃_a with ũ = S u, ψ̃ = T ψ (:func:`~convexcontact.fem.contact.multiplier_transform`). T is
    its diagonal D plus vertex-to-edge terms E whose square is zero, so T⁻¹ = D⁻¹ − D⁻¹ E D⁻¹: at a vertex
    ũ_v = u_v, at an edge ũ_e = (u_e − α(u_v + u_w)) / (1 − 2α)."""
    T = multiplier_transform(mesh, nodes)
    inverse = sp.diags(1.0 / T.diagonal())
    return sp.csr_matrix(inverse - inverse @ (T - sp.diags(T.diagonal())) @ inverse).T.tocsr()


def slave_nodes(slave: Segments | Facets) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The slave boundary's nodes, each facet's node numbers among them, the weights w_i = ∫ψ_i and the
    nodal normals n_i ∝ ∫ψ_i n ds (the facets' normals averaged with the weights of ψ_i: a middle node takes its
    facet's normal), as :mod:`.contact` weighs a single body's nodes."""
    nodes, local = np.unique(slave.nodes, return_inverse=True)
    corners, dim = slave.nodes.shape[1], slave.normal.shape[1]
    local = local.reshape(-1, corners)
    share = np.outer(slave.measure, slave.shares).ravel()
    weights = np.bincount(local.ravel(), weights=share)
    summed = np.column_stack([np.bincount(local.ravel(), share * np.repeat(slave.normal[:, j], corners))
                              for j in range(dim)])
    return nodes, local, weights, summed / np.linalg.norm(summed, axis=1, keepdims=True)


def transfer_matrix(pair: Pair, slave, master, local, weights, normals, coords):
    """Π (slave nodes × master nodes) of the pair's method, the master's nodes, and which slave nodes keep
    their rows."""
    masters, master_local = np.unique(master.nodes, return_inverse=True)
    master_local = master_local.reshape(master.nodes.shape)
    mean_normal = weights @ normals / np.linalg.norm(weights @ normals)
    # each slave facet's (node's) own size on top of how far its normal can carry it across the gap (:func:`across`
    # bounds where its projection lands): twice the largest facet, as before, took nearly every pair on graded
    # meshes (7.2·10⁷ candidates at 1.4·10⁶ DOFs, bench two-body: the assembly 13.3 s, 4.2 s with the own size)
    margin = slave.size
    shape = (len(weights), len(masters))
    if pair.method == "node_to_segment":
        margin = np.zeros(len(weights))
        np.maximum.at(margin, local.ravel(), np.repeat(slave.size, local.shape[1]))
        i, f, b, values = node_to_segment(coords, normals, master, mean_normal, margin)
        ok = np.zeros(len(weights), bool)
        ok[i] = True
        return sp.coo_matrix((values, (i, master_local[f, b])), shape=shape).tocsr(), masters, ok
    (e, a, f, b, values), covered = (mortar_3d(slave, master, mean_normal) if isinstance(slave, Facets)
                                     else mortar(slave, master, mean_normal, margin))
    if (covered > 1 + COVERED).any():
        raise SceneError("contact.master", f"{pair.master!r} is met twice along the normals of {pair.boundary!r} "
                         "(it folds over, or faces the slave from both sides)",
                         "name only the part of the master boundary that faces the slave")
    ok = np.ones(len(weights), bool)
    ok[local[covered < 1 - COVERED].ravel()] = False  # a node keeps its row only when its facets are covered
    mass = sp.coo_matrix((values, (local[e, a], master_local[f, b])), shape=shape).tocsr()
    return sp.diags(1.0 / weights) @ mass, masters, ok


def pair_trace(pair: Pair, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling, free: np.ndarray,
               prescribed: np.ndarray) -> PairTrace:
    """The trace of a contact pair: slave nodes, their normals and weights, N, T and the gap from geometry."""
    dim = mesh.dim()
    if dim == 3 and pair.method == "node_to_segment":
        raise SceneError("contact.method", "node-to-segment is built in 2-D", "use method = 'mortar'")
    facets = check_boundary(mesh, pair.boundary, "contact.boundary")
    if dim == 2:
        slave = segments(mesh, facets, basis, "contact.boundary")
        master = segments(mesh, check_boundary(mesh, pair.master, "contact.master"), basis, "contact.master")
    else:
        slave = facets_3d(mesh, facets, "contact.boundary", basis)
        master = facets_3d(mesh, check_boundary(mesh, pair.master, "contact.master"), "contact.master", basis)
    nodes, local, weights, normals = slave_nodes(slave)
    coords = basis.doflocs[:, dim * nodes].T
    all_dofs = dim * nodes[:, None] + np.arange(dim)
    planes = symmetry_planes(mesh, basis, all_dofs, normals, free, prescribed)
    normals = in_plane(normals, planes)  # before the transfer: node-to-segment projects along them
    transfer, masters, ok = transfer_matrix(pair, slave, master, local, weights, normals, coords)
    # the slave's coefficients in its multipliers' basis (P2 facets in 3-D; the identity else), on the kept rows;
    # an edge node's row holds its vertices too, so it is kept only with them: the forces its multiplier puts on
    # the slave then land on kept nodes, which the results, the estimate and the pair's balance sum over
    transformed = sp.identity(ok.size, format="csr") if not getattr(slave, "transformed", False) else (
        transformed_coefficients(mesh, nodes))
    ok &= abs(transformed) @ (~ok).astype(float) == 0
    if not ok.any():
        raise SceneError("contact.master", f"no facet of {pair.master!r} faces {pair.boundary!r} (they lie side by "
                         "side, back to back, or beside each other along the interface: no slave facet's normal meets "
                         "the master)", "pair boundaries that face each other: the slave's outward normal must point "
                         "at the master, across from it")
    left_out = (f"{np.count_nonzero(~ok)} of {ok.size} nodes of {pair.boundary!r} have no master facet under their "
                "whole support: they are left out of the contact (make the larger boundary the master)")
    transformed = sp.coo_matrix(transformed[ok])
    transfer, normals, weights, coords = sp.coo_matrix(transfer[ok]), normals[ok], weights[ok], coords[ok]
    dofs, master_dofs = all_dofs[ok], dim * masters[:, None] + np.arange(dim)
    master_coords = basis.doflocs[:, master_dofs[:, 0]].T
    tangents, bitangents, mean_tangent = tangent_frame(normals, weights)
    N_full = relative_rows(normals, all_dofs, transfer, master_dofs, basis.N, transformed)
    frame = [tangents] if bitangents is None else [tangents, bitangents]
    symmetric = held_by_symmetry(frame, planes[ok])  # the master's columns too: the full model's images cancel them
    T_full = emptied(sp.vstack([relative_rows(t, all_dofs, transfer, master_dofs, basis.N, transformed)
                                for t in frame]).tocsr(), symmetric)
    gap = ((transfer @ master_coords - transformed @ basis.doflocs[:, all_dofs[:, 0]].T) * normals).sum(axis=1)
    if gap.min() < -max(slave.size.max(), master.size.max()):
        raise SceneError("parts", f"the bodies overlap: {pair.boundary!r} lies up to {-gap.min() * scaling.length:.3g} "
                         f"inside {pair.master!r}, deeper than a cell of the interface",
                         "move the bodies apart (Rectangle origin, Part offset); an interference fit must be "
                         "shallower than a cell")
    return PairTrace(
        facets=facets, dofs=dofs, coords=coords, normals=normals,
        tangents=tangents, coordinate=coords @ mean_tangent, weights=weights, mass=sp.diags(weights, format="csr"),
        N=N_full[:, free], T=T_full[:, free], normal_offset=N_full @ prescribed, tangent_offset=T_full @ prescribed,
        gap=gap * scaling.length / scaling.displacement, obstacle_coupling=None, obstacle_force=0.0,
        master_dofs=master_dofs, master_coords=master_coords, transfer=transfer.tocsr(), N_full=N_full,
        T_full=T_full, warnings=() if ok.all() else (left_out,), pieces=((slice(None), dofs, master_dofs),),
        bitangents=bitangents, symmetric=symmetric,
    )


def obstacle_piece(contact: Contact, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling, free: np.ndarray,
                   prescribed: np.ndarray) -> PairTrace:
    """A rigid obstacle under a body's boundary as a piece of a stack of pairs: its trace with no master."""
    trace = contact_trace(contact, mesh, basis, scaling, free, prescribed)
    dim = mesh.dim()
    no_master = sp.coo_matrix((trace.m, 0))
    frame = [trace.tangents] if trace.bitangents is None else [trace.tangents, trace.bitangents]
    N_full = relative_rows(trace.normals, trace.dofs, no_master, np.zeros((0, dim), int), basis.N)
    T_full = emptied(sp.vstack([relative_rows(t, trace.dofs, no_master, np.zeros((0, dim), int), basis.N)
                                for t in frame]).tocsr(), trace.symmetric)
    return PairTrace(**{name: getattr(trace, name) for name in (
        "facets", "dofs", "coords", "normals", "tangents", "coordinate", "weights", "mass", "N", "T", "normal_offset",
        "tangent_offset", "gap", "obstacle_coupling", "obstacle_force", "bitangents", "symmetric")},
        master_dofs=np.zeros((0, dim), int), master_coords=np.zeros((0, dim)), transfer=no_master.tocsr(),
        N_full=N_full, T_full=T_full, pieces=((slice(None), trace.dofs, np.zeros((0, dim), int)),))


def pairs_trace(pairs: Pairs, *arguments) -> PairTrace:
    """The trace of several contacts: pairs (:func:`pair_trace`) and rigid obstacles (:func:`obstacle_piece`)."""
    return stack([numbered(index, pair_trace if isinstance(pair, Pair) else obstacle_piece, pair, *arguments)
                  for index, pair in enumerate(pairs.pairs)])


def numbered(index: int, build, pair: Contact, *arguments) -> PairTrace:
    """``build(pair, …)``, its errors about ``contact.X`` named ``contact[index].X``: which pair of several."""
    try:
        return build(pair, *arguments)
    except SceneError as error:
        if not error.field.startswith("contact."):
            raise
        raise SceneError(f"contact[{index}].{error.field.removeprefix('contact.')}",
                         str(error)[len(error.field) + 2:]) from None
