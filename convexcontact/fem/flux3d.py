"""The equilibrated stress (Prager–Synge) of :mod:`.flux` on 3-D P1 tetrahedra: the same patch problems, in RT0 on the
patch ω_a of each vertex a, row by row of the stress (docs/estimate.md, "The equilibrated bound on P1 tetrahedra")::

    σ_a = argmin ‖σ − w_a‖_{ω_a}   over RT0(ω_a), row i (w_a the cellwise RT0 interpolant of ψ_a σ_h,i), with
          ∫_T div σ = ∫_T (∇ψ_a · σ_h,i − ψ_a f_i)   on each cell T of ω_a,
          ∫_E σ n = ∫_E ψ_a g_i     on the facets E ∋ a of Γ_N and Γ_C (g_i the applied or the lumped contact traction),
          σ n = 0 on ∂ω_a inside the body, free on the facets where component i is held (Dirichlet).

A pair of bodies is one mesh whose bodies share no vertex, so no patch spans both: each body's contact side takes
its own lumped traction as the datum (the master's from the forces the mortar coupling transfers), as in 2-D
(:func:`.flux.bound`; docs/estimate.md, "The equilibrated bound on pairs of P1 tetrahedra").

In 3-D a patch is a graph of cells and facets, not a chain: its unknowns are the fluxes through the facets that
contain a (the facet of a cell opposite a lies on ∂ω_a), one divergence constraint per cell. Each patch is an
equality-constrained least-squares problem, solved through its KKT system

    [ A  Cᵀ ] [x]   [b]        A = Σ_T B_Tᵀ M_T B_T (M_T the RT0 mass matrix of T's three facets at a),
    [ C  0  ] [λ] = [r],       C: the cells' divergence rows and the prescribed boundary fluxes.

Where no flux at a is free (interior vertices, and vertices whose boundary facets are all prescribed for row i) the
cells' rows sum to the data and one of them is redundant: it is dropped (its cell then carries the data's
incompatibility, round-off for the exact discrete solution: the ``defect``). The boundary rows of held facets and
the dropped cell's row are kept as rows of the identity, so the systems' shapes depend on the mesh only, not on the
row i or the Dirichlet conditions.

All patches are solved in stacks of equal size by LAPACK (``np.linalg.solve``): 2.0–3.2 s for the 4,913 patches × 3
rows of a 13,328-DOF mesh, against 11.1 s for the same systems as one block-diagonal sparse KKT per row factored by
SuperLU and 18.9 s by PARDISO (off by 10⁻⁶: its pivot perturbation on the indefinite KKT; docs/estimate.md, "The
equilibrated bound on P1 tetrahedra"). The systems are assembled by hand from the cells' corners (a scikit-fem RT0 form per patch would be one
Python call per patch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arrays import group_ranks
from .assembly import FEModel
from .estimate import ContactState, scaled_body_force
from .flux import (
    Equilibrated,
    FluxEstimate,
    bound,
    cell_norms,
    elastic_stress,
    equilibrium_defect,
    opposite_facets,
    vertex_values,
)

CHUNK = 1024
"""Patches per stacked solve: its dense systems (rows × patches × n² doubles, n ≈ 60 on a uniform mesh) stay near
0.1 GB; 256 to 4,096 cost the same (0.47 s CPU for the whole bound at 13,328 DOFs)."""


def supported(fem: FEModel) -> bool:
    """The reconstruction covers 3-D P1 tetrahedra, one body or a pair (each body's contact side its own datum)."""
    return fem.dim == 3 and fem.scene.body.element == "P1" and fem.mesh.t.shape[0] == 4


def flux_estimate(fem: FEModel, u: np.ndarray, state: ContactState) -> FluxEstimate:
    """The equilibrated-flux bound of the full (scaled) P1 displacement ``u`` under the contact ``state``, one body or
    a pair (:func:`.flux.bound` with :func:`equilibrate`)."""
    return bound(fem, u, state, equilibrate)


def tetrahedra(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex coordinates (x, k, cells), 6 × the signed volumes (cells,) and the barycentric gradients ∇λ_k
    (x, k, cells): those of k = 1, 2, 3 are the rows of the inverse Jacobian of x = p_0 + Σ_k λ_k (p_k − p_0)."""
    xyz = np.take(mesh.p, mesh.t, axis=1)
    jacobian = (xyz[:, 1:] - xyz[:, :1]).transpose(2, 0, 1)  # (cells, x, k)
    det = np.linalg.det(jacobian)
    if not np.all(np.abs(det) > 0):
        raise ValueError("mesh: a tetrahedron has no volume (flat or repeated vertices); check the mesh (skfem's "
                         "Mesh.is_valid(), or a fresh one from the geometry)")
    grads = np.empty_like(xyz)
    grads[:, 1:] = np.linalg.inv(jacobian).transpose(2, 1, 0)
    grads[:, 0] = -grads[:, 1:].sum(axis=1)
    return xyz, det, grads


def rt0_mass(xyz: np.ndarray, volume: np.ndarray) -> np.ndarray:
    """M_jl = ∫_T φ_j · φ_l (j, l, cells) of the RT0 functions φ_j = (x − p_j) / 3|T| (unit outward flux through
    the facet opposite p_j): (Σ_m |c_m|² / 20 + c_j · c_l) / 9|T|, c the vertices from the centroid (∫_T |x − x_T|²
    = |T| Σ_m |c_m|² / 20)."""
    centred = xyz - xyz.mean(axis=1, keepdims=True)
    spread = (centred**2).sum(axis=(0, 1)) / 20.0
    return (np.einsum("xjc,xlc->jlc", centred, centred) + spread) / (9.0 * volume)


@dataclass(frozen=True)
class Patches:
    """The patch problems' layout. Corner (k, c): cell c in the patch of vertex t[k, c]; its slots s = 0, 1, 2 are
    its facets opposite the vertices ``SLOTS[k, s]`` = (k + 1 + s) mod 4, all three containing t[k, c].

    Per patch a: ``facets`` F_a (the facets ∋ a), ``cells`` T_a and ``boundary`` B_a (the boundary facets ∋ a) give
    the unknowns [x (F_a) | λ (T_a) | μ (B_a)], ``size`` n_a = F_a + T_a + B_a. Per corner: its ``cell`` row (local λ index) and per
    slot the local facet ``slot_facet`` and the ``sign`` of the facet's global normal (out of ``mesh.f2t[0]``) as seen
    from the cell. Per boundary pair (vertex ``boundary_vertex``, facet ``boundary_facet``): its local ``boundary_row``
    and facet column ``boundary_column``, and ``boundary_position`` of the vertex in ``mesh.facets``."""

    slot_facet: np.ndarray
    sign: np.ndarray
    cell: np.ndarray
    facets: np.ndarray
    cells: np.ndarray
    boundary: np.ndarray
    boundary_vertex: np.ndarray
    boundary_facet: np.ndarray
    boundary_position: np.ndarray
    boundary_row: np.ndarray
    boundary_column: np.ndarray

    @property
    def size(self) -> np.ndarray:
        return self.facets + self.cells + self.boundary


SLOTS = np.array([[(k + 1 + s) % 4 for s in range(3)] for k in range(4)])  # (k, s): the vertex opposite slot s


def ranks(keys: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The rank of each entry among the entries of equal key (keys in [0, count)), and the count per key."""
    return group_ranks(keys), np.bincount(keys, minlength=count)


def patches(mesh, opposite: np.ndarray) -> Patches:
    """:class:`Patches` of ``mesh`` (``opposite``: :func:`.flux.opposite_facets`)."""
    t, facets, nv, nf = mesh.t, mesh.facets, mesh.nvertices, mesh.nfacets
    ncells = t.shape[1]
    pair, facet_count = ranks(facets.ravel(), nv)  # (position m, facet) → local facet index in the patch of facets[m]
    cell, cell_count = ranks(t.ravel(), nv)
    facet = opposite.T[SLOTS]  # (k, s, cells)
    vertex = np.broadcast_to(t[:, None], facet.shape)
    position = np.argmax(facets[:, facet] == vertex, axis=0)
    slot_facet = pair[position * nf + facet]
    sign = np.where(mesh.f2t[0, facet] == np.arange(ncells), 1.0, -1.0)
    outside = np.flatnonzero(mesh.f2t[1] == -1)
    boundary_position = np.repeat(np.arange(3), outside.size)
    boundary_facet = np.tile(outside, 3)
    boundary_vertex = facets[boundary_position, boundary_facet]
    boundary_row, boundary_count = ranks(boundary_vertex, nv)
    return Patches(slot_facet, sign, cell.reshape(4, ncells), facet_count, cell_count, boundary_count,
                   boundary_vertex, boundary_facet, boundary_position, boundary_row,
                   pair[boundary_position * nf + boundary_facet])


def ordering(size: np.ndarray, shared: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The patches by ``shared``, then ``size`` (``order``), and each patch's first row in the flat vector of all
    unknowns (``offset``, per vertex)."""
    order = np.lexsort((size, shared))
    offset = np.empty(size.size, dtype=np.int64)
    offset[order] = np.concatenate([[0], np.cumsum(size[order])[:-1]])
    return order, offset


@dataclass(frozen=True)
class Systems:
    """The KKT systems' entries, local to each patch (rows and columns in [0, n_a)). Per corner (flat k · cells + c):
    the slots' facet rows ``facet`` (s, corners), the cell's row ``cell``, the A block ``mass`` (s, s', corners: the
    signed RT0 mass), the constraint's coefficients ``divergence`` (i, s, corners; the slots' signs, zero on a
    dropped row) and ``dropped`` (i, corners), the right-hand sides ``slot_rhs`` (i, s, corners) and ``cell_rhs``
    (i, corners). Per boundary pair: its ``boundary_row``, facet column ``boundary_column``, whether its flux is
    ``known`` (i, pairs) and its ``moment`` (i, pairs)."""

    facet: np.ndarray
    cell: np.ndarray
    mass: np.ndarray
    divergence: np.ndarray
    dropped: np.ndarray
    slot_rhs: np.ndarray
    cell_rhs: np.ndarray
    boundary_row: np.ndarray
    boundary_column: np.ndarray
    known: np.ndarray
    moment: np.ndarray


def systems(mesh, layout: Patches, mass: np.ndarray, target: np.ndarray, rhs: np.ndarray, moments: np.ndarray,
            held: np.ndarray) -> Systems:
    """:class:`Systems` of all patches: ``mass`` the cells' RT0 mass matrices (j, l, cells), ``target`` w's outward
    fluxes through the facets opposite k (i, k, cells), ``rhs`` the cells' divergence data per corner (i, k, cells),
    ``moments`` ∫_E ψ_a g_i (position of a in ``mesh.facets``, i, nfacets), ``held`` (i, nfacets).

    min ½ xᵀAx − bᵀx: per cell, z_s = sign_s x_s − target_{j_s} and ½ zᵀMz, so A gets sign_s sign_s' M_ss' and b
    sign_s Σ_s' M_ss' target_{j_s'}."""
    t = mesh.t
    cells = np.arange(t.shape[1])
    vertex = t.ravel()

    sign = layout.sign.transpose(1, 0, 2).reshape(3, -1)  # (s, corners)
    slot_mass = mass[SLOTS[:, :, None, None], SLOTS[:, None, :, None], cells].transpose(1, 2, 0, 3).reshape(3, 3, -1)
    slot_target = target[:, SLOTS[:, :, None], cells].transpose(0, 2, 1, 3).reshape(3, 3, -1)  # (i, s, corners)
    free = np.zeros((3, mesh.nvertices), dtype=bool)  # a free (held) boundary flux at the vertex, per row
    for i in range(3):
        free[i, layout.boundary_vertex[held[i, layout.boundary_facet]]] = True
    # a patch with no free flux for row i drops the row of its last cell
    dropped = ~free[:, vertex] & (layout.cell.ravel() == layout.cells[vertex] - 1)
    known = ~held[:, layout.boundary_facet]
    return Systems(layout.slot_facet.transpose(1, 0, 2).reshape(3, -1), layout.facets[vertex] + layout.cell.ravel(),
                   sign[:, None] * sign * slot_mass, np.where(dropped[:, None], 0.0, sign), dropped,
                   sign * np.einsum("stn,itn->isn", slot_mass, slot_target), np.where(dropped, 0.0, rhs.reshape(3, -1)),
                   layout.facets[layout.boundary_vertex] + layout.cells[layout.boundary_vertex] + layout.boundary_row,
                   layout.boundary_column, known,
                   np.where(known, moments[layout.boundary_position, :, layout.boundary_facet].T, 0.0))


def chunk_system(system: Systems, corners: np.ndarray, patch: np.ndarray, pairs: np.ndarray, pair_patch: np.ndarray,
                 count: int, n: int, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """The dense KKT matrices (rows, count, n, n) and right-hand sides (3, count, n) of ``count`` patches of size n:
    their ``corners`` and boundary ``pairs``, each with its patch in the chunk (``patch``, ``pair_patch``); ``rows``
    1 where the three rows share the matrix."""
    facet, cell = system.facet[:, corners], system.cell[corners]
    facet_row = patch * n + facet  # (s, corners): the row in the chunk's stacked rows
    cell_row = patch * n + cell
    boundary_row = pair_patch * n + system.boundary_row[pairs]
    boundary_column = system.boundary_column[pairs]
    column_row = pair_patch * n + boundary_column
    index = np.concatenate([(facet_row[:, None] * n + facet).ravel(), (cell_row * n + facet).ravel(),
                            (facet_row * n + cell).ravel(), cell_row * n + cell, boundary_row * n + boundary_column,
                            column_row * n + system.boundary_row[pairs], boundary_row * n + system.boundary_row[pairs]])
    stride = count * n * n
    dense = np.empty((rows, stride))
    for i in range(rows):
        divergence = system.divergence[i][:, corners].ravel()
        known = system.known[i, pairs]
        values = np.concatenate([system.mass[:, :, corners].ravel(), divergence, divergence,
                                 system.dropped[i, corners], known, known, ~known])
        dense[i] = np.bincount(index, values, minlength=stride)
    right = np.zeros((3, count * n))
    for i in range(3):
        right[i] = np.bincount(facet_row.ravel(), system.slot_rhs[i][:, corners].ravel(), minlength=count * n)
    right[:, cell_row] = system.cell_rhs[:, corners]
    right[:, boundary_row] = system.moment[:, pairs]
    return dense.reshape(rows, count, n, n), right.reshape(3, count, n)


def solve_patches(mesh, layout: Patches, system: Systems, shared: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The flat solution (i, unknowns) of every patch's KKT system and each patch's ``offset`` in it. Patches of one
    size are stacked (``CHUNK`` at a time) and solved by ``np.linalg.solve`` (LU on each); a ``shared`` patch (no held
    facet at its vertex) has one matrix for the three rows, factored once for three right-hand sides."""
    size = layout.size
    order, offset = ordering(size, shared)
    rank = np.empty(size.size, dtype=np.int64)
    rank[order] = np.arange(size.size)
    corner_rank, pair_rank = rank[mesh.t.ravel()], rank[layout.boundary_vertex]
    corners, pairs = np.argsort(corner_rank, kind="stable"), np.argsort(pair_rank, kind="stable")
    corner_start = np.searchsorted(corner_rank[corners], np.arange(size.size + 1))
    pair_start = np.searchsorted(pair_rank[pairs], np.arange(size.size + 1))
    size, shared, start = size[order], shared[order], offset[order]
    out = np.empty((3, size.sum()))
    bounds = np.flatnonzero((np.diff(size) != 0) | (np.diff(shared) != 0)) + 1
    for lo, hi in zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [size.size]])):
        n = int(size[lo])
        for first in range(lo, hi, CHUNK):
            last = min(first + CHUNK, hi)
            chunk_corners = corners[corner_start[first]:corner_start[last]]
            chunk_pairs = pairs[pair_start[first]:pair_start[last]]
            dense, right = chunk_system(system, chunk_corners, corner_rank[chunk_corners] - first, chunk_pairs,
                                        pair_rank[chunk_pairs] - first, last - first, n, 1 if shared[lo] else 3)
            span = slice(start[first], start[first] + (last - first) * n)
            if shared[lo]:
                out[:, span] = np.linalg.solve(dense[0], right.transpose(1, 2, 0)).transpose(2, 0, 1).reshape(3, -1)
            else:
                out[:, span] = np.linalg.solve(dense, right[..., None]).reshape(3, -1)
    return out, offset


def equilibrate(fem: FEModel, u_components: np.ndarray, facet_moments: np.ndarray, held: np.ndarray) -> Equilibrated:
    """The equilibrated stress of the P1 displacement ``u_components`` (3, vertices) on tetrahedra; ``facet_moments``
    (3, 3, nfacets) ∫_E ψ_a g_i for the three vertices a of each boundary facet (``mesh.facets`` order), ``held``
    (3, nfacets) the components a Dirichlet condition prescribes on each boundary facet (their fluxes are free).

    The target w_a is the cellwise RT0 interpolant of ψ_a σ_h,i, whose outward flux through the facet of T opposite
    p_j ∋ a is −|T| σ_h,i · ∇λ_j: Σ_a w_a = σ_h cell by cell, so each patch minimizes its own share of σ̂ − σ_h and
    a stress constant over a patch is reproduced exactly (as in 2-D, :func:`.flux.equilibrate`)."""
    mesh = fem.mesh
    lam, mu = fem.lame
    xyz, det, gradients = tetrahedra(mesh)
    volume = np.abs(det) / 6.0
    sigma_h = elastic_stress(fem, u_components, gradients)
    body_force = scaled_body_force(fem)
    opposite = opposite_facets(mesh)
    layout = patches(mesh, opposite)
    target = -volume * np.einsum("cix,xkc->ikc", sigma_h, gradients)  # (i, k, cells)
    # ∫_T (∇ψ_a · σ_h,i − ψ_a f_i) at corner k: −target_k − |T| f_i / 4
    rhs = -target - (volume / 4.0) * body_force[:, None, None]
    shared = np.ones(mesh.nvertices, dtype=bool)
    shared[layout.boundary_vertex[held[:, layout.boundary_facet].any(axis=0)]] = False
    system = systems(mesh, layout, rt0_mass(xyz, volume), target, rhs, facet_moments, held)
    solution, offset = solve_patches(mesh, layout, system, shared)
    base = offset[mesh.t][:, None] + layout.slot_facet  # (k, s, cells)
    flux = np.zeros((3, 4, mesh.nelements))  # the outward flux of σ̂ row i through the facet opposite j (i, j, cells)
    for k in range(4):
        for s in range(3):
            flux[:, SLOTS[k, s]] += layout.sign[k, s] * solution[:, base[k, s]]
    vertex_stress = vertex_values(flux, xyz, volume)
    symmetric, skew = cell_norms(vertex_stress, sigma_h, lam, mu, volume)
    return Equilibrated(vertex_stress, symmetric, skew, equilibrium_defect(flux, volume, body_force))
