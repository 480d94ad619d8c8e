"""Friction points of Γ_C: where the friction term Σ_k s_k |(R u)_k| is evaluated.

- ``nodal``: the contact nodes, R = diag(w) T (lumped quadrature);
- ``weak``: the contact nodes, R = M T (Hild's continuous P1 multipliers);
- ``gauss``: Gauss points of the facets of Γ_C, R = diag(ω_q) G T, where G
  interpolates nodal values to the points (u_T at a point is linear in nodal values,
  so the quadrature is exact for the discrete field).

The multiplier λ_T,k of row k is the friction traction on the body along the
tangent; |λ_T,k| ≤ s_k.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe

from .contact import ContactTrace


@dataclass
class FrictionPoints:
    """Rows of the friction term, in scaled units.

    ``R`` (points × free DOFs) and ``offset`` give the weighted slip R u + offset;
    ``weights`` ω_k are the lengths the points stand for; ``interpolation`` G
    (points × contact nodes) maps nodal values (pressures, coefficients) to the
    points; ``coords`` locate the points; ``coupling`` is R applied to a unit
    tangential translation of the obstacle (None without a tangential force).
    """

    R: sp.csr_matrix
    offset: np.ndarray
    weights: np.ndarray
    interpolation: sp.csr_matrix
    coords: np.ndarray
    coupling: np.ndarray | None

    @property
    def count(self) -> int:
        return self.weights.size

    def slip(self, u: np.ndarray) -> np.ndarray:
        """Weighted slip R u + offset at the points (divide by ``weights`` for a length)."""
        return self.R @ u + self.offset

    def nodal_traction(self, contact: ContactTrace, traction: np.ndarray) -> np.ndarray:
        """Friction traction at the contact nodes carrying the same nodal forces (lumped)."""
        if self.interpolation.shape[0] == contact.m and self.weights is contact.weights:
            return traction
        return (self.interpolation.T @ (self.weights * traction)) / contact.weights


def gauss_interpolation(mesh: fe.Mesh, basis: fe.Basis, contact: ContactTrace):
    """G (points × contact nodes), weights ω_q and coordinates of Gauss points on Γ_C."""
    scalar = fe.FacetBasis(mesh, basis.elem.elem, facets=contact.facets)
    # scalar DOF j carries vector DOFs 2j, 2j + 1 (scikit-fem interleaves components)
    node_of_dof = np.full(scalar.N, -1)
    node_of_dof[contact.dofs[:, 0] // 2] = np.arange(contact.m)
    assert np.allclose(scalar.doflocs[:, contact.dofs[:, 0] // 2], basis.doflocs[:, contact.dofs[:, 0]])
    nfacets, nqp = scalar.dx.shape
    rows = np.arange(nfacets * nqp).reshape(nfacets, nqp)
    entries = [
        (scalar.basis[j][0].value.ravel(), rows.ravel(), np.repeat(node_of_dof[scalar.element_dofs[j]], nqp))
        for j in range(scalar.Nbfun)
    ]
    values, i, k = (np.concatenate(parts) for parts in zip(*entries))
    on_facet = k >= 0  # the element's other DOFs vanish on the facet
    assert np.allclose(values[~on_facet], 0.0)
    values, i, k = values[on_facet], i[on_facet], k[on_facet]
    G = sp.csr_matrix((values, (i, k)), shape=(nfacets * nqp, contact.m))  # duplicates are summed
    coords = scalar.global_coordinates().value.reshape(2, -1).T
    return G, scalar.dx.ravel(), coords


def friction_points(
    contact: ContactTrace, mesh: fe.Mesh, basis: fe.Basis, quadrature: str, non_penetration: str
) -> FrictionPoints:
    """The friction rows for the chosen quadrature and non-penetration form."""
    if quadrature == "gauss":
        G, weights, coords = gauss_interpolation(mesh, basis, contact)
        weighting = sp.diags(weights) @ G
    else:
        G, weights, coords = sp.identity(contact.m, format="csr"), contact.weights, contact.coords
        weighting = contact.mass if non_penetration == "weak" else sp.diags(weights)
    coupling = None if contact.tangential_coupling is None else weighting @ contact.tangential_coupling
    return FrictionPoints(
        R=sp.csr_matrix(weighting @ contact.T),
        offset=weighting @ contact.tangent_offset,
        weights=weights,
        interpolation=sp.csr_matrix(G),
        coords=coords,
        coupling=coupling,
    )
