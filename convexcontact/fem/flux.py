"""An equilibrated stress (Prager–Synge) for 2-D P1 triangles: a guaranteed bound of the energy error of the problem
with the contact traction fixed, plus the contact terms (docs/estimate.md).

Row by row of the stress, σ̂ is the sum over the vertices a of the patch fluxes σ_a in Raviart–Thomas RT0 on the
patch ω_a of a (Braess–Schöberl; Ern–Vohralík)::

    σ_a = argmin ‖σ − w_a‖_{ω_a}   over RT0(ω_a), row i (w_a the cellwise RT0 interpolant of ψ_a σ_h), with
          −div σ = Π_0(ψ_a f − ∇ψ_a · σ_h)   on each cell of ω_a,
          ∫_E σ n = ∫_E ψ_a g     on the facets E ∋ a of Γ_N (g the applied traction),
          ∫_E σ n = |E| t_a / 2   on the contact facets E ∋ a (t_a = F_a / w_a: the nodal contact force lumped),
          σ n = 0 on ∂ω_a inside the body, free on the facets where component i is held (Dirichlet).

Σ_a w_a = σ_h in every cell, so each patch minimizes its own share of σ̂ − σ_h, and a stress constant over a patch is
reproduced exactly on any mesh; the textbook target ψ_a σ_h (not in RT0) is not, on graded or locally refined meshes.

The patch problems are solvable because u_h is the discrete solution (the residual vanishes on ψ_a e_i, and the
contact fluxes at a sum to F_a). Then −div σ̂ = f (f constant per cell), σ̂ n = g on Γ_N and the facet mean t̂ of the
lumped tractions on the contact facets; for the continuum solution u of the problem whose contact traction is t̂,
e = u − u_h (Prager–Synge, σ̂ not symmetric)::

    ‖e‖_E ≤ ‖C^{-½}(sym σ̂ − σ_h)‖ + (C_K² − 1)^{½} ‖(2μ)^{-½} skew σ̂‖,

C_K Korn's constant of the body and its Dirichlet boundary (‖∇v‖ ≤ C_K ‖ε(v)‖; √2 for v = 0 on the whole
boundary). :func:`flux_estimate` adds the complementarity and friction terms of the contact (Weiss–Wohlmuth).

Written by hand (not with scikit-fem's RT elements): a patch problem in RT0 is the chain of cells around a, one
divergence constraint per cell on the two fluxes through its facets at a, solved by propagation from one known flux,
with one free circulation where none is known; assembling scikit-fem forms would be one Python call per patch. Here
every patch is solved at once with NumPy, no linear system.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..scene.meshing import check_boundary
from .assembly import FEModel
from .estimate import ContactState, applied_traction, components, held_components


@dataclass(frozen=True)
class Equilibrated:
    """The equilibrated stress of one P1 solution (scaled units) and its estimates per cell (squares).

    ``vertex_stress`` σ̂ at the three vertices of each cell (d, d, cells, 3; row i is the reconstructed flux of
    component i); ``symmetric`` ‖C^{-½}(sym σ̂ − σ_h)‖²_T, ``skew`` ‖(2μ)^{-½} skew σ̂‖²_T per cell; ``defect`` the
    largest |∫_T (f + div σ̂)| over the cells, relative to the largest |∫_T f| + Σ|fluxes| (round-off and the algebraic
    error of u_h: the patch problems are compatible only for the exact discrete solution).
    """

    vertex_stress: np.ndarray
    symmetric: np.ndarray
    skew: np.ndarray
    defect: float


def supported(fem: FEModel) -> bool:
    """The reconstruction covers 2-D P1 triangles."""
    return fem.dim == 2 and fem.scene.body.element == "P1" and fem.mesh.t.shape[0] == 3


def triangles(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex coordinates (x, k, cells), the Jacobian determinants (cells,) and the barycentric gradients ∇λ_k
    (x, k, cells). Laid out with the cells last, every small contraction here is a loop over whole columns (a
    broadcast sum over a short last axis, einsum's generic loop or matmul on stacks of 3 × 2 matrices cost several
    times more)."""
    xy = mesh.p[:, mesh.t]
    ahead, behind = xy[:, [1, 2, 0]], xy[:, [2, 0, 1]]  # p_{k+1}, p_{k+2}
    det = (xy[0, 1] - xy[0, 0]) * (xy[1, 2] - xy[1, 0]) - (xy[1, 1] - xy[1, 0]) * (xy[0, 2] - xy[0, 0])
    # ∇λ_k = rot(p_{k+1} − p_{k+2}) / det, oriented by the sign of det
    return xy, det, np.stack([ahead[1] - behind[1], behind[0] - ahead[0]]) / det


def cell_geometry(mesh):
    """Vertex coordinates (cells, 3, 2), areas (cells,) and the barycentric gradients (cells, 3, 2) (views of
    :func:`triangles`' arrays)."""
    xy, det, grads = triangles(mesh)
    return xy.transpose(2, 1, 0), 0.5 * np.abs(det), grads.transpose(2, 1, 0)


def opposite_facets(mesh) -> np.ndarray:
    """(cells, 3): the facet of each cell opposite its local vertex k (scikit-fem numbers a triangle's facets
    (v0 v1), (v1 v2), (v0 v2): opposite v2, v0, v1; checked, and found by search where a mesh numbers otherwise)."""
    t, facets, edges = mesh.t, mesh.facets, mesh.t2f
    out = edges[[1, 2, 0]]  # (k, cells)
    if ((facets[0, out] == t) | (facets[1, out] == t)).any():
        for l in range(3):
            e = edges[l]
            for k in range(3):
                away = (facets[0, e] != t[k]) & (facets[1, e] != t[k])
                out[k, away] = e[away]
    return out.T


def elastic_stress(fem: FEModel, u_components: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """σ(u_h) per cell (cells, 2, 2; a view of a (2, 2, cells) array) of the P1 displacement ``u_components``
    (d, vertices)."""
    lam, mu = fem.lame
    nodal = u_components[:, fem.mesh.t]  # (a, k, cells)
    grad_u = (nodal[:, None] * grads.transpose(2, 1, 0)[None]).sum(axis=2)  # (a, x, cells): Σ_k u_a(p_k) ∂_x λ_k
    stress = mu * (grad_u + grad_u.transpose(1, 0, 2))
    trace = lam * (grad_u[0, 0] + grad_u[1, 1])
    stress[0, 0] += trace
    stress[1, 1] += trace
    return stress.transpose(2, 0, 1)


def sort_by_vertex_and_angle(vertex: np.ndarray, angle: np.ndarray, nvertices: int) -> np.ndarray:
    """The permutation sorting the corners by ``vertex``, then by ``angle`` in [0, 4). One sort of packed 64-bit
    keys (vertex, angle quantized, index): SIMD-sorted, ~20× faster than np.lexsort; lexsort where the quantization
    would tie two corners of a vertex (cells of angles ≲ 10⁻⁶ rad, or meshes of more than ~10⁸ cells)."""
    index_bits, vertex_bits = int(vertex.size - 1).bit_length(), int(nvertices - 1).bit_length()
    angle_bits = 62 - index_bits - vertex_bits
    if angle_bits >= 8:
        quantized = np.minimum((angle * 2.0 ** (angle_bits - 2)).astype(np.int64), 2**angle_bits - 1)
        key = ((vertex.astype(np.int64) << angle_bits | quantized) << index_bits) | np.arange(vertex.size)
        key.sort()
        if (np.diff(key >> index_bits) > 0).all():
            return key & ((1 << index_bits) - 1)
    return np.lexsort((angle, vertex))


@dataclass(frozen=True)
class Chains:
    """The corners (k, c) of the cells (flat index k · cells + c, vertex t[k, c]) in chain order: by vertex, then
    counterclockwise around it, a boundary vertex's chain starting at the cell whose clockwise facet at the vertex is
    a boundary facet. ``order`` the flat index at each position, ``starts`` each chain's first position, ``segment``
    the chain of each corner (flat); per chain its ``vertex`` and the boundary facet it starts at and ends at
    (``first_facet``, ``last_facet``; −1 for the closed chains around interior vertices)."""

    order: np.ndarray
    starts: np.ndarray
    segment: np.ndarray
    vertex: np.ndarray
    first_facet: np.ndarray
    last_facet: np.ndarray

    @property
    def lasts(self) -> np.ndarray:
        return np.append(self.starts[1:], self.order.size) - 1


def patch_chains(mesh, xy: np.ndarray, det: np.ndarray) -> Chains:
    """The chains of cells around each vertex (:class:`Chains`); consecutive cells share their facet at the vertex,
    checked (a mesh whose cells overlap or are inverted is refused)."""
    ahead, behind = [1, 2, 0], [2, 0, 1]
    opposite = opposite_facets(mesh).T
    # counterclockwise around vertex k a cell enters through its facet (k, k+1) and leaves through (k, k+2)
    # (opposite k+2 and k+1), the other way round for a cell numbered clockwise
    positive = det > 0
    entering = np.where(positive, opposite[behind], opposite[ahead]).ravel()
    leaving = np.where(positive, opposite[ahead], opposite[behind]).ravel()
    outside = mesh.f2t[1] == -1
    begins = outside[entering]
    vertex = mesh.t.ravel()
    # a pseudo-angle of the direction to the cell's centroid (increasing with the angle, in [−1, 3); no arctan2),
    # measured from a boundary vertex's first cell
    direction = xy[:, ahead] + xy[:, behind] - 2.0 * xy
    dx, dy = direction[0].ravel(), direction[1].ravel()
    ratio = dy / (np.abs(dx) + np.abs(dy))
    angle = np.where(dx < 0, 2.0 - ratio, ratio)
    reference = np.zeros(mesh.nvertices)
    reference[vertex[begins]] = angle[begins]
    order = sort_by_vertex_and_angle(vertex, (angle - reference[vertex]) % 4.0, mesh.nvertices)
    around = vertex[order]
    new = begins[order]
    new[0] = True
    new[1:] |= around[1:] != around[:-1]
    starts = np.flatnonzero(new)
    lasts = np.append(starts[1:], order.size) - 1
    into, out_of = entering[order], leaving[order]
    if not ((out_of[:-1] == into[1:]) | new[1:]).all() or not (
            outside[out_of[lasts]] | (out_of[lasts] == into[starts])).all():
        raise ValueError("mesh: the cells around a vertex do not form a chain of cells sharing facets (overlapping, "
                         "inverted or degenerate cells); check the mesh, e.g. with skfem's Mesh.is_valid()")
    segment = np.empty(order.size, dtype=np.int64)
    segment[order] = np.cumsum(new) - 1
    first_facet = np.where(begins[order[starts]], into[starts], -1)
    last_facet = np.where(outside[out_of[lasts]], out_of[lasts], -1)
    return Chains(order, starts, segment.reshape(3, -1), around[starts], first_facet, last_facet)


def chain_fluxes(chains: Chains, rhs: np.ndarray, first: np.ndarray, last: np.ndarray, first_known: np.ndarray,
                 last_known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fluxes of all patch problems through each corner's two facets, counterclockwise around its vertex:
    entering y_in and leaving y_out (rows, ordered corners), with y_out − y_in = ``rhs`` (rows, ordered corners) at
    every corner and y_in = the previous corner's y_out along a chain. Each chain starts from its known flux: the
    outward ``first`` flux of its first facet (y_in = −first) where ``first_known``, else the outward ``last`` flux
    of its last facet where ``last_known``, else 0 (the chain's circulation, chosen after). A cycle closes on its own
    start, a chain known at both ends on its last flux: the last corner carries the data's incompatibility (the
    defect, round-off for the exact discrete solution).

    The recurrence y_out = y_in + rhs along a chain is a cumulative sum: one np.cumsum over all chains, each
    chain's partial sums taken from its start."""
    starts, lasts = chains.starts, chains.lasts
    partial = np.cumsum(rhs, axis=1)
    before = np.where(starts > 0, partial[:, starts - 1], 0.0)  # the sums of the chains before each chain
    total = partial[:, lasts] - before
    entering = np.where(first_known, -first, np.where(last_known, last - total, 0.0))
    leaving = partial + np.repeat(entering - before, np.diff(np.append(starts, rhs.shape[1])), axis=1)
    leaving[:, lasts] = np.where(last_known, last, entering + np.where(chains.last_facet < 0, 0.0, total))
    y_in = np.empty_like(leaving)
    y_in[:, 1:] = leaving[:, :-1]
    y_in[:, starts] = entering
    return y_in, leaving


def boundary_fluxes(mesh, facet_moments: np.ndarray, held: np.ndarray, facet: np.ndarray, vertex: np.ndarray):
    """Per row and chain, whether the outward flux through the chain's end ``facet`` (−1: none) at ``vertex`` is
    prescribed (not held) and its value ∫_E ψ_a g_i (``facet_moments``)."""
    on = np.flatnonzero(facet >= 0)
    facets = facet[on]
    known = np.zeros((2, facet.size), dtype=bool)
    value = np.zeros((2, facet.size))
    known[:, on] = ~held[:, facets]
    value[:, on] = facet_moments[(mesh.facets[1, facets] == vertex[on]).astype(np.int64), :, facets].T
    return known, value


def equilibrate(fem: FEModel, u_components: np.ndarray, facet_moments: np.ndarray, held: np.ndarray) -> Equilibrated:
    """The equilibrated stress of the P1 displacement ``u_components`` (d, vertices).

    ``facet_moments`` (2, d, nfacets): ∫_E ψ_a g_i for the two vertices a of each boundary facet (``mesh.facets``
    order); ``held`` (d, nfacets) the components a Dirichlet condition prescribes on each boundary facet (their
    fluxes are free).

    In RT0 a patch problem is a chain of cells around its vertex, one divergence constraint per cell on the two
    fluxes through its facets at the vertex: the fluxes follow from one known flux (a Neumann facet) by a
    cumulative sum along the chain (:func:`chain_fluxes`), and where none is known (interior and Dirichlet
    vertices) up to one free circulation, chosen to minimize the patch's share of σ̂ − σ_h (a scalar quadratic per
    patch, :func:`circulations`). No linear system is solved."""
    mesh = fem.mesh
    lam, mu = fem.lame
    xy, det, gradients = triangles(mesh)
    area, grads = 0.5 * np.abs(det), gradients.transpose(2, 1, 0)
    sigma_h = elastic_stress(fem, u_components, grads)
    body_force = np.asarray(fem.scene.body_force, dtype=float) * fem.scaling.length / fem.scaling.pressure
    chains = patch_chains(mesh, xy, det)
    # w_a, the RT0 interpolant of ψ_a σ_h,i: its outward flux through the facet opposite k is −|T| σ_h,i · ∇λ_k at
    # both vertices a of the facet (i, k, cells)
    target = -area * (sigma_h.transpose(1, 2, 0)[:, :, None] * gradients[None]).sum(axis=1)
    # the divergence constraint at corner k: the outward fluxes through its facets opposite k+1 and k+2 sum to
    # Π_0(ψ_a f − ∇ψ_a · σ_h) |T| = w's (−target_k) less |T| f / 3
    rhs = -target - (area / 3.0) * body_force[:, None, None]
    first = boundary_fluxes(mesh, facet_moments, held, chains.first_facet, chains.vertex)
    last = boundary_fluxes(mesh, facet_moments, held, chains.last_facet, chains.vertex)
    y_in, y_out = chain_fluxes(chains, rhs.reshape(2, -1)[:, chains.order], first[1], last[1], first[0], last[0])
    natural = np.empty((2, 2, y_in.shape[1]))
    natural[:, 0][:, chains.order], natural[:, 1][:, chains.order] = y_in, y_out
    y_in, y_out = natural.reshape(2, 2, 3, -1).transpose(1, 0, 2, 3)
    # outward fluxes through the facets opposite k+1 (ahead) and k+2 (behind) of each corner k
    positive = det > 0
    ahead, behind = np.where(positive, y_out, -y_in), np.where(positive, -y_in, y_out)
    orientation = np.where(positive, 1.0, -1.0)
    free = ~(first[0] | last[0])
    circulation = circulations(chains, xy, area, orientation, ahead - target[:, [1, 2, 0]],
                               behind - target[:, [2, 0, 1]], free)
    ahead += orientation * circulation
    behind -= orientation * circulation
    x = behind[:, [1, 2, 0]] + ahead[:, [2, 0, 1]]  # outward flux through facet k (i, k, cells)
    flux = x.transpose(0, 2, 1)  # (i, c, k)
    residual = flux.sum(axis=2) + area * body_force[:, None]  # ∫_T (div σ̂ + f)
    scale = np.abs(area[None] * body_force[:, None]).max() + np.abs(flux).max()
    defect = float(np.abs(residual).max() / scale) if scale > 0 else 0.0
    vertex_stress = vertex_values(x, xy, area)
    symmetric, skew = cell_norms(vertex_stress, sigma_h, lam, mu, area)
    return Equilibrated(vertex_stress, symmetric, skew, defect)


def circulations(chains: Chains, xy, area, orientation, ahead, behind, free) -> np.ndarray:
    """The circulation c (rows, k, cells: each corner's chain's) minimizing per row and free chain Σ_T ‖σ_a − w_a‖²_T,
    ``ahead``, ``behind`` (rows, k, cells) the outward fluxes of σ_a − w_a through the facets opposite k+1 and k+2 of
    corner k, c adding (1, −1) · ``orientation`` to them (0 on the chains with a known flux, ``free`` False).

    With M the RT0 mass matrix of the two facets' functions, M_kl = (c_k · c_l + Σ_m |c_m|² / 12) / 4|T| (c the
    vertices from the centroid), the patch's energy is quadratic in c, curvature |e_k|² / 4|T| (e_k = p_{k+1} −
    p_{k+2}) and slope (e_k · c_{k+1} z_ahead + e_k · c_{k+2} z_behind) / 4|T| per corner.

    w_a is the cellwise RT0 interpolant of ψ_a σ_h,i. Σ_a w_a = σ_h cell by cell, so σ̂ − σ_h = Σ_a (σ_a − w_a):
    each patch minimizes its own share, and a stress σ_h constant over a patch is reproduced exactly on any mesh
    (the textbook target ψ_a σ_h is not in RT0, and its projection leaves a circulation that does not vanish on
    graded or locally refined meshes: η / ‖σ_h‖ ≈ 10 % for a constant stress on the graded punch mesh,
    docs/estimate.md)."""
    centred = xy - xy.mean(axis=1, keepdims=True)
    edge = xy[:, [1, 2, 0]] - xy[:, [2, 0, 1]]
    weight = orientation / (4.0 * area)
    slope = ((edge * centred[:, [1, 2, 0]]).sum(axis=0) * weight * ahead
             + (edge * centred[:, [2, 0, 1]]).sum(axis=0) * weight * behind)
    segment, count = chains.segment, chains.starts.size
    curvature = np.bincount(segment.ravel(), ((edge**2).sum(axis=0) / (4.0 * area)).ravel(), count)
    per_chain = np.stack([np.bincount(segment.ravel(), s.ravel(), count) for s in slope])
    return np.where(free, -per_chain / curvature, 0.0)[:, segment]


def vertex_values(flux: np.ndarray, xy: np.ndarray, area: np.ndarray) -> np.ndarray:
    """σ̂ row i at the vertices m of each cell (i, x, cells, m; a view of an (i, x, m, cells) array) from the outward
    fluxes F_k through the facets opposite k (i, k, cells): Σ_k F_k (p_m − p_k) / 2|T|."""
    total = flux.sum(axis=1)
    moment = (flux[:, None] * xy[None]).sum(axis=2)  # Σ_k F_k p_k (i, x, cells)
    return ((total[:, None, None] * xy[None] - moment[:, :, None]) / (2.0 * area)).transpose(0, 1, 3, 2)


def cell_norms(vertex_stress, sigma_h, lam, mu, area):
    """‖C^{-½}(sym σ̂ − σ_h)‖²_T and ‖(2μ)^{-½} skew σ̂‖²_T per cell, by the facet-midpoint rule (exact: the integrands
    are quadratic), component by component."""
    at = vertex_stress.transpose(0, 1, 3, 2)  # (i, x, m, cells)
    mid = 0.5 * (at + at[:, :, [1, 2, 0]])
    a, d = mid[0, 0] - sigma_h[:, 0, 0], mid[1, 1] - sigma_h[:, 1, 1]
    b = 0.5 * (mid[0, 1] + mid[1, 0]) - sigma_h[:, 0, 1]
    w = 0.5 * (mid[0, 1] - mid[1, 0])
    # C⁻¹τ : τ = (|τ|² − λ/(2μ + 2λ) (tr τ)²) / 2μ for σ = 2με + λ tr ε I in 2-D
    energy = (a * a + d * d + 2 * b * b).sum(axis=0) - lam / (2 * mu + 2 * lam) * ((a + d) ** 2).sum(axis=0)
    return area * energy / (6 * mu), area * 2 * (w * w).sum(axis=0) / (6 * mu)


def contact_facets(fem: FEModel) -> np.ndarray:
    """The facets whose traction is the contact's: Γ_C (a pair's slave side) and the master sides of pairs."""
    facets = [fem.contact.facets]
    contact = fem.scene.contact
    for pair in getattr(contact, "pairs", None) or (contact,):
        if getattr(pair, "master", ""):
            facets.append(check_boundary(fem.mesh, pair.master, "contact.master"))
    return np.unique(np.concatenate(facets))


def lumped_traction(fem: FEModel, state: ContactState, facets: np.ndarray) -> np.ndarray:
    """t_a = F_a / w_a (vertices, d) at the nodes of the contact ``facets``, F the nodal contact forces (a pair's on
    both sides) and w_a = Σ |E| / 2 over a's contact facets on its side."""
    mesh = fem.mesh
    forces = np.zeros((mesh.nvertices, fem.dim))
    forces[fem.contact.dofs[:, 0] // fem.dim] = state.forces
    if state.master_forces is not None:
        forces[fem.contact.master_dofs[:, 0] // fem.dim] += state.master_forces
    weights = np.bincount(mesh.facets[:, facets].ravel(), np.tile(0.5 * facet_lengths(mesh, facets), 2),
                          minlength=mesh.nvertices)
    return np.divide(forces, weights[:, None], out=np.zeros_like(forces), where=weights[:, None] > 0)


def facet_moments(fem: FEModel, lumped: np.ndarray, on: np.ndarray) -> np.ndarray:
    """∫_E ψ_a g_i (2 vertices of E in ``mesh.facets`` order, d, nfacets) on the boundary facets: g the applied
    traction (constant on each straight facet) and, on the contact facets ``on``, the lumped contact traction
    t_a = F_a / w_a near each node a (``lumped`` (vertices, d)): the moment |E| t_a / 2, whose sum over a's facets is
    the nodal force F_a."""
    mesh = fem.mesh
    out = np.zeros((2, 2, mesh.nfacets))
    facets = mesh.boundary_facets()
    edge = np.diff(mesh.p[:, mesh.facets[:, facets]], axis=1)[:, 0]  # (x, facets)
    length = np.linalg.norm(edge, axis=0)
    normal = np.stack([edge[1], -edge[0]]) / length
    inward = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1) - mesh.p[:, mesh.facets[0, facets]]
    normal *= np.where((normal * inward).sum(axis=0) > 0, -1.0, 1.0)
    # one point per straight facet is all applied_traction reads of a basis (a scikit-fem FacetBasis costs more)
    points = SimpleNamespace(find=facets, normals=normal[:, :, None], dx=np.empty((facets.size, 1)))
    out[:, :, facets] = 0.5 * length * applied_traction(fem, points)[None, :, :, 0]
    out[:, :, on] = 0.5 * facet_lengths(mesh, on)[None, None] * lumped[mesh.facets[:, on]].transpose(0, 2, 1)
    return out


def facet_lengths(mesh, facets: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(mesh.p[:, mesh.facets[:, facets]], axis=1)[:, 0], axis=0)


KORN = np.sqrt(2.0)
"""Korn's constant C_K (‖∇v‖ ≤ C_K ‖ε(v)‖) the reported bound assumes: √2, exact for v vanishing on the whole
boundary; a body held on a part of its boundary has a larger, unknown one (docs/estimate.md)."""

TERMS = ("equilibrated", "asymmetry", "complementarity", "friction", "penetration")
"""The kinds of terms of the equilibrated estimate (docs/estimate.md)."""


@dataclass(frozen=True)
class FluxEstimate:
    """The equilibrated-flux estimate of one 2-D P1 solution, scaled energy units.

    ``eta`` the bound (a + (a² + 4b)^½) / 2, a = η_sym + (C_K² − 1)^½ η_skew, b the contact terms (‖e‖²_E ≤ a ‖e‖_E
    + b); ``indicators`` per cell (η_sym,T² + (C_K² − 1) η_skew,T² + the contact terms at T, scaled to sum to η²);
    ``terms`` each kind's sum; ``energy`` ‖u_h‖²_E; ``defect`` the equilibrium defect of σ̂ (:class:`Equilibrated`).
    """

    indicators: np.ndarray
    terms: dict[str, float]
    energy: float
    eta: float
    defect: float

    @property
    def relative(self) -> float:
        """η / ‖u_h‖_E (inf for a zero solution with a nonzero estimate, 0 for both zero)."""
        if self.energy > 0:
            return self.eta / np.sqrt(self.energy)
        return 0.0 if self.eta == 0 else np.inf


def contact_terms(fem: FEModel, state: ContactState, lumped: np.ndarray) -> dict[str, np.ndarray]:
    """The complementarity, friction and penetration terms per contact facet, with the traction σ̂ n = t̂ (the mean of
    the lumped nodal tractions over the facet): ∫_E p̂ (g − u_N,h) (kept where positive), ∫_E |t̂_T| |v_T| + t̂_T · v_T
    and 2μ |E|⁻¹ ‖(u_N,h − g)_+‖²_E (trapezoidal rule on the facet's two nodes)."""
    mesh, contact = fem.mesh, fem.contact
    facets = contact.facets
    ends = mesh.facets[:, facets]  # (2, facets) vertices
    length = facet_lengths(mesh, facets)
    node = np.full(mesh.nvertices, -1)
    node[contact.dofs[:, 0] // fem.dim] = np.arange(contact.dofs.shape[0])
    traction = lumped[ends].mean(axis=0)  # (facets, d)
    normal = contact.normals[node[ends]].mean(axis=0)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    pressure = -(traction * normal).sum(axis=1)
    out = {name: np.zeros(facets.size) for name in TERMS[2:]}
    if state.constrained:
        opening = (state.gap - state.normal_displacement)[node[ends]]  # (2, facets)
        out["complementarity"] = np.maximum(pressure * length * opening.mean(axis=0), 0.0)
        out["penetration"] = 2.0 * fem.lame[1][mesh.f2t[0, facets]] * 0.5 * (np.maximum(-opening, 0.0) ** 2).sum(axis=0)
    if state.slip is not None:
        tangential = traction + pressure[:, None] * normal
        slip = state.slip[node[ends]]  # (2, facets, d)
        slip = slip - (slip * normal).sum(axis=2)[..., None] * normal
        out["friction"] = 0.5 * length * (np.linalg.norm(tangential, axis=1) * np.linalg.norm(slip, axis=2)
                                          + (tangential * slip).sum(axis=2)).sum(axis=0)
    return out


def flux_estimate(fem: FEModel, u: np.ndarray, state: ContactState) -> FluxEstimate:
    """The equilibrated-flux estimate of the full (scaled) P1 displacement ``u`` under the contact ``state``; for a
    pair of bodies (mortar or node to segment) each body's traction on its contact side is the datum, and the
    complementarity and friction terms are the slave side's (relative gap and slip)."""
    mesh = fem.mesh
    on = contact_facets(fem)
    lumped = lumped_traction(fem, state, on)
    held = np.zeros((fem.dim, mesh.nfacets), dtype=bool)
    boundary = mesh.boundary_facets()
    held[:, boundary] = held_components(fem, boundary)
    stress = equilibrate(fem, components(fem, u), facet_moments(fem, lumped, on), held)
    per_facet = contact_terms(fem, state, lumped)
    cells = mesh.f2t[0, fem.contact.facets]
    parts = {"equilibrated": stress.symmetric, "asymmetry": (KORN**2 - 1) * stress.skew}
    for name, values in per_facet.items():
        parts[name] = np.bincount(cells, values, minlength=mesh.nelements)
    a = np.sqrt(stress.symmetric.sum()) + np.sqrt(parts["asymmetry"].sum())
    b = sum(parts[name].sum() for name in TERMS[2:])
    eta = 0.5 * (a + np.sqrt(a**2 + 4 * b))
    local = sum(parts.values())
    total = local.sum()
    # scaled to sum to η² (the VTU's and the residual estimate's convention): one factor for every cell, which
    # Dörfler marking does not see
    indicators = local * (eta**2 / total) if total > 0 else local
    return FluxEstimate(indicators, {name: float(parts[name].sum()) for name in TERMS},
                        float(u @ (fem.K_full @ u)), float(eta), stress.defect)
