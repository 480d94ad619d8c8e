"""Friction points of Γ_C: where the friction term Σ_k s_k |(R u)_k| is evaluated.

- ``nodal``: the contact nodes, R = diag(w) T (lumped quadrature);
- ``weak``: the contact nodes, R = M T (Hild's continuous P1 multipliers);
- ``gauss``: Gauss points of the facets of Γ_C, R = diag(ω_q) G T, where G
  interpolates nodal values to the points (u_T at a point is linear in nodal values,
  so the quadrature is exact for the discrete field).

In 3-D the slip at a point has two components (along the two tangents of
:class:`~convexcontact.fem.contact.ContactTrace`); R stacks its rows component-major
(all points along t1, then all along t2), as T does, so that 2-D is the case d − 1 = 1.
The multiplier λ_T,k (d − 1 components) is the friction traction on the body at point
k; ‖λ_T,k‖ ≤ s_k — the exact isotropic cone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe

from .contact import ContactTrace, emptied, gauss_interpolation


@dataclass
class FrictionPoints:
    """Rows of the friction term, in scaled units.

    ``R`` (points·(d−1) × free DOFs, component-major) and ``offset`` give the weighted
    slip R u + offset; ``dim`` = d − 1 is the number of tangential components;
    ``weights`` ω_k are the lengths (areas) the points stand for (weighted slips divided by them are lengths);
    ``interpolation`` G
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
    dim: int = 1

    @property
    def count(self) -> int:
        return self.weights.size

    def components(self, values: np.ndarray) -> np.ndarray:
        """A component-major stacked vector (points·(d−1)) as a (points, d−1) array."""
        return values.reshape(self.dim, -1).T

    def slip(self, u: np.ndarray) -> np.ndarray:
        """Weighted slip R u + offset at the points (divide by ``weights`` for a length)."""
        return self.R @ u + self.offset

    def nodal_traction(self, contact: ContactTrace, traction: np.ndarray) -> np.ndarray:
        """Friction traction at the contact nodes carrying the same nodal forces (lumped); (m,) in
        2-D, (m, 2) in 3-D."""
        per_point = self.components(traction)
        if not (self.interpolation.shape[0] == contact.m and self.weights is contact.weights):
            per_point = (self.interpolation.T @ (self.weights[:, None] * per_point)) / contact.weights[:, None]
        return per_point[:, 0] if self.dim == 1 else per_point


def friction_points(
    contact: ContactTrace, mesh: fe.Mesh, basis: fe.Basis, quadrature: str, non_penetration: str,
    nodes: np.ndarray | None = None,
) -> FrictionPoints:
    """The friction rows for the chosen quadrature and non-penetration form; ``nodes``: the contact nodes
    that carry friction (nodal quadrature), all when None."""
    if quadrature == "gauss":
        G, weights, coords = gauss_interpolation(mesh, basis, contact.facets, contact.dofs)
        weighting = sp.diags(weights) @ G
    elif nodes is not None:  # pairs of which some are frictionless: their nodes get no tangential unknowns
        G = sp.identity(contact.m, format="csr")[nodes]
        weights, coords = contact.weights[nodes], contact.coords[nodes]
        weighting = sp.diags(weights) @ G
    else:
        G, weights, coords = sp.identity(contact.m, format="csr"), contact.weights, contact.coords
        weighting = contact.mass if non_penetration == "weak" else sp.diags(weights)
    coupling = None if contact.tangential_coupling is None else weighting @ contact.tangential_coupling
    components = contact.dim - 1
    weighting = sp.block_diag([weighting] * components, format="csr")  # the same weights for each tangent
    R = sp.csr_matrix(weighting @ contact.T)
    if quadrature != "gauss" and contact.symmetric is not None:  # weak rows mix the neighbours' T: empty them too
        R = emptied(R, contact.symmetric.reshape(components, -1)[:, slice(None) if nodes is None else nodes].ravel())
    return FrictionPoints(
        R=R,
        offset=weighting @ contact.tangent_offset,
        weights=weights,
        interpolation=sp.csr_matrix(G),
        coords=coords,
        coupling=coupling,
        dim=components,
    )
