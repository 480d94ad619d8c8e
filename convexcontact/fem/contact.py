"""The contact trace: nodes of Γ_C, normals, tangents, weights, operators N and T, gap."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe
from skfem.helpers import dot

from ..scene.model import Contact, SceneError
from .mesh import check_boundary
from .scaling import Scaling


@dataclass
class ContactTrace:
    """Contact nodes i = 1..m of Γ_C in scaled units.

    ``N`` and ``T`` (m × free DOFs) give u_N = N u + normal_offset and
    u_T = T u + tangent_offset, the offsets coming from Dirichlet data. Tangents
    point towards increasing ``coordinate`` (the position along Γ_C projected on
    its mean tangent). ``weights`` are w_i = ∫ψ_i ds, ``mass`` the consistent
    boundary mass M of the trace space. ``obstacle_coupling`` (force control only)
    is how much a unit advance of the obstacle closes the gap at each node;
    ``tangential_coupling`` (tangential force only) is the tangential motion of each
    node's obstacle point for a unit tangential translation of the obstacle.
    """

    facets: np.ndarray
    dofs: np.ndarray  # (m, 2) full DOF indices (x, y components)
    coords: np.ndarray  # (m, 2)
    normals: np.ndarray  # (m, 2)
    tangents: np.ndarray  # (m, 2)
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

    @property
    def m(self) -> int:
        return self.coords.shape[0]


def _rows(vectors: np.ndarray, dofs: np.ndarray, ndofs: int) -> sp.csr_matrix:
    """m × ndofs matrix whose row i takes the dot product of vectors[i] with node i's displacement."""
    m = dofs.shape[0]
    return sp.csr_matrix((vectors.ravel(), (np.repeat(np.arange(m), 2), dofs.ravel())), shape=(m, ndofs))


def contact_trace(
    contact: Contact, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling, free: np.ndarray, prescribed: np.ndarray
) -> ContactTrace:
    """Build the trace of Γ_C from the named boundary and the obstacle."""
    facets = check_boundary(mesh, contact.boundary, "contact.boundary")
    view = basis.get_dofs(facets)
    dofs = np.column_stack([view.all("u^1"), view.all("u^2")])
    if dofs.shape[0] == 0:
        raise SceneError("contact.boundary", f"{contact.boundary!r} carries no nodes")
    coords = basis.doflocs[:, dofs[:, 0]].T

    facet_basis = fe.FacetBasis(mesh, basis.elem, facets=facets)
    # n_i ∝ ∫ ψ_i n ds: the outward normal averaged with the shape function's weight,
    # well defined for any Lagrange element and for curved facets
    weighted_normal = fe.asm(fe.LinearForm(lambda v, w: dot(w.n, v)), facet_basis)[dofs]
    normals = weighted_normal / np.linalg.norm(weighted_normal, axis=1, keepdims=True)
    mass = fe.asm(fe.BilinearForm(lambda u, v, w: u[0] * v[0]), facet_basis).tocsr()[dofs[:, 0]][:, dofs[:, 0]]
    weights = np.asarray(mass.sum(axis=1)).ravel()  # partition of unity: Σ_j ∫ψ_iψ_j = ∫ψ_i

    tangents = np.column_stack([normals[:, 1], -normals[:, 0]])
    mean_tangent = weights @ tangents
    mean_tangent /= np.linalg.norm(mean_tangent)
    if mean_tangent[np.argmax(np.abs(mean_tangent))] < 0:
        tangents, mean_tangent = -tangents, -mean_tangent
    coordinate = coords @ mean_tangent

    N_full = _rows(normals, dofs, basis.N)
    T_full = _rows(tangents, dofs, basis.N)

    obstacle = contact.obstacle
    user_coords = coords * scaling.length
    gap = obstacle.shape_gap(user_coords[:, 0], user_coords[:, 1], coordinate * scaling.length)
    gap = (gap - (obstacle.depth or 0.0)) / scaling.displacement
    mean_normal = weights @ normals
    mean_normal /= np.linalg.norm(mean_normal)
    coupling = normals @ mean_normal if obstacle.force_controlled else None
    tangential = tangents @ mean_tangent if obstacle.tangential_force is not None else None

    return ContactTrace(
        facets=facets,
        dofs=dofs,
        coords=coords,
        normals=normals,
        tangents=tangents,
        coordinate=coordinate,
        weights=weights,
        mass=mass,
        N=N_full[:, free],
        T=T_full[:, free],
        normal_offset=N_full @ prescribed,
        tangent_offset=T_full @ prescribed,
        gap=gap,
        obstacle_coupling=coupling,
        obstacle_force=(obstacle.force or 0.0) / scaling.force,
        tangential_coupling=tangential,
        obstacle_tangential_force=(obstacle.tangential_force or 0.0) / scaling.force,
    )
