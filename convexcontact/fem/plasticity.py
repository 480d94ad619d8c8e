"""Strains at the quadrature points that carry the plastic strain (scaled units).

Strains are written in Mandel components — (xx, yy, zz, √2 xy) in plane strain (ε_zz(u) = 0, but the
plastic strain has a zz component), (xx, yy, zz, √2 yz, √2 xz, √2 xy) in 3-D — so that the Frobenius
product of tensors is the Euclidean product of their components. A deviatoric tensor is stored by its k
coordinates in the orthonormal basis :data:`DEVIATORS` (k = 3 in plane strain, 5 in 3-D): ‖ε_p‖ is then
the Euclidean norm of its coordinates, and tr ε_p = 0 holds by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import skfem as fe

from ..scene.description import Material
from .assembly import FEModel

_R2, _R6 = np.sqrt(0.5), np.sqrt(1.0 / 6.0)
DEVIATORS = {
    2: np.array([[_R2, _R6, 0], [-_R2, _R6, 0], [0, -2 * _R6, 0], [0, 0, 1]]),
    3: np.block([[np.array([[_R2, _R6], [-_R2, _R6], [0, -2 * _R6]]), np.zeros((3, 3))],
                 [np.zeros((3, 2)), np.eye(3)]]),
}
"""Π (Mandel components × k): an orthonormal basis of the deviatoric symmetric tensors (plane strain: of those with
zero xz, yz)."""

ORDERS = {"P1": 1, "P2": 2, "Q1": 2, "Q2": 4}
"""The quadrature order of each element's plastic points: it integrates ε(u):ε(u) exactly, so that
Σ_q w_q B_qᵀ C B_q is K (P1 triangles: the centroid, where scikit-fem's lowest rule has 3 points)."""

CENTROID = (np.array([[1.0 / 3.0], [1.0 / 3.0]]), np.array([0.5]))


@dataclass(frozen=True)
class PlasticPoints:
    """The quadrature points of the plastic strain: ``deviatoric`` (k·points × full DOFs) maps u to the deviatoric
    strain coordinates Πᵀε(u) at each point (point-major), ``trace`` (points × full DOFs) to tr ε(u); ``weights``
    are the points' volumes, ``shear`` 2μ and ``lame`` λ there, ``element`` the cell of each point."""

    deviatoric: sp.csr_matrix
    trace: sp.csr_matrix
    weights: np.ndarray
    shear: np.ndarray
    lame: np.ndarray
    element: np.ndarray
    components: int

    @property
    def count(self) -> int:
        return self.weights.size

    def coupling(self) -> sp.csr_matrix:
        """G = Σ_q w_q 2μ_q (Πᵀ B_q)ᵀ (full DOFs × k·points): the nodal forces Gα of a plastic strain α."""
        return (self.deviatoric.T @ sp.diags(np.repeat(self.weights * self.shear, self.components))).tocsr()

    def per_point(self, values: np.ndarray) -> np.ndarray:
        """A per-element array at the points."""
        return values[self.element]


def plastic_points(fem: FEModel) -> PlasticPoints:
    """The strain operators of ``fem``'s body at the element's plastic points (:data:`ORDERS`)."""
    dim = fem.dim
    kind = fem.scene.body.element
    rule = {"quadrature": CENTROID} if (kind, dim) == ("P1", 2) else {"intorder": ORDERS[kind]}
    basis = fe.CellBasis(fem.mesh, fem.basis.elem, dofs=fem.basis.dofs, **rule)
    cells, points = basis.dx.shape
    rows, columns, values = [], [], []
    pairs = [(0, 0), (1, 1)] + ([(2, 2), (1, 2), (0, 2), (0, 1)] if dim == 3 else [(0, 1)])
    # Mandel row of each pair: plane strain (xx, yy, zz, √2xy), zz row empty
    mandel = [0, 1, 2, 3, 4, 5] if dim == 3 else [0, 1, 3]
    size = 6 if dim == 3 else 4
    point = np.arange(cells * points).reshape(cells, points)
    for j in range(basis.Nbfun):
        grad = basis.basis[j][0].grad  # (i, k, cell, point): ∂_k φ_j^i
        for row, (a, b) in zip(mandel, pairs):
            factor = 1.0 if a == b else np.sqrt(0.5)  # √2 · ½(∂_b u_a + ∂_a u_b)
            strain = factor * (grad[a, b] + grad[b, a]) if a != b else grad[a, a]
            rows.append((point * size + row).ravel())
            columns.append(np.repeat(basis.element_dofs[j], points))
            values.append(strain.ravel())
    B = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                      shape=(cells * points * size, fem.basis.N))
    Pi = DEVIATORS[dim]
    deviatoric = sp.kron(sp.eye(cells * points), Pi.T, format="csr") @ B
    trace = sp.kron(sp.eye(cells * points), np.r_[1.0, 1.0, 1.0, np.zeros(size - 3)][None, :], format="csr") @ B
    element = np.repeat(np.arange(cells), points)
    lam, mu = fem.lame
    return PlasticPoints(deviatoric.tocsr(), trace.tocsr(), basis.dx.ravel(), 2.0 * mu[element], lam[element], element,
                         Pi.shape[1])


def material_per_element(fem: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """(σ_Y, η_p) per element in user units; σ_Y = inf where a material is elastic."""
    materials = fem.scene.materials
    named = {None: materials} if isinstance(materials, Material) else materials
    sigma, eta = np.full(fem.mesh.t.shape[1], np.inf), np.zeros(fem.mesh.t.shape[1])
    for name, material in named.items():
        cells = slice(None) if name is None else fem.mesh.subdomains[name]
        if material.plastic:
            sigma[cells], eta[cells] = material.yield_stress, material.plastic_viscosity
    return sigma, eta
