"""Built-in scenes: the demo and the verification cases of DESIGN.md."""

from __future__ import annotations

import dataclasses

import numpy as np
import skfem as fe

from .checks import SceneError, finite, positive_integer
from .description import Body, Box, Contact, Dirichlet, Material, Obstacle, Rectangle, Scene, Signorini, Traction
from .meshing import tensor_mesh

HERTZ_FORCE = 0.0086307
"""Force per unit thickness giving a = 0.1, p₀ = 0.054945 for R = 1, E = 1, ν = 0.3."""

HERTZ_SPHERE_FORCE = 4 * 0.1**3 / (3 * (1 - 0.3**2))
"""Force on the whole sphere giving a = 0.1, p₀ = 0.069956 for R = 1, E = 1, ν = 0.3 (3-D Hertz)."""


def hertz_punch(nx: int = 80, element: str = "P1", force: float = HERTZ_FORCE, law=None) -> Scene:
    """Plane-strain block [-2, 2] × [-2, 0] pressed by a rigid cylindrical punch (R = 1).

    Force control: the punch carries ``force`` per unit thickness (DESIGN.md case 2).
    The mesh is graded 10:1 towards the punch axis and the top surface.
    """
    rows = half(nx)
    return Scene(
        name="hertz",
        body=Body(
            Rectangle(width=4.0, height=2.0, nx=nx, ny=rows, origin=(-2.0, -2.0), grading=(10.0, 10.0), refine_x=0.0),
            element=element,
        ),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=(Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=Contact("top", Obstacle("parabolic", radius=1.0, force=force), law or Signorini()),
    )


def half(nx) -> int:
    """The rows of a block ``nx`` cells wide and half as high: ``nx`` an integer ≥ 2."""
    if positive_integer(nx, "nx", "give the cells across, e.g. 40") < 2:
        raise SceneError("nx", f"the block is nx cells wide and nx // 2 high, so nx ≥ 2, got {nx}", "give e.g. 40")
    return nx // 2


def pressure_patch(nx: int = 8, element: str = "P1", pressure: float = 0.1, law=None) -> Scene:
    """Unit square on a flat rigid foundation, uniform pressure on top (DESIGN.md case 1).

    A roller on the left side removes the horizontal rigid motion.
    """
    return Scene(
        name="patch",
        body=Body(Rectangle(width=1.0, height=1.0, nx=nx, ny=nx), element=element),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=(Dirichlet("left", ux=0.0),),
        tractions=(Traction("top", pressure=pressure),),
        contact=Contact("bottom", Obstacle("flat", gap=0.0), law or Signorini()),
    )


def punch_mesh(
    h: float, fine: float = 0.15, rows: int = 10, width: float = 4.0, depth: float = 2.0, quads: bool = False
) -> fe.Mesh:
    """Block [-width/2, width/2] × [-depth, 0], cells of size h over |x| < fine and ``rows`` rows deep.

    Away from that zone the cells grow geometrically (24 columns each side, 30 rows), so
    the contact zone of a punch is resolved uniformly at little cost. Quadrilaterals keep
    the mirror symmetry about x = 0 that the one-diagonal triangles break.
    """

    check_punch_mesh(h, fine, rows, width, depth)

    def growing(length: float, cells: int) -> np.ndarray:
        sizes = np.geomspace(1.0, (length / h) ** ((cells - 1) / cells), cells)
        return np.cumsum(sizes) * length / sizes.sum()

    x_fine = np.arange(-fine, fine + h / 2, h)
    x_out = fine + growing(width / 2 - fine, 24)
    x = np.concatenate([-x_out[::-1], x_fine, x_out])
    y = -np.concatenate([np.arange(rows + 1) * h, rows * h + growing(depth - rows * h, 30)])[::-1]
    return tensor_mesh(x, y, quads=quads)


def check_punch_mesh(h, fine, rows, width, depth) -> None:
    """The sizes of :func:`punch_mesh`: ``h`` fits the fine zone (``fine`` ≤ width/2, ``rows`` h < depth) and the
    mesh fits in memory (h = 1e-9 asked for 92 GiB)."""
    from .meshing import check_memory

    for name, value in (("h", h), ("fine", fine), ("width", width), ("depth", depth)):
        if finite(value, name) <= 0:
            raise SceneError(name, f"must be positive, got {value}", "give a length, e.g. h = 0.005")
    positive_integer(rows, "rows", "give the rows of fine cells, e.g. 10")
    if h > fine or fine >= width / 2 or rows * h >= depth:
        raise SceneError("h", f"h = {h} must be at most fine = {fine} < width/2 = {width / 2}, with rows × h = "
                         f"{rows * h:g} < depth = {depth}", "give a smaller h (the cells of the contact zone)")
    nodes = (2 * fine / h + 50) * (rows + 32)
    check_memory(2 * nodes, 2, "h", f"h = {h}", "give a larger h")


def frictional_punch(h: float = 0.005, depth: float = 0.02, friction: float = 0.6, nu: float = 0.3,
                     element: str = "P1", law=None) -> Scene:
    """Oden's example (DESIGN.md case 4): a rigid cylinder (R = 1) indents the block, Coulomb friction."""
    from .description import Coulomb

    law = law or Coulomb(friction=friction)
    return Scene(
        name="frictional_punch",
        body=Body(punch_mesh(h, quads=element in ("Q1", "Q2")), element=element),
        materials=Material(E=1.0, nu=nu),
        dirichlet=(Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=Contact("top", Obstacle("parabolic", radius=1.0, depth=depth), law),
    )


def tresca_punch(nx: int = 40, slip_bound: float = 0.005, depth: float = 0.01, regularization: float | None = None):
    """The Hertz block indented by depth (displacement control) with Tresca friction of a given bound."""
    from .description import Tresca

    law = Tresca(slip_bound=slip_bound, regularization=regularization)
    contact = Contact("top", Obstacle("parabolic", radius=1.0, depth=depth), law)
    return dataclasses.replace(hertz_punch(nx=nx, law=law), name="tresca_punch", contact=contact)


def quarter_box(cells: int, element: str, grading: float, obstacle: Obstacle, law, name: str,
                size: float = 1.0) -> Scene:
    """The quarter [0, size]² × [−size, 0] of a body indented on its top at the z axis.

    Symmetry rollers on the planes x = 0 (``left``) and y = 0 (``front``), clamped
    ``bottom``; cells graded ``grading``:1 towards the origin. Hexahedra (Q1, Q2) keep
    the model's diagonal symmetry x ↔ y, which the tetrahedra of a cube split break.
    """
    box = Box(size=(size, size, size), cells=(cells,) * 3, origin=(0.0, 0.0, -size), grading=(grading,) * 3,
              refine=(0.0, 0.0, 0.0))
    return Scene(
        name=name,
        body=Body(box, element=element),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=(Dirichlet("left", ux=0.0), Dirichlet("front", uy=0.0), Dirichlet("bottom", ux=0.0, uy=0.0, uz=0.0)),
        contact=Contact("top", obstacle, law or Signorini()),
    )


def hertz_sphere(cells: int = 16, element: str = "P1", force: float = HERTZ_SPHERE_FORCE, grading: float = 12.0,
                 law=None) -> Scene:
    """3-D Hertz: a rigid sphere (R = 1; its paraboloid, as in Hertz theory) pressed with ``force``, quarter model.

    The quarter carries ``force``/4 (the obstacle force of the scene); with the default
    force a = 0.1 and p₀ = 0.069956 (:func:`convexcontact.analytic.hertz_sphere`), the body
    is 10a wide and deep.
    """
    obstacle = Obstacle("parabolic", radius=1.0, center=(0.0, 0.0, 0.0), force=force / 4)
    return quarter_box(cells, element, grading, obstacle, law, "hertz_sphere")


def punch_3d(cells: int = 12, law=None, element: str = "Q1", depth: float = 0.01, radius: float | None = 1.0,
             grading: float = 8.0) -> Scene:
    """A rigid punch indents the top of a box by ``depth`` at the z axis, quarter model (any law).

    ``radius``: a rounded (paraboloidal) punch, contact radius about sqrt(R·depth); None: a flat
    rigid plane pressed on the whole top (the uniform indentation of a clamped block).
    Sizes for benchmarks: 3(cells + 1)³ DOFs with Q1.
    """
    obstacle = (Obstacle("parabolic", radius=radius, center=(0.0, 0.0, 0.0), depth=depth) if radius is not None
                else Obstacle("flat", depth=depth))
    return quarter_box(cells, element, grading, obstacle, law, "punch_3d")


def whole_face(dim: int = 2, nodes: int = 1001, dofs: float = 1e5, law=None, depth: float = 0.01,
               shift: float = 0.003) -> Scene:
    """A block whose whole bottom rests on a flat rigid foundation (gap 0), its top pressed down by ``depth``
    and moved sideways by ``shift`` (a large contact zone: every bottom node is a contact node).

    2-D: a strip of height 1 and ``nodes`` − 1 square P1 cells along the bottom; 3-D: a Q1 block of
    about ``nodes`` bottom nodes, square in plan; the rows up the height make about ``dofs`` DOFs.
    """
    if dim not in (2, 3):
        raise SceneError("dim", f"got {dim!r}", "give 2 or 3")
    if positive_integer(nodes, "nodes", "give the contact nodes, e.g. 1001") < 3:
        raise SceneError("nodes", f"at least 3 contact nodes (2 cells along the face), got {nodes}", "give e.g. 1001")
    if finite(dofs, "dofs") <= 0:
        raise SceneError("dofs", f"must be positive, got {dofs}", "give the DOFs wanted, e.g. 1e5")
    if dim == 2:
        nx = max(2, nodes - 1)
        ny = max(2, round(dofs / (2 * (nx + 1))) - 1)
        geometry = Rectangle(width=nx / ny, height=1.0, nx=nx, ny=ny)
        top = Dirichlet("top", ux=shift, uy=-depth)
    else:
        n = max(2, round(np.sqrt(nodes)) - 1)
        nz = max(2, round(dofs / (3 * (n + 1) ** 2)) - 1)
        geometry = Box(size=(n / nz, n / nz, 1.0), cells=(n, n, nz))
        top = Dirichlet("top", ux=shift, uy=0.0, uz=-depth)
    return Scene(
        name="whole_face",
        body=Body(geometry, element="P1" if dim == 2 else "Q1"),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=(top,),
        contact=Contact("bottom", Obstacle("flat", gap=0.0), law or Signorini()),
    )
