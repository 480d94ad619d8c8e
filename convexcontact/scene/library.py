"""Built-in scenes: the demo and the verification cases of DESIGN.md."""

from __future__ import annotations

from .model import Body, Contact, Dirichlet, Material, Obstacle, Rectangle, Scene, Signorini, Traction

HERTZ_FORCE = 0.0086307
"""Force per unit thickness giving a = 0.1, p₀ = 0.054945 for R = 1, E = 1, ν = 0.3."""


def hertz_punch(nx: int = 80, element: str = "P1", force: float = HERTZ_FORCE, law=None) -> Scene:
    """Plane-strain block [-2, 2] × [-2, 0] pressed by a rigid cylindrical punch (R = 1).

    Force control: the punch carries ``force`` per unit thickness (DESIGN.md case 2).
    The mesh is graded 10:1 towards the punch axis and the top surface.
    """
    return Scene(
        name="hertz",
        body=Body(
            Rectangle(width=4.0, height=2.0, nx=nx, ny=nx // 2, origin=(-2.0, -2.0), grading=(10.0, 10.0), refine_x=0.0),
            element=element,
        ),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=(Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=Contact("top", Obstacle("parabolic", radius=1.0, force=force), law or Signorini()),
    )


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
