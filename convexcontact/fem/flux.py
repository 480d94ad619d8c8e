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
from . import flux_correction
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


def cell_geometry(mesh):
    """Vertex coordinates (cells, 3, 2), areas (cells,) and the barycentric gradients (cells, 3, 2)."""
    corners = mesh.p[:, mesh.t].transpose(2, 1, 0)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    grads = np.empty_like(corners)
    # ∇λ_k = rot(opposite edge) / det, oriented by the sign of det
    for k in range(3):
        a, b = corners[:, (k + 1) % 3], corners[:, (k + 2) % 3]
        grads[:, k, 0], grads[:, k, 1] = (a[:, 1] - b[:, 1]) / det, (b[:, 0] - a[:, 0]) / det
    return corners, 0.5 * np.abs(det), grads


def opposite_facets(mesh) -> np.ndarray:
    """(cells, 3): the facet of each cell opposite its local vertex k (scikit-fem numbers a triangle's facets
    (v0 v1), (v1 v2), (v0 v2): opposite v2, v0, v1; checked, and found by search where a mesh numbers otherwise)."""
    t, facets, edges = mesh.t, mesh.facets, mesh.t2f
    out = edges[[1, 2, 0]].T
    ends = facets[:, out]  # (2, cells, 3)
    if not ((ends != t.T[None]).all(axis=0)).all():
        for l in range(3):
            e = edges[l]
            for k in range(3):
                away = (facets[0, e] != t[k]) & (facets[1, e] != t[k])
                out[away, k] = e[away]
    return np.ascontiguousarray(out)


def elastic_stress(fem: FEModel, u_components: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """σ(u_h) per cell (cells, 2, 2) of the P1 displacement ``u_components`` (d, vertices)."""
    lam, mu = fem.lame
    nodal = u_components[:, fem.mesh.t].transpose(2, 0, 1)  # (cells, a, k)
    grad_u = (nodal[:, :, :, None] * grads[:, None]).sum(axis=2)  # (cells, a, x): Σ_k u_a(p_k) ∇λ_k
    strain = 0.5 * (grad_u + grad_u.transpose(0, 2, 1))
    trace = strain[:, 0, 0] + strain[:, 1, 1]
    return 2 * mu[:, None, None] * strain + (lam * trace)[:, None, None] * np.eye(2)


def patch_pairs(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The facet opposite each local vertex (cells, 3), the sign of its normal seen from the cell (outward +1), and
    the pair index 2E + side of (vertex j of the cell, facet opposite k) (cells, 3, 3): the flux of σ_a, a the vertex,
    through E along E's normal (outward of ``f2t[0]``)."""
    opposite = opposite_facets(mesh)
    sign = np.where(mesh.f2t[0, opposite] == np.arange(mesh.nelements)[:, None], 1.0, -1.0)
    pair = 2 * opposite[:, None, :] + (mesh.facets[1, opposite][:, None, :] == mesh.t.T[:, :, None])
    return opposite, sign, pair.astype(np.int32)  # 32-bit indices: half the memory traffic of the gathers


def propagate(first, second, s1, s2, rhs, known, values) -> None:
    """Solve the divergence constraints s1 x[first] + s2 x[second] = rhs of all patches at once, in place: each
    constraint with one of its two fluxes known gives the other, sweep after sweep along the chains of cells around
    each vertex (about half as many sweeps as the largest patch has cells). ``values`` (columns: right-hand sides) and
    ``known`` hold the seeds."""
    active = np.arange(first.size, dtype=np.int32)
    while active.size:
        f, g = first[active], second[active]
        known_f, known_g = known[f], known[g]
        forward, backward = known_f & ~known_g, known_g & ~known_f
        if not (forward.any() or backward.any()):
            return
        a, b = active[forward], active[backward]
        values[second[a]] = (rhs[a] - s1[a, None] * values[first[a]]) / s2[a, None]
        values[first[b]] = (rhs[b] - s2[b, None] * values[second[b]]) / s1[b, None]
        known[second[a]] = True
        known[first[b]] = True
        active = active[~(known_f & known_g | forward | backward)]  # constraints still waiting for a flux


def rt0_mass(corners: np.ndarray, area: np.ndarray) -> np.ndarray:
    """∫_T φ_k · φ_l (cells, 3, 3) of the RT0 functions φ_k = (x − p_k) / 2|T| (unit outward flux through the facet
    opposite vertex k). With x − p_k = Σ_m λ_m (p_m − p_k), ∫ λ_m λ_n = |T| (1 + δ_mn) / 12 and the vertices c_m taken
    from the centroid (Σ c_m = 0) it reduces to (Σ_m |c_m|² / 12 + c_k · c_l) / 4|T|."""
    centred = corners - corners.mean(axis=1, keepdims=True)
    gram = (centred[:, :, None, :] * centred[:, None, :, :]).sum(axis=3)  # c_m · c_n
    return (gram + (gram[:, 0, 0] + gram[:, 1, 1] + gram[:, 2, 2])[:, None, None] / 12.0) / (4.0 * area[:, None, None])


def equilibrate(fem: FEModel, u_components: np.ndarray, facet_moments: np.ndarray, held: np.ndarray) -> Equilibrated:
    """The equilibrated stress of the P1 displacement ``u_components`` (d, vertices).

    ``facet_moments`` (2, d, nfacets): ∫_E ψ_a g_i for the two vertices a of each boundary facet (``mesh.facets``
    order); ``held`` (d, nfacets) the components a Dirichlet condition prescribes on each boundary facet (their
    fluxes are free).

    In RT0 a patch problem is a chain of cells around its vertex, one divergence constraint per cell on the two
    fluxes through its facets at the vertex: the fluxes follow from one known flux (a Neumann facet) by propagation,
    and where none is known (interior and Dirichlet vertices) up to one free circulation, chosen to minimize the
    patch's share of σ̂ − σ_h (a scalar quadratic per patch, :func:`optimal_circulation`). No linear system is solved."""
    mesh = fem.mesh
    lam, mu = fem.lame
    corners, area, grads = cell_geometry(mesh)
    sigma_h = elastic_stress(fem, u_components, grads)
    body_force = np.asarray(fem.scene.body_force, dtype=float) * fem.scaling.length / fem.scaling.pressure
    opposite, sign, pair = patch_pairs(mesh)
    npairs, patch = 2 * mesh.nfacets, mesh.t.T  # patch[c, j]: the vertex whose patch (c, j) belongs to
    mass = rt0_mass(corners, area)
    # the two facets at vertex j of each cell: (c, j) → the pairs (j, facet k1) and (j, facet k2), k1, k2 ≠ j
    k1, k2 = np.array([1, 0, 0]), np.array([2, 2, 1])
    cells = np.arange(mesh.nelements)[:, None]
    first, second = pair[cells, np.arange(3), k1], pair[cells, np.arange(3), k2]
    s1, s2 = sign[:, k1], sign[:, k2]
    boundary = mesh.f2t[1] == -1
    # both rows at once: row i's pairs are offset by i·npairs
    rhs = -area[None, :, None] * (body_force[:, None, None] / 3.0 - against_rows(grads, sigma_h))
    known = np.zeros((2, npairs), dtype=bool)
    values = np.zeros((2, npairs, 2))  # a particular solution and the patch's circulation (where no flux is known)
    any_pair = np.empty(mesh.nvertices, dtype=np.int64)
    any_pair[patch.ravel()] = first.ravel()
    for i in range(2):
        neumann = np.flatnonzero(boundary & ~held[i])
        for side in range(2):
            known[i, 2 * neumann + side] = True
            values[i, 2 * neumann + side, 0] = facet_moments[side, i, neumann]
        # a seed per patch without a known flux: a Dirichlet facet's pair if it has one, else any pair of the patch
        has_known = np.zeros(mesh.nvertices, dtype=bool)
        has_known[mesh.facets[:, neumann].ravel()] = True
        dirichlet = np.flatnonzero(boundary & held[i])
        seed = any_pair.copy()
        seed[mesh.facets[:, dirichlet].ravel()] = np.concatenate([2 * dirichlet, 2 * dirichlet + 1])
        seeded = seed[~has_known]
        known[i, seeded] = True
        values[i, seeded, 1] = 1.0
    both = np.zeros((rhs.size, 2))
    both[:, 0] = rhs.ravel()
    flat_values = values.reshape(-1, 2)
    f, g = first.ravel(), second.ravel()
    propagate(np.concatenate([f, f + npairs]), np.concatenate([g, g + npairs]), np.tile(s1.ravel(), 2),
              np.tile(s2.ravel(), 2), both, known.ravel(), flat_values)
    values = flat_values.reshape(2, npairs, 2)
    x = optimal_circulation(values, first, second, s1, s2, mass, area, grads, sigma_h, mesh)
    flux = sign[None] * (x[:, 2 * opposite] + x[:, 2 * opposite + 1])  # outward flux of σ̂ row i (i, c, k)
    residual = flux.sum(axis=2) + area * body_force[:, None]  # ∫_T (div σ̂ + f)
    scale = np.abs(area[None] * body_force[:, None]).max() + np.abs(flux).max()
    defect = float(np.abs(residual).max() / scale) if scale > 0 else 0.0
    # σ̂ row i at vertex m: Σ_k F_k (p_m − p_k) / 2|T|
    vertex_stress = (flux.sum(axis=2)[:, None, :, None] * corners.transpose(2, 0, 1)[None]
                     - (flux[..., None] * corners[None]).sum(axis=2).transpose(0, 2, 1)[..., None]
                     ) / (2.0 * area[None, None, :, None])
    vertex_stress = flux_correction.corrected(vertex_stress, sigma_h, grads, area, fem.lame, mesh, opposite, held, KORN)
    symmetric, skew = cell_norms(vertex_stress, sigma_h, lam, mu, area)
    return Equilibrated(vertex_stress, symmetric, skew, defect)


def against_rows(vectors: np.ndarray, sigma_h: np.ndarray) -> np.ndarray:
    """(rows i, cells, 3): vectors (cells, 3, 2) dotted with row i of σ_h per cell (written out, as the other small
    contractions here are broadcast sums: einsum's generic loop, and matmul's on stacks of 3 × 2 matrices, took a
    third of the estimate's time)."""
    return np.stack([vectors[..., 0] * sigma_h[:, i, None, 0] + vectors[..., 1] * sigma_h[:, i, None, 1]
                     for i in range(2)])


def optimal_circulation(values, first, second, s1, s2, mass, area, grads, sigma_h, mesh) -> np.ndarray:
    """The fluxes x (rows, pairs) = particular + c circulation (``values`` (rows, pairs, 2)), c minimizing per row
    and patch Σ_T ‖σ_a − w_a‖²_T over the patch's two fluxes k = k1, k2 at its vertex a in each cell (``first``,
    ``second``: their pairs, (cells, j)); w_a the cellwise RT0 interpolant of ψ_a σ_h,i, fluxes ∫_E ψ_a σ_h,i|_T · n
    = −|T| σ_h,i · ∇λ_k through the facets E ∋ a. Σ_a w_a = σ_h cell by cell, so σ̂ − σ_h = Σ_a (σ_a − w_a): each
    patch minimizes its own share, and a stress σ_h constant over a patch is reproduced exactly on any mesh (the
    textbook target ψ_a σ_h is not in RT0, and its projection leaves a circulation that does not vanish on graded or
    locally refined meshes: η / ‖σ_h‖ ≈ 10 % for a constant stress on the graded punch mesh, docs/estimate.md)."""
    k, l = np.array([1, 0, 0]), np.array([2, 2, 1])
    xk, xl = values[:, first] * s1[..., None], values[:, second] * s2[..., None]  # (rows, c, j, 2 columns)
    mkk, mkl, mll = mass[:, k, k, None], mass[:, k, l, None], mass[:, l, l, None]
    qk, ql = mkk * xk + mkl * xl, mkl * xk + mll * xl  # Q applied to both columns
    wk = -area[None, :, None] * against_rows(grads[:, k], sigma_h)  # (rows, c, j): w_a's outward fluxes
    wl = -area[None, :, None] * against_rows(grads[:, l], sigma_h)
    load_k = mkk[..., 0] * wk + mkl[..., 0] * wl
    load_l = mkl[..., 0] * wk + mll[..., 0] * wl
    h_k, h_l = xk[..., 1], xl[..., 1]
    nv = mesh.nvertices
    patch = (mesh.t.T[None] + np.array([0, nv])[:, None, None]).ravel()  # (row, cell, j) → row · nv + vertex
    curvature = np.bincount(patch, (h_k * qk[..., 1] + h_l * ql[..., 1]).ravel(), 2 * nv)
    slope = np.bincount(patch, (h_k * (qk[..., 0] - load_k) + h_l * (ql[..., 0] - load_l)).ravel(), 2 * nv)
    circulation = (-slope / np.where(curvature > 0, curvature, np.inf)).reshape(2, nv)
    owner = mesh.facets.T.ravel()  # pair 2E + side belongs to the patch of vertex facets[side, E]
    return values[..., 0] + circulation[:, owner] * values[..., 1]


def cell_norms(vertex_stress, sigma_h, lam, mu, area):
    """‖C^{-½}(sym σ̂ − σ_h)‖²_T and ‖(2μ)^{-½} skew σ̂‖²_T per cell, by the facet-midpoint rule (exact: the integrands
    are quadratic), component by component."""
    mid = 0.5 * (vertex_stress + vertex_stress[..., [1, 2, 0]])  # (i, x, c, 3 midpoints)
    a, d = mid[0, 0] - sigma_h[:, 0, 0, None], mid[1, 1] - sigma_h[:, 1, 1, None]
    b = 0.5 * (mid[0, 1] + mid[1, 0]) - sigma_h[:, 0, 1, None]
    w = 0.5 * (mid[0, 1] - mid[1, 0])
    # C⁻¹τ : τ = (|τ|² − λ/(2μ + 2λ) (tr τ)²) / 2μ for σ = 2με + λ tr ε I in 2-D
    energy = (a * a + d * d + 2 * b * b).sum(axis=1) - lam / (2 * mu + 2 * lam) * ((a + d) ** 2).sum(axis=1)
    return area * energy / (6 * mu), area * 2 * (w * w).sum(axis=1) / (6 * mu)


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
