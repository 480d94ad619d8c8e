"""A residual a-posteriori estimate of the energy-norm discretization error, contact-aware (Hild–Nicaise).

For a body against a rigid obstacle or a pair of bodies, any element (the residual terms are element-agnostic), in
scaled units. Per cell T, with σ = σ(u_h), h the cell (facet) size, μ_T the shear
modulus, t_h the contact traction the discrete problem holds and g_N the applied traction::

    η_T² = (1/2μ_T) [ h_T² ‖f + div σ‖²_T                                   interior
                      + ½ Σ_{E ⊂ ∂T interior} h_E ‖[σ n]‖²_E                 jump
                      + Σ_{E ⊂ ∂T ∩ Γ_N} h_E ‖σ n − g_N‖²_E                  neumann
                      + Σ_{E ⊂ ∂T ∩ Γ_C} h_E ‖σ n − t_h‖²_E ]                contact (normal and tangential)
           + Σ_{E ⊂ ∂T ∩ Γ_C} (∫_E p_h (g − u_N,h))_+                       complementarity
           + Σ_{E ⊂ ∂T ∩ Γ_C} 2μ_T h_E⁻¹ ‖(u_N,h − g)_+‖²_E                  penetration
           + Σ_{E ⊂ ∂T ∩ Γ_C} ∫_E (|t_T,h| |v_T,h| + t_T,h · v_T,h)           friction (slip against the traction)

Components of σ n held by a Dirichlet condition are left out (they are reactions). The contact
traction is the field of the trace space whose moments are the discrete nodal contact forces F
(t_h = Σ τ_i ψ_i with M τ = F, M the boundary mass of Γ_C): the same for lumped, weak (Hild's P1) and
Gauss-point multipliers, and with it the residual vanishes on the discrete test functions. p_h = −t_h·n
is the pressure, g and u_N,h the trace-space interpolants of the nodal gap and normal displacement,
v_T,h the slip. For a pair the contact term runs over both sides of Γ_C, each against its own traction (the master's
from the forces the mortar coupling transfers to its nodes), and the other contact terms over the slave side with
the pair's own discrete gap and relative slip. The complementarity term is signed on each facet: its sum over Γ_C is the discrete complementarity
λᵀC(g − u_N), zero for the exact discrete solution. The obstacle's own interpolation error (g − g_h, O(h²) for a smooth obstacle) is not
included. The 1/2μ weights put the residual terms in energy units (‖u − u_h‖² ≤ C/(2μ) ‖residual‖²
by Korn's inequality).

Reliability holds up to a constant the theory does not give (Hild & Nicaise, M2AN 41, 2007): η is an
estimate, not a guaranteed bound. Its measured effectivity is in docs/estimate.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe
from scipy.sparse.linalg import splu
from skfem.assembly import Dofs

from ..scene.description import Dirichlet
from ..scene.meshing import check_boundary
from .assembly import FEModel, check_length
from .assembly import stress as elastic_stress

TERMS = ("interior", "jump", "neumann", "contact", "complementarity", "penetration", "friction")
"""The kinds of terms of η², in the order of the module's formula."""


@dataclass(frozen=True)
class ErrorEstimate:
    """The residual estimate of one solution, scaled energy units (squares: η² = Σ_T η_T²).

    ``indicators`` η_T² per cell; ``terms`` each kind's sum over the cells (:data:`TERMS`; they add up to η²);
    ``energy`` ‖u_h‖²_E = uᵀKu of the solution.
    """

    indicators: np.ndarray
    terms: dict[str, float]
    energy: float

    @property
    def eta(self) -> float:
        return float(np.sqrt(self.indicators.sum()))

    @property
    def relative(self) -> float:
        """η / ‖u_h‖_E (inf for a zero solution with a nonzero residual, 0 for both zero)."""
        if self.energy > 0:
            return self.eta / np.sqrt(self.energy)
        return 0.0 if self.eta == 0 else np.inf


@dataclass(frozen=True)
class ContactState:
    """The discrete contact state at the m nodes of Γ_C (scaled units): nodal contact ``forces`` on the body
    (m, d), ``normal_displacement`` u_N, ``gap`` g (at the obstacle's final position) and the ``slip`` v_T
    relative to the obstacle as vectors (m, d; None without friction)."""

    forces: np.ndarray
    normal_displacement: np.ndarray
    gap: np.ndarray
    slip: np.ndarray | None = None
    constrained: bool = True  # non-penetration (False: normal compliance, no complementarity)
    gap_at_nodes: bool = True  # the discrete constraint rows weigh the nodal gap (nodal, weak); False at Gauss points
    nodal_friction: bool = True  # the discrete friction law holds node by node (lumped, not weak or Gauss)
    master_forces: np.ndarray | None = None  # a pair's forces on its master nodes (mortar: transferred), (n, d)


def components(fem: FEModel, u: np.ndarray) -> np.ndarray:
    """(d, scalar DOFs): scikit-fem's vector DOF d·s + a is component a of scalar DOF s."""
    return u.reshape(-1, fem.dim).T


def interpolate(basis: fe.AbstractBasis, nodal: np.ndarray, field: str = "value") -> np.ndarray:
    """Σ_j nodal[..., dof_j] φ_j at the basis' quadrature points, (..., elements, points); ``field`` "grad": ∇φ_j,
    (..., d, elements, points). scikit-fem's ``interpolate`` sums the same terms in the same order, but computes the
    values with the gradients and first an np.unique of all the basis' element DOFs, on every call: a quarter of the
    estimate's time at 10⁵ P2 DOFs."""
    out = 0.0
    for j in range(basis.Nbfun):
        shape = basis.basis[j][0]  # a DiscreteField: the values, with .grad
        coefficients = np.take(nodal, basis.element_dofs[j], axis=-1)[..., None]
        if field == "grad":
            out = out + coefficients[..., None, :, :] * shape.grad
        else:
            out = out + coefficients * np.asarray(shape)
    return out


def gradient(basis: fe.AbstractBasis, u_components: np.ndarray) -> np.ndarray:
    """∇u at the basis' quadrature points, (d, d, elements, points): [a, k] = ∂_k u_a."""
    return interpolate(basis, u_components, "grad")


def stress(grad_u: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """σ from ∇u (d, d, elements, points) with the model's law (:func:`.assembly.stress`), Lamé parameters per
    element."""
    return elastic_stress(lam[:, None], mu[:, None])(0.5 * (grad_u + grad_u.transpose(1, 0, 2, 3)))


CHUNK = 50_000
"""Cells or facets integrated at once: bounds the memory of the shape functions at the quadrature points (Q2
hexahedra: 27 functions, value and gradient, at 9 points of each facet)."""

ORDER = {"P1": 1, "Q1": 1, "P2": 2, "Q2": 2}
"""Polynomial order per variable of each element: σ(u_h) has at most this degree per variable and its squares twice
it, the quadrature order of every term (scikit-fem's default comes from the total degree: 12 for Q2 hexahedra)."""


def chunks(indices: np.ndarray):
    for start in range(0, indices.size, CHUNK):
        yield indices[start:start + CHUNK]


def scalar_space(fem: FEModel) -> dict:
    """Keyword arguments of scikit-fem's bases for the scalar element of ``fem``: its DOFs (numbered once), the
    quadrature order, no DOF locations."""
    elem = fem.basis.elem.elem
    return {"elem": elem, "dofs": Dofs(fem.mesh, elem), "disable_doflocs": True,
            "intorder": 2 * ORDER[fem.scene.body.element]}


def stress_divergence(fem: FEModel, space: dict, cells: fe.CellBasis, u_components: np.ndarray) -> np.ndarray:
    """div σ(u_h) at the quadrature points of ``cells`` (d, elements, points).

    scikit-fem's Lagrange elements give no second derivatives. On affine cells (and on the tensor meshes'
    rectangles) σ(u_h) lies in the element's broken space, so its values at the element's reference nodes
    interpolate it exactly and the shape functions' gradients give its divergence."""
    elem = space["elem"]
    if elem.maxdeg == 1:  # P1: σ is constant per cell
        return np.zeros((fem.dim, *cells.dx.shape))
    nodes = fe.CellBasis(fem.mesh, elem, elements=cells.tind, dofs=space["dofs"], disable_doflocs=True,
                         quadrature=(elem.doflocs.T, np.ones(elem.doflocs.shape[0])))
    lam, mu = fem.lame
    sigma = stress(gradient(nodes, u_components), lam[cells.tind], mu[cells.tind])  # (d, d, elements, nodes)
    shape_gradients = np.stack([cells.basis[j][0].grad for j in range(cells.Nbfun)])  # (nodes, d, elements, points)
    return np.einsum("akej,jkep->aep", sigma, shape_gradients)


def scaled_body_force(fem: FEModel) -> np.ndarray:
    """The body force per unit volume in scaled units, one entry per dimension (a scene's default (0, 0) is zero in
    3-D too)."""
    force = np.zeros(fem.dim)
    if any(fem.scene.body_force):
        force[:] = np.asarray(fem.scene.body_force, dtype=float) * fem.scaling.length / fem.scaling.pressure
    return force


def interior(fem: FEModel, space: dict, u_components: np.ndarray) -> np.ndarray:
    """h_T² ‖f + div σ‖²_T / 2μ_T per cell (f the body force)."""
    out = np.zeros(fem.mesh.nelements)
    body_force = scaled_body_force(fem)
    if space["elem"].maxdeg == 1 and not body_force.any():  # P1 without body force: nothing to integrate
        return out
    for chunk in chunks(np.arange(fem.mesh.nelements)):
        cells = fe.CellBasis(fem.mesh, elements=chunk, **space)
        residual = stress_divergence(fem, space, cells, u_components)
        if body_force.any():
            residual = residual + body_force[:, None, None]
        h = np.asarray(cells.mesh_parameters())
        out[chunk] = (h**2 * (residual**2).sum(axis=0) * cells.dx).sum(axis=1) / (2.0 * fem.lame[1][chunk])
    return out


def jumps(fem: FEModel, space: dict, u_components: np.ndarray) -> np.ndarray:
    """½ Σ h_E ‖[σ n]‖²_E per cell over its interior facets, each side weighted by its own 1/2μ."""
    lam, mu = fem.lame
    out = np.zeros(fem.mesh.nelements)
    for chunk in chunks(np.flatnonzero(fem.mesh.f2t[1] != -1)):
        sides = [fe.InteriorFacetBasis(fem.mesh, facets=chunk, side=side, **space) for side in (0, 1)]
        traction = [np.einsum("abep,bep->aep", stress(gradient(b, u_components), lam[b.tind], mu[b.tind]),
                              np.asarray(b.normals)) for b in sides]
        h = np.asarray(sides[0].mesh_parameters())
        per_facet = (h * ((traction[0] - traction[1]) ** 2).sum(axis=0) * sides[0].dx).sum(axis=1)
        for b in sides:
            np.add.at(out, b.tind, 0.5 * per_facet / (2.0 * mu[b.tind]))
    return out


def held_components(fem: FEModel, facets: np.ndarray) -> np.ndarray:
    """(d, facets) mask of the displacement components a Dirichlet condition prescribes on each facet."""
    held = np.zeros((fem.dim, facets.size), dtype=bool)
    position = {facet: i for i, facet in enumerate(facets)}
    for condition in fem.scene.dirichlet:
        on = [position[f] for f in check_boundary(fem.mesh, condition.boundary, "dirichlet.boundary") if f in position]
        for a, name in enumerate(Dirichlet.COMPONENTS[:fem.dim]):
            if getattr(condition, name) is not None:
                held[a, on] = True
    return held


def applied_traction(fem: FEModel, boundary: fe.FacetBasis) -> np.ndarray:
    """g_N (d, facets, points) of the scene's tractions on the boundary facets of ``boundary`` (scaled)."""
    out = np.zeros((fem.dim, *boundary.dx.shape))
    position = {facet: i for i, facet in enumerate(boundary.find)}
    for load in fem.scene.tractions:
        rows = [position[f] for f in check_boundary(fem.mesh, load.boundary, "traction.boundary")]
        if load.pressure is not None:
            out[:, rows] += -load.pressure / fem.scaling.pressure * np.asarray(boundary.normals)[:, rows]
        else:
            vector = check_length(load.vector, fem.dim, f"traction[{load.boundary}].vector")
            out[:, rows] += (vector / fem.scaling.pressure)[:, None, None]
    return out


def trace_field(fem: FEModel, nodal: np.ndarray) -> np.ndarray:
    """A field given at the contact nodes ((m,) or (m, d)) as scalar-DOF vectors ((N,) or (d, N)), zero elsewhere."""
    nodes = fem.contact.dofs[:, 0] // fem.dim
    count = fem.basis.N // fem.dim
    out = np.zeros((count,) if nodal.ndim == 1 else (nodal.shape[1], count))
    out[..., nodes] = nodal.T
    return out


def contact_facets(fem: FEModel) -> np.ndarray:
    """The facets whose traction is the contact's: Γ_C (a pair's slave side) and the master sides of pairs."""
    facets = [fem.contact.facets]
    contact = fem.scene.contact
    for pair in getattr(contact, "pairs", None) or (contact,):
        if getattr(pair, "master", ""):
            facets.append(check_boundary(fem.mesh, pair.master, "contact.master"))
    return np.unique(np.concatenate(facets))


def contact_forces(fem: FEModel, state: ContactState) -> np.ndarray:
    """The nodal contact forces (scalar DOFs, d) on both sides of the contact: the slave's (a body's against an
    obstacle) and, for a pair, the master's (mortar: the forces the mortar matrix transfers), zero elsewhere."""
    forces = np.zeros((fem.basis.N // fem.dim, fem.dim))
    np.add.at(forces, fem.contact.dofs[:, 0] // fem.dim, state.forces)
    if state.master_forces is not None:
        np.add.at(forces, fem.contact.master_dofs[:, 0] // fem.dim, state.master_forces)
    return forces


def contact_traction(fem: FEModel, space: dict, state: ContactState, facets: np.ndarray) -> np.ndarray:
    """τ (d, scalar DOFs) of the discrete contact traction t_h = Σ τ_i ψ_i on the contact ``facets``: M τ = F, M the
    consistent boundary mass of the facets' nodes and F the nodal contact forces on them (:func:`contact_forces`), so
    that ∫ t_h ψ_i = F_i and the residual vanishes on the discrete test functions. For a pair each side holds its own
    (the facets of the two bodies share no node: M is block diagonal); one body's M is its trace's ``mass``."""
    mass = fe.asm(fe.BilinearForm(lambda u, v, w: u * v), fe.FacetBasis(fem.mesh, facets=facets, **space)).tocsr()
    nodes = np.unique(fem.basis.get_dofs(facets).flatten() // fem.dim)  # (the others' rows hold round-off only)
    tau = np.zeros((fem.basis.N // fem.dim, fem.dim))
    tau[nodes] = splu(sp.csc_matrix(mass[nodes][:, nodes])).solve(np.ascontiguousarray(contact_forces(fem, state)[nodes]))
    return tau.T


def boundary_terms(fem: FEModel, space: dict, u_components: np.ndarray, state: ContactState) -> dict:
    """The Neumann, contact, complementarity, penetration and friction terms per cell; a pair's contact term on both
    sides (each against its own traction), the others on the slave side (the relative gap and slip)."""
    contact, (lam, mu) = fem.contact, fem.lame
    boundary = fe.FacetBasis(fem.mesh, facets=fem.mesh.boundary_facets(), **space)
    cell = boundary.tind
    on = contact_facets(fem)
    on_contact = np.isin(boundary.find, on)
    tau = contact_traction(fem, space, state, on)
    target = np.where(on_contact[None, :, None], interpolate(boundary, tau), applied_traction(fem, boundary))
    n = np.asarray(boundary.normals)
    residual = np.einsum("abep,bep->aep", stress(gradient(boundary, u_components), lam[cell], mu[cell]), n) - target
    residual = np.where(held_components(fem, boundary.find)[:, :, None], 0.0, residual)
    h = np.asarray(boundary.mesh_parameters())
    weighted = (h * (residual**2).sum(axis=0) * boundary.dx).sum(axis=1) / (2.0 * mu[cell])
    out = {name: np.zeros(fem.mesh.nelements) for name in TERMS[2:]}
    np.add.at(out["neumann"], cell[~on_contact], weighted[~on_contact])
    np.add.at(out["contact"], cell[on_contact], weighted[on_contact])

    facets = fe.FacetBasis(fem.mesh, facets=contact.facets, **space)
    cell, n, h = facets.tind, np.asarray(facets.normals), np.asarray(facets.mesh_parameters())
    # only on the facets whose nodes all carry contact rows: a pair leaves out the slave nodes the master does not
    # cover, and their zeros in the gap's and slip's interpolants are no discrete gap or slip (between two open P2
    # vertices a left-out edge node read as a penetration: 94 % of η² on two P2 spheres with Tresca). Where every
    # node of a facet holds a row, the interpolant of their 1s is 1 at every point (a partition of unity).
    rows = interpolate(facets, trace_field(fem, np.ones(contact.m)))
    dx = np.where(np.abs(rows - 1.0).max(axis=1, keepdims=True) < 1e-9, facets.dx, 0.0)
    traction = interpolate(facets, tau)
    pressure = -(traction * n).sum(axis=0)
    if state.constrained:
        opening = interpolate(facets, trace_field(fem, state.gap - state.normal_displacement))
        # signed on each facet (its sum over Γ_C is λᵀC(g − u_N), zero at the discrete complementarity), not the
        # pointwise (p_h)_+ (g − u_N,h)_+: P2 tetrahedra's weak multipliers oscillate (docs/estimate.md)
        np.add.at(out["complementarity"], cell, np.maximum((pressure * opening * dx).sum(axis=1), 0.0))
        np.add.at(out["penetration"], cell, 2.0 * mu[cell] * (np.maximum(-opening, 0.0) ** 2 / h * dx).sum(axis=1))
    if state.slip is not None:
        tangential = traction + pressure * n
        slip = interpolate(facets, trace_field(fem, state.slip))
        slip = slip - (slip * n).sum(axis=0) * n
        misdirected = np.linalg.norm(tangential, axis=0) * np.linalg.norm(slip, axis=0) + (tangential * slip).sum(axis=0)
        np.add.at(out["friction"], cell, (misdirected * dx).sum(axis=1))
    return out


def estimate(fem: FEModel, u: np.ndarray, state: ContactState) -> ErrorEstimate:
    """The residual estimate of the full (scaled) displacement ``u`` under the contact ``state``."""
    space = scalar_space(fem)
    u_components = components(fem, u)
    parts = {"interior": interior(fem, space, u_components), "jump": jumps(fem, space, u_components),
             **boundary_terms(fem, space, u_components, state)}
    indicators = sum(parts[name] for name in TERMS)
    return ErrorEstimate(indicators, {name: float(parts[name].sum()) for name in TERMS}, float(u @ (fem.K_full @ u)))


def algebraic_error(fem: FEModel, u: np.ndarray, state: ContactState) -> float:
    """An estimate of ‖u_h − u_h*‖_E, u_h* the exact discrete solution, from the discrete residuals (scaled).

    With K(u − u*) = r − Bᵀ(λ − λ*), ‖u − u*‖²_E ≤ ‖r‖²_{K⁻¹} + λᵀC(g − u_N) + λ*ᵀC(u_N − g)_+ (λ* ≥ 0,
    λ*ᵀC(u_N* − g) = 0). λᵀC(u_N − g) = F_N·(u_N − g) for rows that weigh the nodal gap (nodal, weak); the friction law
    held node by node adds Σ_i |F_T,i| |v_T,i| + F_T,i·v_T,i. ‖r‖²_{K⁻¹} is estimated by rᵀ diag(K)⁻¹ r (no solve) and
    the penetration term is left to the certificate: an estimate, not a bound. Gauss-point rows (their gap lives at
    the points) and weak or Gauss friction contribute their equilibrium residual only.
    """
    contact = fem.contact
    forces = np.zeros(fem.basis.N)
    forces[contact.dofs.ravel()] = state.forces.ravel()
    if state.master_forces is not None:
        forces[contact.master_dofs.ravel()] += state.master_forces.ravel()
    residual = (fem.K_full @ u - fem.f_full - forces)[fem.free]
    squared = residual @ (residual / fem.K_full.diagonal()[fem.free])
    normal_force = -(state.forces * contact.normals).sum(axis=1)
    if state.constrained and state.gap_at_nodes:
        squared += abs(normal_force @ (state.normal_displacement - state.gap))
    if state.slip is not None and state.nodal_friction:
        tangential = state.forces + normal_force[:, None] * contact.normals
        squared += (np.linalg.norm(tangential, axis=1) * np.linalg.norm(state.slip, axis=1)
                    + (tangential * state.slip).sum(axis=1)).sum()
    return float(np.sqrt(max(squared, 0.0)))


def dorfler(indicators: np.ndarray, fraction: float = 0.5) -> np.ndarray:
    """The fewest cells whose indicators η_T² sum to at least ``fraction`` of η² (Dörfler marking), largest first:
    the cells an adaptive step refines."""
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction: must lie in (0, 1], got {fraction}; 0.5 is usual")
    order = np.argsort(indicators)[::-1]
    reached = np.cumsum(indicators[order]) >= fraction * indicators.sum()
    return np.sort(order[:np.argmax(reached) + 1])
