"""Meshes and finite element bases from a scene's body."""

from __future__ import annotations

import numpy as np
import skfem as fe

from ..scene.model import Body, MeshFile, Rectangle, SceneError

_ELEMENTS = {
    "P1": (fe.ElementTriP1, (fe.MeshTri1,)),
    "P2": (fe.ElementTriP2, (fe.MeshTri1, fe.MeshTri2)),
    "Q1": (fe.ElementQuad1, (fe.MeshQuad1,)),
    "Q2": (fe.ElementQuad2, (fe.MeshQuad1, fe.MeshQuad2)),
}


def _outward(length: float, cells: int, ratio: float) -> np.ndarray:
    """Distances of cells+1 nodes from 0 over ``length``, sizes growing geometrically to ``ratio``."""
    sizes = ratio ** (np.arange(cells) / max(cells - 1, 1))
    return np.concatenate([[0.0], np.cumsum(sizes)]) * length / sizes.sum()


def graded(start: float, length: float, cells: int, ratio: float, focus: float | None) -> np.ndarray:
    """Node coordinates of ``cells`` cells on [start, start+length], finest at ``focus``.

    Cell sizes grow geometrically away from the focus, the largest ``ratio`` times
    the smallest (per side). ``focus=None`` gives uniform cells.
    """
    if focus is None or ratio == 1:
        return np.linspace(start, start + length, cells + 1)
    left = float(np.clip(focus - start, 0.0, length))
    n_left = round(cells * left / length)
    n_right = cells - n_left
    x_left = start + left - _outward(left, n_left, ratio)[::-1] if n_left else np.array([start + left])
    x_right = start + left + _outward(length - left, n_right, ratio)[1:] if n_right else np.array([])
    return np.concatenate([x_left, x_right])


def tensor_mesh(x: np.ndarray, y: np.ndarray, quads: bool = False) -> fe.Mesh:
    """Tensor-product mesh on the nodes x × y with boundaries left, right, bottom, top.

    The sides are found by their exact coordinates: scikit-fem's ``with_defaults`` uses a
    tolerance of a hundredth of the smallest element, which tags every facet of a row of
    elements of aspect ratio ≳ 50 as "top" or "bottom".
    """
    mesh = (fe.MeshQuad1 if quads else fe.MeshTri1).init_tensor(x, y)
    tol = 1e-9 * max(np.ptp(x), np.ptp(y))  # of the body size, not of the smallest element
    return mesh.with_boundaries({
        "left": lambda p: np.abs(p[0] - x.min()) < tol,
        "right": lambda p: np.abs(p[0] - x.max()) < tol,
        "bottom": lambda p: np.abs(p[1] - y.min()) < tol,
        "top": lambda p: np.abs(p[1] - y.max()) < tol,
    })


def rectangle(geometry: Rectangle, quads: bool) -> fe.Mesh:
    """Structured rectangle with boundaries left, right, bottom, top."""
    x0, y0 = geometry.origin
    gx, gy = geometry.grading
    focus_y = y0 + geometry.height if geometry.refine_y == "top" else y0
    x = graded(x0, geometry.width, geometry.nx, gx, geometry.refine_x)
    y = graded(y0, geometry.height, geometry.ny, gy, focus_y if gy > 1 else None)
    return tensor_mesh(x, y, quads)


def load_mesh(geometry: MeshFile) -> fe.Mesh:
    """Read a mesh file with meshio (through scikit-fem); physical groups become names."""
    try:
        return fe.Mesh.load(str(geometry.path))
    except Exception as error:  # meshio raises many types; the user needs the file and the cause
        raise SceneError("body.mesh", f"could not read {geometry.path}: {error}") from error


def build_mesh(body: Body) -> fe.Mesh:
    """The body's mesh in user units."""
    geometry = body.geometry
    if isinstance(geometry, Rectangle):
        return rectangle(geometry, quads=body.element in ("Q1", "Q2"))
    if isinstance(geometry, MeshFile):
        return load_mesh(geometry)
    if isinstance(geometry, fe.Mesh):
        return geometry
    raise SceneError("body.mesh", f"unsupported geometry {type(geometry).__name__}")


def vector_basis(mesh: fe.Mesh, element: str) -> fe.Basis:
    """Vector-valued basis of ``element`` on ``mesh``; refuses mismatched cell types."""
    element_type, mesh_types = _ELEMENTS[element]
    if not isinstance(mesh, mesh_types):
        raise SceneError(
            "body.element",
            f"{element} does not fit a {type(mesh).__name__} mesh",
            "use P1/P2 on triangles and Q1/Q2 on quadrilaterals",
        )
    return fe.Basis(mesh, fe.ElementVector(element_type()))


def check_boundary(mesh: fe.Mesh, name: str, field_name: str) -> np.ndarray:
    """Facet indices of the named boundary, or an error listing the names there are."""
    boundaries = mesh.boundaries or {}
    if name not in boundaries:
        raise SceneError(field_name, f"unknown boundary {name!r}", f"the mesh has {sorted(boundaries)}")
    facets = np.asarray(boundaries[name])
    if facets.size == 0:
        raise SceneError(field_name, f"boundary {name!r} has no facets")
    return facets
