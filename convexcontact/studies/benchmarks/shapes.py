"""The bench's family of shapes (``convexcontact bench --scenario shapes``, issue 25): one body whose whole bottom rests
on a flat rigid foundation, from a square block to strips 400 times longer than high, ends free or clamped, and two
bodies; 2-D, P1, E = 1, ν = 0.3, about ``dofs`` free DOFs each.

- ``block``, ``tall``: a block 1 : 1 and 1 : 4 (width : height) whose top is pressed down by 0.01 and moved by 0.003;
- ``strip-free-A``: a strip of aspect A : 1, its top pressed down and moved the same way, its ends free;
- ``strip-clamped-A``: a strip of aspect A : 1, its ends clamped, a traction (0.001, −0.01) on its top: its long
  waves are the bending of a beam on the foundation (the hard case of the slab preconditioner);
- ``two-body``: the bench's punch on an elastic foundation (``bench.two_body_scene``).
"""

from __future__ import annotations

import numpy as np

ASPECTS = (20, 100, 400)
SHAPES = ("block", "tall", *(f"strip-{ends}-{aspect}" for ends in ("free", "clamped") for aspect in ASPECTS),
          "two-body")


def shape_scene(shape: str, law, dofs: float):
    """The scene of a one-body ``shape`` (SHAPES but "two-body", which the bench builds) with the contact law ``law``
    (a law object) and about ``dofs`` free DOFs."""
    if shape in ("block", "tall"):
        return strip(1.0 if shape == "block" else 0.25, dofs, "free", law, shape)
    _, ends, aspect = shape.split("-")
    return strip(float(aspect), dofs, ends, law, shape)


def strip(aspect: float, dofs: float, ends: str, law, name: str):
    """A rectangle ``aspect`` : 1 of square P1 cells, about ``dofs`` free DOFs, its whole bottom on a flat foundation;
    ends "free" (top pressed down by 0.01 and moved by 0.003) or "clamped" (top under a traction (0.001, −0.01))."""
    import convexcontact as cc

    rows = max(2, round(np.sqrt(dofs / (2 * aspect))))
    columns = max(2, round(aspect * rows))
    geometry = cc.Rectangle(width=columns / rows, height=1.0, nx=columns, ny=rows)
    if ends == "free":
        dirichlet, tractions = (cc.Dirichlet("top", ux=0.003, uy=-0.01),), ()
    else:
        dirichlet = (cc.Dirichlet("left", ux=0.0, uy=0.0), cc.Dirichlet("right", ux=0.0, uy=0.0))
        tractions = (cc.Traction("top", vector=(0.001, -0.01)),)
    return cc.Scene(name=name, body=cc.Body(geometry, "P1"), materials=cc.Material(1.0, 0.3), dirichlet=dirichlet,
                    tractions=tractions, contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), law))
