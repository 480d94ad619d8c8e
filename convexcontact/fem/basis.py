"""Finite element bases on a body's mesh, with the quadrature chosen per element (:data:`ELEMENT_TYPES`)."""

from __future__ import annotations

from functools import cached_property

import numpy as np
import skfem as fe

from ..scene.description import SceneError
from ..scene.meshing import ELEMENT_TYPES

CENTROID = (np.array([[1.0 / 3.0], [1.0 / 3.0]]), np.array([0.5]))
"""The one-point rule of the reference triangle (exact for degree 1): P1's stiffness and loads."""


def vector_basis(mesh: fe.Mesh, element: str, intorder: int | None = None) -> fe.Basis:
    """Vector-valued basis of ``element`` on ``mesh`` with the quadrature of :data:`ELEMENT_TYPES`
    (``intorder`` overrides it); refuses mismatched cell types."""
    dim = mesh.dim()
    if (element, dim) not in ELEMENT_TYPES:
        raise SceneError("body.element", f"{element} has no {dim}-D version")
    element_type, mesh_types, order = ELEMENT_TYPES[element, dim]
    if not isinstance(mesh, mesh_types):
        raise SceneError(
            "body.element",
            f"{element} does not fit a {type(mesh).__name__} mesh",
            "use P1/P2 on triangles or tetrahedra and Q1/Q2 on quadrilaterals or hexahedra",
        )
    quadrature = CENTROID if (element, dim) == ("P1", 2) and intorder is None else None
    return VectorBasis(mesh, fe.ElementVector(element_type()), intorder=order if intorder is None else intorder,
                       quadrature=quadrature)


class VectorBasis(fe.CellBasis):
    """scikit-fem's CellBasis whose shape functions are evaluated at the quadrature points on first use.

    A CellBasis evaluates the values and gradients of all its vector shape functions at every quadrature point
    when built: 1.1 s and 0.3 GB at 10⁶ DOFs of P1 in 2-D, 4.3 GB for Q1 at 3·10⁵ DOFs in 3-D. The assembly needs
    only the DOFs and the scalar gradients (:mod:`.stiffness`); what integrates over the whole body with this
    basis (body forces, stresses) evaluates them then. The constructor is CellBasis's, its last two
    lines made properties (so that scikit-fem's ``with_elements``, ``split_bases`` … build this class too)."""

    def __init__(self, mesh: fe.Mesh, elem: fe.Element, mapping=None, intorder: int | None = None, elements=None,
                 quadrature: tuple | None = None, dofs=None, disable_doflocs: bool = False):
        fe.AbstractBasis.__init__(self, mesh, elem, mapping, intorder, quadrature, mesh.refdom, dofs, disable_doflocs)
        self.tind = None if elements is None else mesh.normalize_elements(elements)
        self.nelems = mesh.nelements if elements is None else len(self.tind)

    @cached_property
    def basis(self) -> list:
        return [self.elem.gbasis(self.mapping, self.X, j, tind=self.tind) for j in range(self.Nbfun)]

    @cached_property
    def dx(self) -> np.ndarray:
        return (np.abs(self.mapping.detDF(self.X, tind=self.tind))
                * np.broadcast_to(self.W, (self.nelems, self.W.shape[-1])))
