"""Derived fields for output: element stresses and vertex values, in user units."""

from __future__ import annotations

import numpy as np
from skfem.helpers import sym_grad

from ..fem.assembly import stress


def element_stress(result) -> dict[str, np.ndarray]:
    """Element averages of the stress components (σ_xx, σ_yy, σ_xy [, σ_zz, σ_xz, σ_yz]) and von Mises
    (in-plane in 2-D)."""
    fem = result.fem
    basis = fem.basis
    strain = sym_grad(basis.interpolate(result.displacement / fem.scaling.displacement))
    lam, mu = (p[:, None] for p in fem.lame)
    sigma = stress(lam, mu)(strain) * fem.scaling.pressure
    dx = basis.dx
    components = {"sigma_xx": (0, 0), "sigma_yy": (1, 1), "sigma_xy": (0, 1)}
    if fem.dim == 3:
        components.update(sigma_zz=(2, 2), sigma_xz=(0, 2), sigma_yz=(1, 2))
    mean = {name: (sigma[i, j] * dx).sum(axis=1) / dx.sum(axis=1) for name, (i, j) in components.items()}
    sxx, syy, sxy = mean["sigma_xx"], mean["sigma_yy"], mean["sigma_xy"]
    szz, sxz, syz = (mean.get(name, 0.0) for name in ("sigma_zz", "sigma_xz", "sigma_yz"))
    mean["von_mises"] = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2)
                                + 3 * (sxy**2 + sxz**2 + syz**2))
    return mean


def point_dofs(fem) -> np.ndarray:
    """(points, d) the DOFs at each point of the mesh (``mesh.p``, as to_meshio writes it): a linear mesh's vertices,
    every node of a quadratic one (MeshTri2, MeshTet2: its p holds the edge nodes, in the P2 basis's order)."""
    if fem.mesh.p.shape[1] > fem.mesh.nvertices:
        return np.arange(fem.basis.N).reshape(-1, fem.dim)
    return fem.basis.nodal_dofs.T


def vertex_displacement(result) -> np.ndarray:
    """(points, d) displacement at the mesh's points (:func:`point_dofs`)."""
    return result.displacement[point_dofs(result.fem)]


def vertex_of_dof(fem) -> np.ndarray:
    """The mesh point of each DOF (−1 for mid-side nodes of a linear mesh)."""
    vertex = np.full(fem.basis.N, -1)
    points = point_dofs(fem)
    vertex[points[:, 0]] = np.arange(points.shape[0])
    return vertex


def vertex_contact(result, values: np.ndarray, dofs: np.ndarray | None = None) -> np.ndarray:
    """A contact-node field (scalar or per-node vectors) spread onto all mesh vertices (zero off Γ_C
    and at mid-side nodes); ``dofs`` (default: the contact nodes') say where the values sit."""
    fem = result.fem
    out = np.zeros((fem.mesh.p.shape[1],) + values.shape[1:])
    vertices = vertex_of_dof(fem)[(fem.contact.dofs if dofs is None else dofs)[:, 0]]
    on_vertex = vertices >= 0
    out[vertices[on_vertex]] = values[on_vertex]
    return out
