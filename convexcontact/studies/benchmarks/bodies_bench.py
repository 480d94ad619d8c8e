"""Two-body costs, as ratios measured in one process (docs/bodies.md, Performance).

- :func:`mortar_assembly`: the trace of a pair (mortar and node-to-segment) against the stiffness assembly of
  the same two-body mesh, at a given number of slave facets;
- :func:`two_body_solve`: the contact solve of a punch on an elastic foundation against one linear solve of
  the whole assembly (K's factorization and u = K⁻¹f), as ``convexcontact bench`` reports for one body.
"""

from __future__ import annotations

import dataclasses
import time


def strips(facets: int, rows: int, ratio: float = 1.3, element: str = "P1"):
    """Two strips of square cells of ``element`` (P1, P2: triangles; Q1, Q2), ``facets`` against about ``ratio`` ×
    ``facets`` across the interface."""
    import convexcontact as cc

    master = round(ratio * facets)
    parts = [cc.Part("upper", cc.Rectangle(1.0, rows / facets, facets, rows, origin=(0.0, rows / master)),
                     cc.Material(1.0, 0.3), element),
             cc.Part("lower", cc.Rectangle(1.0, rows / master, master, rows, origin=(0.0, 0.0)), cc.Material(1.0, 0.3),
                     element)]
    return cc.bodies_scene(parts, cc.Pair("upper.bottom", master="lower.top"),
                           dirichlet=[cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0),
                                      cc.Dirichlet("upper.top", ux=0.0, uy=-1e-4)], name="strips")


def slabs(cells: int, ratio: float = 1.3):
    """Two slabs of P1 tetrahedra, ``cells`` × ``cells`` hexahedra across (2 cells² triangles) against about
    ``ratio`` times as many per side, one layer deep."""
    import convexcontact as cc
    from convexcontact.scene.description import Box

    master = round(ratio * cells)
    parts = [cc.Part("upper", Box(size=(1.0, 1.0, 1 / cells), cells=(cells, cells, 1), origin=(0, 0, 1 / master)),
                     cc.Material(1.0, 0.3)),
             cc.Part("lower", Box(size=(1.0, 1.0, 1 / master), cells=(master, master, 1)), cc.Material(1.0, 0.3))]
    return cc.bodies_scene(parts, cc.Pair("upper.bottom", master="lower.top"),
                           dirichlet=[cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0, uz=0.0),
                                      cc.Dirichlet("upper.top", ux=0.0, uy=0.0, uz=-1e-4)], name="slabs")


def timed(function, *args) -> float:
    start = time.perf_counter()
    function(*args)
    return time.perf_counter() - start


def mortar_assembly(facets: int = 10_000, rows: int = 8, dim: int = 2, element: str = "P1") -> dict:
    """Seconds to build the pair's trace (mortar, and node-to-segment in 2-D) and the stiffness K of the same mesh;
    in 3-D about ``facets`` slave triangles (``rows`` and ``element`` unused)."""
    from convexcontact.fem.assembly import assemble
    from convexcontact.fem.mortar import pair_trace
    from convexcontact.fem.stiffness import stiffness

    scene = strips(facets, rows, element=element) if dim == 2 else slabs(round((facets / 2) ** 0.5))
    fem = assemble(scene)
    arguments = (fem.mesh, fem.basis, fem.scaling, fem.free, fem.prescribed)
    out = {"slave_facets": fem.mesh.boundaries["upper.bottom"].size,
           "master_facets": fem.mesh.boundaries["lower.top"].size, "dofs": fem.n_free,
           "stiffness": timed(stiffness, fem.basis, fem.lame)}
    for method in ("mortar", "node_to_segment")[: 4 - dim]:
        out[method] = timed(pair_trace, dataclasses.replace(scene.contact, method=method), *arguments)
        out[f"{method}_per_stiffness"] = out[method] / out["stiffness"]
    return out


def two_body_solve(h: float = 0.004, solver: str = "clarabel") -> dict:
    """The Signorini punch on a foundation (:func:`~convexcontact.scene.bodies_library.punch_on_foundation`): the
    contact solve (formulation, condensation, solve) against one linear solve of both bodies."""
    import convexcontact as cc
    from convexcontact.fem.factorization import factorize

    model = cc.prepare(cc.bodies_library.punch_on_foundation(h, law=cc.Signorini()))
    fem = model.fem
    linear = timed(lambda: factorize(fem.K, dim=fem.dim).solve(fem.f))
    result = model.solve(solver)
    contact = sum(value for stage, value in result.timings.items() if stage != "assembly")
    return {"dofs": fem.n_free, "contact_nodes": fem.contact.m, "formulation": model.formulation,
            "linear": linear, "contact": contact, "contact_per_linear": contact / linear,
            "certificate": result.certificate.worst}


def hertz_errors(h: float, element: str = "P2", faceted_master: bool = True) -> dict:
    """Two cylinders against plane-strain Hertz (docs/bodies.md, Quadratic pairs): the peak's and the fitted p₀'s
    relative errors (p² = p₀²(1 − x²/a²) over p > 0.3 p_max), the closed zone's half-width and a.
    ``faceted_master``: a flat slave on a cylinder R₂ = 2 faceted four times finer; else two faceted cylinders
    R₁ = R₂ = 4 meshed alike. R = 2 and E* = 1/(2(1 − 0.3²)) in both."""
    import numpy as np

    import convexcontact as cc

    if faceted_master:
        scene = cc.bodies_library.two_cylinders(h, radii=(np.inf, 2.0), approach=0.006, width=3.0, height=2.0,
                                                master_h=h / 4, element=element)
    else:
        scene = cc.bodies_library.two_cylinders(h, radii=(4.0, 4.0), approach=0.006, width=4.0, height=2.0,
                                                element=element)
    result = cc.solve(scene)
    a = np.sqrt(4 * result.normal_force * 2.0 / (np.pi * 0.5 / (1 - 0.3**2)))
    p0 = 2 * result.normal_force / (np.pi * a)
    s, p = result.contact.coordinate, result.contact.pressure
    inside = p > 0.3 * p.max()
    (c0, _), *_ = np.linalg.lstsq(np.column_stack([np.ones(inside.sum()), s[inside] ** 2]), p[inside] ** 2, rcond=None)
    return {"peak": result.max_pressure / p0 - 1, "fitted_p0": np.sqrt(c0) / p0 - 1,
            "half_width": result.contact_half_width, "a": a, "certificate": result.certificate.worst,
            "pair_balance": result.certificate.residuals["pair_balance"]}
