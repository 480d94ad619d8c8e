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
boundary). The RT0 sum's skew part is then driven down by a divergence-free correction that keeps every constraint
(:mod:`.flux_correction`). :func:`flux_estimate` adds the complementarity and friction terms of the contact
(Weiss–Wohlmuth).

Written by hand (not with scikit-fem's RT elements): a patch problem in RT0 is the chain of cells around a, one
divergence constraint per cell on the two fluxes through its facets at a, solved by a cumulative sum from one known
flux, with one free circulation where none is known; assembling scikit-fem forms would be one Python call per patch.
Here the cells of all patches are sorted into their chains once, and every patch is solved at once by one
np.cumsum per row of the stress: no linear system, no loop over patches or sweeps.

What does not depend on the chains (σ_h, σ̂ at the vertices, the cell norms, the facet data, the contact terms and
:func:`bound`) is written for triangles and tetrahedra alike: :mod:`.flux3d` solves the patches of P1 tetrahedra.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from .. import blas
from . import flux_correction
from .assembly import FEModel
from .estimate import (
    ContactState,
    applied_traction,
    components,
    contact_facets,
    contact_forces,
    held_components,
    scaled_body_force,
)


@dataclass(frozen=True)
class Equilibrated:
    """The equilibrated stress of one P1 solution (scaled units) and its estimates per cell (squares).

    ``vertex_stress`` σ̂ at the d + 1 vertices of each cell (d, d, cells, d + 1; row i is the reconstructed flux of
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


BLOCK = 16_384
"""Cells per block of the cell-wise arithmetic (the circulations' weights, σ̂ at the vertices, the norms): its
temporaries then stay in the processor's caches (2× faster at 10⁶ cells than whole arrays)."""


def for_blocks(count: int, work) -> None:
    """work(cells) for the blocks of :data:`BLOCK` cells, shared out between threads (:func:`.flux_correction.parallel`)."""
    flux_correction.for_blocks(count, work, BLOCK)


def triangles(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex coordinates (x, k, cells), the Jacobian determinants (cells,) and the barycentric gradients ∇λ_k
    (x, k, cells).

    Arrays here are laid out with the cells last, so that every small contraction is a loop over whole columns (a
    broadcast sum over a short last axis, einsum's generic loop or matmul on stacks of 3 × 2 matrices cost several
    times more), and gathered with np.take or 1-D fancy indexing: numpy indexes a 2-D array by a slice and a large
    index array 10–100× slower (17 ms for the coordinates of 10⁵ cells, against 1 ms)."""
    xy = np.take(mesh.p, mesh.t, axis=1)
    x, y = xy
    det = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0])
    grads = np.empty_like(xy)
    for k in range(3):  # ∇λ_k = rot(p_{k+1} − p_{k+2}) / det, oriented by the sign of det
        ahead, behind = (k + 1) % 3, (k + 2) % 3
        np.divide(y[ahead] - y[behind], det, out=grads[0, k])
        np.divide(x[behind] - x[ahead], det, out=grads[1, k])
    return xy, det, grads


def opposite_facets(mesh) -> np.ndarray:
    """(cells, d + 1): the facet of each cell opposite its local vertex k (the one of its facets without that
    vertex; found whatever order a mesh numbers a cell's facets in; triangles and tetrahedra).

    The vertex a facet misses is the cell's vertex sum less the facet's (integers: exact), then located among the
    cell's vertices by d comparisons (a search of each facet's ends for each vertex cost 3× more: 30 ms at 10⁵
    cells)."""
    t, facets, cell_facets = mesh.t, mesh.facets, mesh.t2f
    cells = t.shape[1]
    total = t.sum(axis=0, dtype=np.int64)
    out = np.empty_like(cell_facets)
    flat = out.reshape(-1)
    for facet in cell_facets:
        missing = total.copy()
        for ends in facets:
            missing -= np.take(ends, facet)
        slot = np.arange(cells)  # the flat index k · cells + c of (k, c), k the missing vertex's local number
        for k in range(1, t.shape[0]):
            slot[t[k] == missing] += k * cells
        flat[slot] = facet
    return out.T


def elastic_stress(fem: FEModel, u_components: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """σ(u_h) per cell (cells, d, d; a view of a (d, d, cells) array) of the P1 displacement ``u_components``
    (d, vertices); ``gradients`` ∇λ_k (x, k, cells) (:func:`triangles`, :func:`.flux3d.tetrahedra`)."""
    lam, mu = fem.lame
    d = u_components.shape[0]
    nodal = np.take(u_components, fem.mesh.t, axis=1)  # (a, k, cells)
    grad_u = np.empty((d, d, nodal.shape[2]))  # (a, x, cells): Σ_k u_a(p_k) ∂_x λ_k, no (a, x, k, cells) temporary
    for a in range(d):
        for x in range(d):
            np.multiply(nodal[a, 0], gradients[x, 0], out=grad_u[a, x])
            for k in range(1, d + 1):
                grad_u[a, x] += nodal[a, k] * gradients[x, k]
    trace = lam * sum(grad_u[a, a] for a in range(d))
    stress = np.empty_like(grad_u)
    for a in range(d):
        np.multiply(2 * mu, grad_u[a, a], out=stress[a, a])
        stress[a, a] += trace
        for b in range(a + 1, d):
            np.multiply(mu, grad_u[a, b] + grad_u[b, a], out=stress[a, b])
            stress[b, a] = stress[a, b]
    return stress.transpose(2, 0, 1)


def sort_by_vertex_and_angle(vertex: np.ndarray, angle: np.ndarray, nvertices: int) -> np.ndarray:
    """The permutation sorting the corners by ``vertex``, then by ``angle`` in [0, 4): one stable sort of packed
    64-bit keys (vertex, angle quantized, index), ~15× faster than np.lexsort; lexsort where the quantization would
    tie two corners of a vertex (cells with angles of ≲ 10⁻⁶ rad, or meshes of ~10⁸ cells)."""
    index_bits, vertex_bits = int(vertex.size - 1).bit_length(), int(nvertices - 1).bit_length()
    angle_bits = 62 - index_bits - vertex_bits
    if angle_bits >= 8:
        # in place: every fresh array of this size costs its page faults (as much as the sort itself)
        key = (angle * 2.0 ** (angle_bits - 2)).astype(np.int64)
        np.minimum(key, 2**angle_bits - 1, out=key)
        high = vertex.astype(np.int64)
        high <<= angle_bits
        key |= high
        key <<= index_bits
        key |= np.arange(vertex.size)
        key.sort(kind="stable")  # timsort: the keys come in runs (a mesh's cells number nearby vertices together)
        np.right_shift(key, index_bits, out=high)
        if (high[1:] > high[:-1]).all():
            key &= (1 << index_bits) - 1
            return key
    return np.lexsort((angle, vertex))


@dataclass(frozen=True)
class Chains:
    """The patches' cells in chain order. A corner (k, c) of a cell (flat index k · cells + c) lies in the patch of
    vertex t[k, c]; going counterclockwise around the vertex it enters the cell through one of its two facets at the
    vertex and leaves through the other, into the next corner of the chain. ``order``: the corners by vertex, then
    counterclockwise, a boundary vertex's chain starting at the corner that enters from a boundary facet (flat index
    at each position); ``starts``, ``lengths`` of the chains in it; per facet slot (k, cells), the facet opposite k,
    the positions of the corners ``leaving`` and ``entering`` through it; per chain its ``vertex`` and the boundary
    facets it starts and ends at (``first_facet``, ``last_facet``; −1 for the closed chains around interior
    vertices)."""

    order: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    leaving: np.ndarray
    entering: np.ndarray
    vertex: np.ndarray
    first_facet: np.ndarray
    last_facet: np.ndarray

    @property
    def lasts(self) -> np.ndarray:
        return self.starts + self.lengths - 1


def oriented(positive: np.ndarray, rows: np.ndarray, counterclockwise, clockwise) -> np.ndarray:
    """(3, cells): row k is ``rows[counterclockwise[k]]`` on the cells numbered counterclockwise (``positive``), else
    ``rows[clockwise[k]]``; written into one output (np.where of gathered rows made four fresh (3, cells) arrays,
    each faulted in page by page on every call)."""
    out = np.empty((3, rows.shape[1]), rows.dtype)
    for k in range(3):
        out[k] = rows[clockwise[k]]
        np.copyto(out[k], rows[counterclockwise[k]], where=positive)
    return out


def patch_chains(mesh, xy: np.ndarray, det: np.ndarray, opposite: np.ndarray) -> Chains:
    """The chains of cells around the vertices (:class:`Chains`), sorted once by vertex and the angle of the cells'
    centroids around it (``opposite``: :func:`opposite_facets`). That consecutive corners of a chain share their
    facet is checked: a mesh whose cells overlap is refused."""
    ahead, behind = [1, 2, 0], [2, 0, 1]
    opposite = opposite.T
    # counterclockwise around its vertex k a cell enters through its facet (k, k+1), opposite k+2, and leaves through
    # (k, k+2), opposite k+1; the other way round on a cell numbered clockwise
    positive = det > 0
    enters = oriented(positive, opposite, behind, ahead).ravel()
    leaves = oriented(positive, opposite, ahead, behind).ravel()
    outside = mesh.f2t[1] == -1
    begins = outside[enters]
    vertex = mesh.t.ravel()
    # a pseudo-angle of the direction from the vertex to the cell's centroid (increasing with the angle, in
    # [−1, 3); no arctan2), measured from a boundary vertex's first corner
    dx, dy = (xy.mean(axis=1)[:, None] - xy).reshape(2, -1)
    angle = np.abs(dx)  # dy / (|dx| + |dy|), then 2 − that where dx < 0: in place, no fresh temporaries
    angle += np.abs(dy)
    np.divide(dy, angle, out=angle)
    np.subtract(2.0, angle, out=angle, where=dx < 0)
    reference = np.zeros(mesh.nvertices)
    reference[vertex[begins]] = angle[begins]
    angle -= reference[vertex]  # in (−4, 4): mod 4 by adding 4 where negative (np.remainder costs 3× more)
    np.add(angle, 4.0, out=angle, where=angle < 0)
    order = sort_by_vertex_and_angle(vertex, angle, mesh.nvertices)
    around = vertex[order]
    new = begins[order]
    new[0] = True
    new[1:] |= around[1:] != around[:-1]
    starts = np.flatnonzero(new)
    lengths = np.diff(np.append(starts, order.size))
    lasts = starts + lengths - 1
    into, out_of = enters[order], leaves[order]
    if not (((out_of[:-1] == into[1:]) | new[1:]).all() and (outside[out_of[lasts]] | (out_of[lasts] == into[starts])).all()):
        raise ValueError("mesh: the cells around a vertex do not form a chain of neighbours (overlapping or "
                         "degenerate cells); check the mesh (skfem's Mesh.is_valid(), or a fresh one from the geometry)")
    position = np.empty(order.size, dtype=np.int64)
    position[order] = np.arange(order.size)
    position = position.reshape(3, -1)
    # facet k is left by the cell's corner k+2 and entered by its corner k+1 (counterclockwise cells)
    return Chains(order, starts, lengths, oriented(positive, position, behind, ahead),
                  oriented(positive, position, ahead, behind), around[starts],
                  np.where(begins[order[starts]], into[starts], -1), np.where(outside[out_of[lasts]], out_of[lasts], -1))


def chain_fluxes(chains: Chains, rhs: np.ndarray, first: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One row's fluxes of all patch problems through each corner's two facets, counterclockwise around its vertex:
    entering y_in and leaving y_out (ordered corners), with y_out − y_in = ``rhs`` (ordered corners) and y_in = the
    previous corner's y_out along each chain. A chain starts from its known flux, ``first`` = (known, value) per
    chain of its first facet's outward flux (y_in = −value), else ``last``'s of its last facet, else 0 (the chain's
    circulation, chosen after). A cycle closes on its own start, a chain known at both ends on its last flux: the
    last corner carries the data's incompatibility (the defect; round-off for the exact discrete solution).

    The recurrence y_out = y_in + rhs along a chain is a cumulative sum: one np.cumsum over all chains, each
    chain's partial sums counted from its start."""
    (first_known, first_flux), (last_known, last_flux) = first, last
    starts, lasts = chains.starts, chains.lasts
    partial = np.cumsum(rhs)
    before = np.concatenate([[0.0], partial[starts[1:] - 1]])  # the sums of the chains before each chain
    total = partial[lasts] - before
    entering = np.where(first_known, -first_flux, np.where(last_known, last_flux - total, 0.0))
    y_out = partial + np.repeat(entering - before, chains.lengths)
    y_out[lasts] = np.where(last_known, last_flux, entering + np.where(chains.last_facet < 0, 0.0, total))
    y_in = np.empty_like(y_out)
    y_in[1:] = y_out[:-1]
    y_in[starts] = entering
    return y_in, y_out


def boundary_fluxes(mesh, facet_moments: np.ndarray, held: np.ndarray, facet: np.ndarray, vertex: np.ndarray):
    """Per row and chain, whether the outward flux through the chain's end ``facet`` (−1: none) at ``vertex`` is
    prescribed (not held) (rows, chains) and its value ∫_E ψ_a g_i (``facet_moments``)."""
    on = np.flatnonzero(facet >= 0)
    facets = facet[on]
    known = np.zeros((2, facet.size), dtype=bool)
    value = np.zeros((2, facet.size))
    known[:, on] = ~held[:, facets]
    value[:, on] = facet_moments[(mesh.facets[1][facets] == vertex[on]).astype(np.int64), :, facets].T
    return known, value


@dataclass(frozen=True)
class Circulation:
    """A chain's share of Σ_T ‖σ_a − w_a‖²_T as a function of its circulation c (added to every y_in and y_out of the
    chain): the ``curvature`` per chain; the slope's weights of y_out and y_in at the ordered corners (``leaving``,
    ``entering``), and of w_a's outward fluxes through the facets opposite k+1 and k+2 of each corner k (``ahead``,
    ``behind``; k, cells)."""

    curvature: np.ndarray
    leaving: np.ndarray
    entering: np.ndarray
    ahead: np.ndarray
    behind: np.ndarray


def circulation_weights(chains: Chains, xy: np.ndarray, det: np.ndarray) -> Circulation:
    """:class:`Circulation` of the mesh. At corner k, σ_a − w_a has the outward fluxes z = F − w through the facets
    opposite k+1 and k+2 (z_ahead, z_behind), and c adds ±(1, −1) to them (+ on counterclockwise cells, where F_ahead
    = y_out and F_behind = −y_in; else F_ahead = −y_in, F_behind = y_out). With the RT0 mass matrix of the two
    facets' functions M_kl = (c_k · c_l + Σ_m |c_m|² / 12) / 4|T| (c the vertices from the centroid), the energy is
    quadratic in c: curvature |e_k|² / 4|T| (e_k = p_{k+1} − p_{k+2}) and slope ±(g_ahead z_ahead + g_behind
    z_behind), g_ahead = e_k · c_{k+1} / 4|T|, g_behind = e_k · c_{k+2} / 4|T|, per corner."""
    ahead, behind = [1, 2, 0], [2, 0, 1]
    g_ahead, g_behind, curvature = np.empty((3, *xy.shape[1:]))

    def block(cells):
        corners = xy[..., cells]
        centred = corners - corners.mean(axis=1, keepdims=True)
        edge = corners[:, ahead] - corners[:, behind]
        quarter = 0.5 / np.abs(det[cells])  # 1 / 4|T|
        g_ahead[:, cells] = (edge * centred[:, ahead]).sum(axis=0) * quarter
        g_behind[:, cells] = (edge * centred[:, behind]).sum(axis=0) * quarter
        curvature[:, cells] = (edge**2).sum(axis=0) * quarter

    for_blocks(det.size, block)
    positive = det > 0
    return Circulation(np.add.reduceat(curvature.ravel()[chains.order], chains.starts),
                       np.where(positive, g_ahead, -g_behind).ravel()[chains.order],
                       np.where(positive, g_behind, -g_ahead).ravel()[chains.order],
                       np.where(positive, g_ahead, -g_ahead), np.where(positive, g_behind, -g_behind))


def row_fluxes(chains: Chains, weights: Circulation, rhs: np.ndarray, target: np.ndarray, first, last) -> np.ndarray:
    """The outward fluxes of σ̂ row i through the facets opposite k of each cell (k, cells): :func:`chain_fluxes` of
    the corners' ``rhs`` (k, cells) from the chains' known boundary fluxes (``first``, ``last``), each free chain's
    circulation minimizing Σ_T ‖σ_a − w_a‖²_T (``target``: w's outward fluxes through the facets opposite k;
    :class:`Circulation`)."""
    y_in, y_out = chain_fluxes(chains, rhs.ravel()[chains.order], first, last)
    own = weights.ahead * target[[1, 2, 0]] + weights.behind * target[[2, 0, 1]]  # w's part of the slopes
    slope = np.add.reduceat(weights.leaving * y_out - weights.entering * y_in - own.ravel()[chains.order],
                            chains.starts)
    circulation = np.repeat(np.where(first[0] | last[0], 0.0, -slope / weights.curvature), chains.lengths)
    y_in += circulation
    y_out += circulation
    return y_out[chains.leaving] - y_in[chains.entering]


def equilibrate(fem: FEModel, u_components: np.ndarray, facet_moments: np.ndarray, held: np.ndarray) -> Equilibrated:
    """The equilibrated stress of the P1 displacement ``u_components`` (d, vertices).

    ``facet_moments`` (2, d, nfacets): ∫_E ψ_a g_i for the two vertices a of each boundary facet (``mesh.facets``
    order); ``held`` (d, nfacets) the components a Dirichlet condition prescribes on each boundary facet (their
    fluxes are free).

    In RT0 a patch problem is a chain of cells around its vertex, one divergence constraint per cell on the two
    fluxes through its facets at the vertex: the fluxes follow from one known flux (a Neumann facet) by a
    cumulative sum along the chain (:func:`chain_fluxes`), and where none is known (interior and Dirichlet
    vertices) up to one free circulation, chosen to minimize the patch's share of σ̂ − σ_h (a scalar quadratic per
    patch, :func:`circulation_weights`). No linear system is solved.

    The target w_a is the cellwise RT0 interpolant of ψ_a σ_h,i. Σ_a w_a = σ_h cell by cell, so σ̂ − σ_h = Σ_a (σ_a −
    w_a): each patch minimizes its own share, and a stress σ_h constant over a patch is reproduced exactly on any
    mesh (the textbook target ψ_a σ_h is not in RT0, and its projection leaves a circulation that does not vanish on
    graded or locally refined meshes: η / ‖σ_h‖ ≈ 10 % for a constant stress on the graded punch mesh,
    docs/estimate.md)."""
    mesh = fem.mesh
    lam, mu = fem.lame
    xy, det, gradients = triangles(mesh)
    area = 0.5 * np.abs(det)
    body_force = scaled_body_force(fem)
    opposite = opposite_facets(mesh)
    sigma_h, x = rt0_fluxes(fem, u_components, xy, det, gradients, body_force, opposite, facet_moments, held)
    defect = equilibrium_defect(x, area, body_force)
    vertex_stress = vertex_values(x, xy, area)
    # freed before the correction allocates its own, as the chains were (rt0_fluxes): the memory the estimate
    # holds at once is what the system maps in afresh, page by page, on every call (docs/estimate.md)
    del x, xy, det
    vertex_stress = flux_correction.corrected(vertex_stress, sigma_h, gradients, area, fem.lame, mesh, opposite, held, KORN)
    symmetric, skew = cell_norms(vertex_stress, sigma_h, lam, mu, area)
    return Equilibrated(vertex_stress, symmetric, skew, defect)


def rt0_fluxes(fem, u_components, xy, det, gradients, body_force, opposite, facet_moments, held):
    """σ_h (cells, 2, 2) and the outward fluxes of σ̂ row i through the facet opposite k of each cell (i, k, cells):
    the patch problems of :func:`equilibrate` in chain order (:func:`patch_chains`, :func:`row_fluxes`). The chain
    order on this thread while σ_h and the patch data are computed on another (they do not depend on it), then the
    two rows side by side. ``xy``, ``det``, ``gradients``: :func:`triangles`; the rest :func:`equilibrate`'s."""
    mesh = fem.mesh
    area = 0.5 * np.abs(det)

    def chain_order():
        return mesh_chains(mesh, xy, det, opposite)

    def patch_data():
        sigma_h = elastic_stress(fem, u_components, gradients)
        # w_a's outward flux through the facet opposite k is −|T| σ_h,i · ∇λ_k at both vertices a of the facet
        target = np.empty((2, *gradients.shape[1:]))  # (i, k, cells)
        for i, row in enumerate(sigma_h.transpose(1, 2, 0)):
            np.multiply(row[0], gradients[0], out=target[i])
            target[i] += row[1] * gradients[1]
        target *= -area
        # the divergence constraint at corner k: the outward fluxes through its facets opposite k+1 and k+2 sum to
        # ∫_T Π_0(ψ_a f − ∇ψ_a · σ_h) = w's (−target_k) less |T| f / 3
        return sigma_h, target, -target - (area / 3.0) * body_force[:, None, None]

    (chains, weights), (sigma_h, target, rhs) = flux_correction.parallel(lambda task: task(), [chain_order, patch_data],
                                                                          det.size)
    first = boundary_fluxes(mesh, facet_moments, held, chains.first_facet, chains.vertex)
    last = boundary_fluxes(mesh, facet_moments, held, chains.last_facet, chains.vertex)
    return sigma_h, np.stack(flux_correction.parallel(
        lambda i: row_fluxes(chains, weights, rhs[i], target[i], (first[0][i], first[1][i]), (last[0][i], last[1][i])),
        range(2), det.size))


_kept = (None, None)  # (a weak reference to the last mesh asked, (its chains, circulation weights, corners))


def mesh_chains(mesh, xy: np.ndarray, det: np.ndarray, opposite: np.ndarray) -> tuple[Chains, Circulation]:
    """:func:`patch_chains` and :func:`circulation_weights` of ``mesh``, kept for the last mesh asked while it lives:
    they depend on the mesh alone (its cells and coordinates), and the cases of a parameter grid share one mesh
    (``studies.parameters.grid``: one assembly per group). Kept with the cells' corners ``xy`` they were computed
    from, and computed afresh where those differ: a mesh's arrays may be changed in place (a deformed
    configuration), and comparing them costs a pass over 6 numbers a cell. One mesh only, so the memory held is one
    mesh's (≈ 240 bytes per cell) and an adaptive loop does not accumulate them; the arrays are read-only."""
    global _kept
    ref, value = _kept
    if ref is not None and ref() is mesh and np.array_equal(value[2], xy):
        return value[:2]
    chains = patch_chains(mesh, xy, det, opposite)
    value = (chains, circulation_weights(chains, xy, det), xy.copy())
    for part in value[:2]:
        for array in vars(part).values():
            array.flags.writeable = False

    def forget(dead):  # called with the weak reference when the mesh is collected: its chains go with it
        global _kept
        if _kept[0] is dead:
            _kept = (None, None)

    _kept = (weakref.ref(mesh, forget), value)
    return value[:2]


def equilibrium_defect(flux: np.ndarray, volume: np.ndarray, body_force: np.ndarray) -> float:
    """The largest |∫_T (div σ̂ + f)| over the cells, relative to the largest |∫_T f| + the largest flux, from the
    outward fluxes (i, k, cells) through the facets opposite k (:attr:`Equilibrated.defect`)."""
    residual = flux.sum(axis=1) + volume * body_force[:, None]
    scale = np.abs(volume[None] * body_force[:, None]).max() + np.abs(flux).max()
    return float(np.abs(residual).max() / scale) if scale > 0 else 0.0


def vertex_values(flux: np.ndarray, xy: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """σ̂ row i at the vertices m of each cell (i, x, cells, m; a view of an (i, x, m, cells) array) from the outward
    fluxes F_k through the facets opposite k (i, k, cells): Σ_k F_k (p_m − p_k) / d|T| (triangles, tetrahedra)."""
    d = xy.shape[0]
    out = np.empty((d, d, *xy.shape[1:]))

    def block(cells):
        scale = 1.0 / (d * volume[cells])
        for i in range(d):
            fluxes = flux[i, :, cells]
            total = fluxes.sum(axis=0)
            for x in range(d):
                corners = xy[x, :, cells]
                np.multiply(corners, total, out=out[i, x, :, cells])
                out[i, x, :, cells] -= (fluxes * corners).sum(axis=0)
                out[i, x, :, cells] *= scale

    for_blocks(volume.size, block)
    return out.transpose(0, 1, 3, 2)


def cell_norms(vertex_stress, sigma_h, lam, mu, volume):
    """‖C^{-½}(sym σ̂ − σ_h)‖²_T and ‖(2μ)^{-½} skew σ̂‖²_T per cell, exact for σ̂ linear per cell: ∫_T q(τ) = |T|
    (Σ_m q(τ_m) + q(Σ_m τ_m)) / (d + 1)(d + 2) for a quadratic form q of a linear τ (τ_m its values at the d + 1
    vertices)."""
    at = vertex_stress.transpose(0, 1, 3, 2)  # (i, x, m, cells)
    out = np.empty((2, volume.size))

    def block(cells):
        out[:, cells] = block_norms(at[..., cells], sigma_h[cells], lam[cells], mu[cells], volume[cells])

    for_blocks(volume.size, block)
    return out[0], out[1]


def block_norms(at, sigma_h, lam, mu, volume):
    d = at.shape[0]
    error = at - sigma_h.transpose(1, 2, 0)[:, :, None]  # σ̂ − σ_h at the vertices (i, x, m, cells)
    trace_weight = lam / (2 * mu + d * lam)

    def compliance(e):  # 2μ C⁻¹τ : τ = |τ|² − λ/(2μ + dλ) (tr τ)² for τ = sym e, σ = 2με + λ tr ε I
        symmetric = e + e.swapaxes(0, 1)
        return 0.25 * (symmetric * symmetric).sum(axis=(0, 1)) - trace_weight * np.trace(e) ** 2

    def asymmetry(e):  # |skew e|² (σ_h is symmetric: skew e = skew σ̂)
        skew = e - e.swapaxes(0, 1)
        return 0.25 * (skew * skew).sum(axis=(0, 1))

    total = error.sum(axis=2)
    weight = volume / ((d + 1) * (d + 2) * 2 * mu)
    return (weight * (compliance(error).sum(axis=0) + compliance(total)),
            weight * (asymmetry(error).sum(axis=0) + asymmetry(total)))


def lumped_traction(fem: FEModel, state: ContactState, facets: np.ndarray) -> np.ndarray:
    """t_a = F_a / w_a (vertices, d) at the nodes of the contact ``facets``, F the nodal contact forces (a pair's on
    both sides) and w_a = Σ |E| / d over a's contact facets on its side."""
    mesh = fem.mesh
    d = fem.dim
    forces = contact_forces(fem, state)  # P1: the scalar DOFs are the vertices
    weights = np.bincount(mesh.facets[:, facets].ravel(), np.tile(facet_measures(mesh, facets) / d, d),
                          minlength=mesh.nvertices)
    return np.divide(forces, weights[:, None], out=np.zeros_like(forces), where=weights[:, None] > 0)


def facet_moments(fem: FEModel, lumped: np.ndarray, on: np.ndarray) -> np.ndarray:
    """∫_E ψ_a g_i (d vertices of E in ``mesh.facets`` order, d, nfacets) on the boundary facets: g the applied
    traction (constant on each flat facet) and, on the contact facets ``on``, the lumped contact traction
    t_a = F_a / w_a near each node a (``lumped`` (vertices, d)): the moment |E| t_a / d, whose sum over a's facets is
    the nodal force F_a."""
    mesh = fem.mesh
    d = fem.dim
    out = np.zeros((d, d, mesh.nfacets))
    facets = mesh.boundary_facets()
    normal = facet_normals(mesh, facets)  # |E| times the unit normal
    measure = np.linalg.norm(normal, axis=0)
    normal /= measure
    inward = mesh.p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1) - mesh.p[:, mesh.facets[0, facets]]
    normal *= np.where((normal * inward).sum(axis=0) > 0, -1.0, 1.0)
    # one point per flat facet is all applied_traction reads of a basis (a scikit-fem FacetBasis costs more)
    points = SimpleNamespace(find=facets, normals=normal[:, :, None], dx=np.empty((facets.size, 1)))
    out[:, :, facets] = measure / d * applied_traction(fem, points)[None, :, :, 0]
    out[:, :, on] = (facet_measures(mesh, on) / d)[None, None] * lumped[mesh.facets[:, on]].transpose(0, 2, 1)
    return out


def facet_normals(mesh, facets: np.ndarray) -> np.ndarray:
    """A normal of each facet (x, facets), of length the facet's measure (length, area), either orientation."""
    ends = mesh.p[:, mesh.facets[:, facets]]  # (x, vertex, facets)
    if mesh.p.shape[0] == 2:
        edge = ends[:, 1] - ends[:, 0]
        return np.stack([edge[1], -edge[0]])
    return 0.5 * np.cross(ends[:, 1] - ends[:, 0], ends[:, 2] - ends[:, 0], axis=0)


def facet_measures(mesh, facets: np.ndarray) -> np.ndarray:
    """Length (2-D) or area (3-D) of each facet."""
    return np.linalg.norm(facet_normals(mesh, facets), axis=0)


KORN = np.sqrt(2.0)
"""Korn's constant C_K (‖∇v‖ ≤ C_K ‖ε(v)‖) the reported bound assumes: √2, exact for v vanishing on the whole
boundary; a body held on a part of its boundary has a larger, unknown one (docs/estimate.md)."""

TERMS = ("equilibrated", "asymmetry", "complementarity", "friction", "penetration")
"""The kinds of terms of the equilibrated estimate (docs/estimate.md)."""


@dataclass(frozen=True)
class FluxEstimate:
    """The equilibrated-flux estimate of one P1 solution (triangles, tetrahedra), scaled energy units.

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
    and 2μ |E|⁻¹ ‖(u_N,h − g)_+‖²_E (the vertex rule on the facet's d nodes: exact for the linear opening); zero on
    the facets of a pair's slave side with a node left out (no row, so no gap or slip: indexed as −1, such a node read
    the last row's values, on the P1 spheres' first level the one closed row's opening 0)."""
    mesh, contact = fem.mesh, fem.contact
    ends = mesh.facets[:, contact.facets]  # (d, facets) vertices
    node = np.full(mesh.nvertices, -1)
    node[contact.dofs[:, 0] // fem.dim] = np.arange(contact.dofs.shape[0])
    rows = (node[ends] >= 0).all(axis=0)
    out = {name: np.zeros(contact.facets.size) for name in TERMS[2:]}
    facets, ends = contact.facets[rows], ends[:, rows]
    measure = facet_measures(mesh, facets)
    d = fem.dim
    traction = lumped[ends].mean(axis=0)  # (facets, d)
    normal = contact.normals[node[ends]].mean(axis=0)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    pressure = -(traction * normal).sum(axis=1)
    if state.constrained:
        opening = (state.gap - state.normal_displacement)[node[ends]]  # (d, facets)
        out["complementarity"][rows] = np.maximum(pressure * measure * opening.mean(axis=0), 0.0)
        out["penetration"][rows] = (2.0 * fem.lame[1][mesh.f2t[0, facets]] / d
                                    * (np.maximum(-opening, 0.0) ** 2).sum(axis=0))
    if state.slip is not None:
        tangential = traction + pressure[:, None] * normal
        slip = state.slip[node[ends]]  # (d, facets, d)
        slip = slip - (slip * normal).sum(axis=2)[..., None] * normal
        out["friction"][rows] = measure / d * (np.linalg.norm(tangential, axis=1) * np.linalg.norm(slip, axis=2)
                                               + (tangential * slip).sum(axis=2)).sum(axis=0)
    return out


def flux_estimate(fem: FEModel, u: np.ndarray, state: ContactState) -> FluxEstimate:
    """The equilibrated-flux estimate of the full (scaled) P1 displacement ``u`` under the contact ``state``; for a
    pair of bodies (mortar or node to segment) each body's traction on its contact side is the datum, and the
    complementarity and friction terms are the slave side's (relative gap and slip)."""
    return bound(fem, u, state, equilibrate)


def bound(fem: FEModel, u: np.ndarray, state: ContactState, equilibrate) -> FluxEstimate:
    """:class:`FluxEstimate` of ``u`` with the stress ``equilibrate(fem, u_components, facet_moments, held)``
    reconstructs (:func:`equilibrate` on triangles, :func:`.flux3d.equilibrate` on tetrahedra)."""
    # BLAS on one thread: the work is shared out by flux_correction.parallel, and OpenBLAS's own threads, spinning
    # after each of its dot products, took the CPU from it (quiet, 10⁵ DOFs, a first call with the default threads:
    # strip 100 : 1 0.53 → 0.42 of a linear solve, the pair 0.48 → 0.37; docs/estimate.md, "Fewer correction steps")
    with blas.limited(1):
        return _bound(fem, u, state, equilibrate)


def _bound(fem: FEModel, u: np.ndarray, state: ContactState, equilibrate) -> FluxEstimate:
    mesh = fem.mesh
    on = contact_facets(fem)
    lumped = lumped_traction(fem, state, on)
    held = np.zeros((fem.dim, mesh.nfacets), dtype=bool)
    boundary = mesh.boundary_facets()
    held[:, boundary] = held_components(fem, boundary)
    moments = facet_moments(fem, lumped, on)
    # the contact terms and ‖u_h‖²_E on a second thread while this one reconstructs the stress
    stress, (per_facet, energy) = flux_correction.parallel(lambda task: task(), [
        lambda: equilibrate(fem, components(fem, u), moments, held),
        lambda: (contact_terms(fem, state, lumped), float(u @ (fem.K_full @ u)))], mesh.nelements)
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
    return FluxEstimate(indicators, {name: float(parts[name].sum()) for name in TERMS}, energy, float(eta),
                        stress.defect)
