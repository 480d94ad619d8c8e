"""The bench's family of shapes (``convexcontact bench --scenario shapes [--dim 3]``, issue 25): one body whose whole
bottom rests on a flat rigid foundation, from a square block to strips 400 times longer than high, ends free or
clamped, tall and flat 3-D blocks and plates, and two bodies; E = 1, ν = 0.3, about ``dofs`` free DOFs each.

2-D, P1 triangles:

- ``block``, ``tall``: a block 1 : 1 and 1 : 4 (width : height) whose top is pressed down by 0.01 and moved by 0.003;
- ``strip-free-A``: a strip of aspect A : 1, its top pressed down and moved the same way, its ends free;
- ``strip-clamped-A``: a strip of aspect A : 1, its ends clamped, a traction (0.001, −0.01) on its top: its long
  waves are the bending of a beam on the foundation (the hard case of the slab preconditioner);
- ``two-body``: the bench's punch on an elastic foundation (``bench.two_body_scene``).

3-D, Q1 hexahedra (as the bench's 3-D whole face):

- ``flat``, ``tall``: a block 4 : 4 : 1 and 1 : 1 : 4 (x : y : height), top pressed down by 0.01 and moved along x by
  0.003;
- ``plate-free-20``: a plate 20 : 20 : 1 pressed and moved the same way, its edges free;
- ``plate-clamped-20``: the same plate, its four edges clamped, a traction (0.001, 0, −0.01) on its top (the plate's
  bending on the foundation);
- ``two-body``: two spheres' caps, the upper one 10 times stiffer, pressed together (``bench.two_body_scene``).
"""

from __future__ import annotations

import numpy as np

ASPECTS = (20, 100, 400)
PLATE = 20
SHAPES = {2: ("block", "tall", *(f"strip-{ends}-{aspect}" for ends in ("free", "clamped") for aspect in ASPECTS),
              "two-body"),
          3: ("flat", "tall", *(f"plate-{ends}-{PLATE}" for ends in ("free", "clamped")), "two-body")}
"""The family's shapes by dimension."""
BLOCKS_3D = {"flat": (4.0, 4.0, 1.0), "tall": (1.0, 1.0, 4.0)}
"""The 3-D blocks' sides x : y : height."""
SHIFT, DEPTH, TRACTION = 0.003, 0.01, (0.001, -0.01)
"""The pressed top's sideways move and depth (ends free); the top's traction, sideways and down (ends clamped)."""


def shape_scene(shape: str, law, dofs: float, dim: int = 2):
    """The scene of a one-body ``shape`` (SHAPES[dim] but "two-body", which the bench builds) with the contact law
    ``law`` (a law object) and about ``dofs`` free DOFs."""
    if dim == 3:
        if shape in BLOCKS_3D:
            return box(BLOCKS_3D[shape], dofs, "free", law, shape)
        _, ends, aspect = shape.split("-")
        return box((float(aspect), float(aspect), 1.0), dofs, ends, law, shape)
    if shape in ("block", "tall"):
        return strip(1.0 if shape == "block" else 0.25, dofs, "free", law, shape)
    _, ends, aspect = shape.split("-")
    return strip(float(aspect), dofs, ends, law, shape)


def loads(ends: str, dim: int, clamped: tuple) -> tuple:
    """(dirichlet, tractions): ends "free", the top pressed down by DEPTH and moved by SHIFT along x; "clamped", the
    ``clamped`` boundaries held and the top under TRACTION."""
    import convexcontact as cc

    down = {"ux": SHIFT, "uy": -DEPTH} if dim == 2 else {"ux": SHIFT, "uy": 0.0, "uz": -DEPTH}
    if ends == "free":
        return (cc.Dirichlet("top", **down),), ()
    held = (cc.Dirichlet(side, **dict.fromkeys(cc.Dirichlet.COMPONENTS[:dim], 0.0)) for side in clamped)
    vector = TRACTION if dim == 2 else (TRACTION[0], 0.0, TRACTION[1])
    return tuple(held), (cc.Traction("top", vector=vector),)


def on_foundation(name: str, body, dirichlet, tractions, law):
    """The one-body scene: ``body`` (E = 1, ν = 0.3) whose bottom rests on a flat rigid foundation (gap 0)."""
    import convexcontact as cc

    return cc.Scene(name=name, body=body, materials=cc.Material(1.0, 0.3), dirichlet=dirichlet, tractions=tractions,
                    contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), law))


def strip(aspect: float, dofs: float, ends: str, law, name: str):
    """A rectangle ``aspect`` : 1 of square P1 cells, about ``dofs`` free DOFs, its whole bottom on a flat foundation;
    ends "free" (top pressed down by 0.01 and moved by 0.003) or "clamped" (top under a traction (0.001, −0.01))."""
    import convexcontact as cc

    rows = max(2, round(np.sqrt(dofs / (2 * aspect))))
    columns = max(2, round(aspect * rows))
    geometry = cc.Rectangle(width=columns / rows, height=1.0, nx=columns, ny=rows)
    return on_foundation(name, cc.Body(geometry, "P1"), *loads(ends, 2, ("left", "right")), law)


def box(sides: tuple, dofs: float, ends: str, law, name: str):
    """A box of height 1 in the proportions ``sides`` (x : y : height) of cubic Q1 cells, about
    ``dofs`` free DOFs (3 per node), its whole bottom on a flat foundation; ends "free" (top pressed down by 0.01 and
    moved along x by 0.003) or "clamped" (the four sides held, the top under a traction (0.001, 0, −0.01))."""
    import convexcontact as cc

    plan = np.array(sides[:2]) / sides[2]
    layers = max(1, round((dofs / (3 * plan.prod())) ** (1 / 3)))
    nx, ny = np.maximum(1, np.round(plan * layers)).astype(int)
    geometry = cc.Box(size=(nx / layers, ny / layers, 1.0), cells=(int(nx), int(ny), layers))
    return on_foundation(name, cc.Body(geometry, "Q1"), *loads(ends, 3, ("left", "right", "front", "back")), law)
