"""What a user describes: body, materials, boundaries, obstacle and contact law.

Plain dataclasses. Each checks its own fields where the value enters and raises
:class:`SceneError` naming the field and the fix; nothing is silently changed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .checks import SceneError, finite, finite_vector, of_type, positive_integer, sequence_of
from .expressions import compile_expression
from .load_history import History

ELEMENTS = ("P1", "P2", "Q1", "Q2")
PLANES = ("strain", "stress")


@dataclass(frozen=True)
class Material:
    """Isotropic linear elastic material; ``name`` (a subdomain) only labels errors.

    ``viscosity`` η ≥ 0 makes it a Kelvin–Voigt body (seed 002, eq. 2.3.3), σ = A ε(u̇) + B ε(u) with
    A = (η/E) B: a retardation time τ = η/E (time units of the history). It acts only in a history.

    ``yield_stress`` σ_Y ≥ 0 makes it elasto-viscoplastic (von Mises, Perzyna; docs/plasticity.md):
    ε̇_p = ⟨‖s‖ − √(2/3)σ_Y⟩ s/(η_p‖s‖), s the stress deviator, η_p = ``plastic_viscosity`` ≥ 0 (a stress
    times a time; 0: rate-independent J2 perfect plasticity). It too acts only in a history.
    """

    E: float
    nu: float
    name: str = field(default="material", compare=False)
    viscosity: float = 0.0
    yield_stress: float | None = None
    plastic_viscosity: float = 0.0

    def __post_init__(self):
        of_type(self.name, str, "material.name", "name the mesh subdomain it is for, e.g. 'steel'")
        E = finite(self.E, f"{self.name}.E")
        nu = finite(self.nu, f"{self.name}.nu")
        if E <= 0:
            raise SceneError(f"{self.name}.E", f"Young's modulus must be positive, got {E}",
                             "give E > 0 (a stress, in the units of the loads)")
        if not -1 < nu < 0.5:
            raise SceneError(
                f"{self.name}.nu",
                f"Poisson's ratio must lie in (-1, 0.5), got {nu}",
                "for near-incompressible bodies use e.g. 0.4999 with P2 or Q2",
            )
        if finite(self.viscosity, f"{self.name}.viscosity") < 0:
            raise SceneError(f"{self.name}.viscosity", f"must be ≥ 0 (0 is elastic), got {self.viscosity}",
                             "give η ≥ 0, a stress times a time")
        object.__setattr__(self, "E", E)
        object.__setattr__(self, "nu", nu)
        object.__setattr__(self, "viscosity", float(self.viscosity))
        self._check_plasticity()

    @property
    def plastic(self) -> bool:
        return self.yield_stress is not None

    def _check_plasticity(self):
        """σ_Y ≥ 0 and η_p ≥ 0, not both 0 (no deviatoric stiffness left), no η_p without σ_Y, no Kelvin–Voigt."""
        eta = finite(self.plastic_viscosity, f"{self.name}.plastic_viscosity")
        if eta < 0:
            raise SceneError(f"{self.name}.plastic_viscosity", f"must be ≥ 0 (0 is rate-independent), got {eta}",
                             "give η_p ≥ 0, a stress times a time")
        object.__setattr__(self, "plastic_viscosity", float(eta))
        if self.yield_stress is None:
            if eta > 0:
                raise SceneError(f"{self.name}.plastic_viscosity", "given without a yield stress",
                                 "give yield_stress = σ_Y ≥ 0 too, or drop plastic_viscosity")
            return
        sigma = finite(self.yield_stress, f"{self.name}.yield_stress")
        if sigma < 0 or (sigma == 0 and eta == 0):
            raise SceneError(f"{self.name}.yield_stress", f"must be > 0, or ≥ 0 with plastic_viscosity > 0, got "
                             f"{sigma}" + (" with plastic_viscosity 0: the body would flow freely" if sigma == 0
                                           else ""), "give σ_Y > 0 (a stress), or η_p > 0 for a viscous fluid")
        if self.viscosity:
            raise SceneError(f"{self.name}.viscosity", "a Kelvin–Voigt viscosity beside a yield stress is not built",
                             "drop viscosity (plastic_viscosity is the plastic rate effect), or drop yield_stress")
        object.__setattr__(self, "yield_stress", float(sigma))


@dataclass(frozen=True)
class Rectangle:
    """Built-in rectangle [x0, x0+width] × [y0, y0+height].

    Boundaries are named ``left``, ``right``, ``bottom``, ``top``. ``grading``
    (≥ 1) is the ratio of the largest to the smallest element size: in x the
    elements are finest at ``refine_x`` (default: the middle); in y they are finest
    at the side named ``refine_y`` ("top" or "bottom").
    """

    width: float = 1.0
    height: float = 1.0
    nx: int = 16
    ny: int = 16
    origin: tuple[float, float] = (0.0, 0.0)
    grading: tuple[float, float] = (1.0, 1.0)
    refine_x: float | None = None
    refine_y: str = "top"

    def __post_init__(self):
        for name in ("width", "height"):
            value = finite(getattr(self, name), f"body.{name}")
            if value <= 0:
                raise SceneError(f"body.{name}", f"must be positive, got {value}", "give the side's length")
            object.__setattr__(self, name, value)
        for name in ("nx", "ny"):
            positive_integer(getattr(self, name), f"body.{name}")
        object.__setattr__(self, "origin", finite_vector(self.origin, "body.origin"))
        grading = finite_vector(self.grading, "body.grading")
        if min(grading) < 1:
            raise SceneError("body.grading", f"ratios must be ≥ 1, got {grading}", "give 1 for uniform cells")
        object.__setattr__(self, "grading", grading)
        refine_x = self.origin[0] + self.width / 2 if self.refine_x is None else finite(self.refine_x, "body.refine_x")
        object.__setattr__(self, "refine_x", refine_x)
        if self.refine_y not in ("top", "bottom"):
            raise SceneError("body.refine_y", f"got {self.refine_y!r}",
                             "use 'top' or 'bottom' (the side graded finest)")


SIZES = (1e-100, 1e100)
"""The sides a 3-D box may have, in any unit: the scales' products (E L², E u² L) stay floats."""


@dataclass(frozen=True)
class Box:
    """Built-in box [x0, x0+Lx] × [y0, y0+Ly] × [z0, z0+Lz] of tetrahedra (P1, P2) or hexahedra (Q1, Q2).

    Boundaries: ``left``/``right`` (x = x0, x0+Lx), ``front``/``back`` (y = y0, y0+Ly),
    ``bottom``/``top`` (z = z0, z0+Lz). ``grading`` (≥ 1 per axis) is the ratio of the
    largest to the smallest cell size; cells are finest at the point ``refine``
    (default: the middle of the top face), on both sides of it inside the box.
    """

    size: tuple[float, float, float] = (1.0, 1.0, 1.0)
    cells: tuple[int, int, int] = (8, 8, 8)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    grading: tuple[float, float, float] = (1.0, 1.0, 1.0)
    refine: tuple[float, float, float] | None = None

    def __post_init__(self):
        size = finite_vector(self.size, "body.size", 3)
        if min(size) <= 0:
            raise SceneError("body.size", f"side lengths must be positive, got {size}", "give [Lx, Ly, Lz] > 0")
        if not SIZES[0] <= min(size) <= max(size) <= SIZES[1]:
            raise SceneError("body.size", f"{size} leaves the floats in a 3-D body's scales (forces ∝ L², energies "
                             "∝ L³; sides of 1e200 overflowed)", f"give sides within {SIZES[0]:g} to {SIZES[1]:g}: "
                             "change the length unit")
        if np.ndim(self.cells) != 1 or len(self.cells) != 3:
            raise SceneError("body.cells", f"expected 3 integers [nx, ny, nz], got {self.cells!r:.60}",
                             "give e.g. [8, 8, 8]")
        cells = tuple(positive_integer(n, f"body.cells[{i}]") for i, n in enumerate(self.cells))
        origin = finite_vector(self.origin, "body.origin", 3)
        grading = finite_vector(self.grading, "body.grading", 3)
        if min(grading) < 1:
            raise SceneError("body.grading", f"ratios must be ≥ 1, got {grading}", "give 1 for uniform cells")
        top_middle = (origin[0] + size[0] / 2, origin[1] + size[1] / 2, origin[2] + size[2])
        refine = top_middle if self.refine is None else finite_vector(self.refine, "body.refine", 3)
        for name, value in (("size", size), ("cells", cells), ("origin", origin), ("grading", grading),
                            ("refine", refine)):
            object.__setattr__(self, name, value)


@dataclass(frozen=True)
class MeshFile:
    """A mesh file read with meshio; gmsh physical groups name boundaries and subdomains."""

    path: Path

    def __post_init__(self):
        path = Path(of_type(self.path, (str, Path), "body.mesh", "give the mesh file's path"))
        if not path.is_file():
            raise SceneError("body.mesh", f"no mesh file at {path}", "check the path")
        object.__setattr__(self, "path", path)


@dataclass(frozen=True)
class Body:
    """Geometry, element and 2-D hypothesis of the elastic body.

    ``plane`` (strain or stress) is a 2-D hypothesis: a 3-D body ignores the default
    ``"strain"`` and refuses ``"stress"``.
    """

    geometry: Rectangle | Box | MeshFile
    element: str = "P1"
    plane: str = "strain"

    def __post_init__(self):
        import skfem

        of_type(self.geometry, (Rectangle, Box, MeshFile, skfem.Mesh), "body.geometry",
                "give cc.Rectangle(...), cc.Box(...), cc.MeshFile(path) or a scikit-fem mesh")
        if self.element not in ELEMENTS:
            raise SceneError("body.element", f"unknown element {self.element!r}", f"use one of {ELEMENTS}")
        if self.plane not in PLANES:
            raise SceneError("body.plane", f"unknown hypothesis {self.plane!r}", f"use one of {PLANES}")
        if isinstance(self.geometry, Box):
            check_plane(self.plane, 3)


def check_plane(plane: str, dim: int) -> None:
    """Plane stress has no meaning for a 3-D body."""
    if dim == 3 and plane == "stress":
        raise SceneError("body.plane", "plane stress is a 2-D hypothesis; this body is 3-D",
                         "drop body.plane (3-D bodies use the full 3-D law)")


@dataclass(frozen=True)
class Dirichlet:
    """Prescribed displacement components on a named boundary (None = free; ``uz`` 3-D only)."""

    boundary: str
    ux: float | None = None
    uy: float | None = None
    uz: float | None = None

    COMPONENTS = ("ux", "uy", "uz")

    def __post_init__(self):
        of_type(self.boundary, str, "dirichlet.boundary", "name a boundary of the mesh, e.g. 'bottom'")
        if self.ux is None and self.uy is None and self.uz is None:
            raise SceneError(f"dirichlet[{self.boundary}]", "no component prescribed", "give ux, uy and/or uz")
        for name in self.COMPONENTS:
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, finite(value, f"dirichlet[{self.boundary}].{name}"))


@dataclass(frozen=True)
class Traction:
    """Surface load on a named boundary: a pressure (pushing inward) or a vector."""

    boundary: str
    pressure: float | None = None
    vector: tuple[float, float] | None = None

    def __post_init__(self):
        of_type(self.boundary, str, "traction.boundary", "name a boundary of the mesh, e.g. 'top'")
        where = f"traction[{self.boundary}]"
        if (self.pressure is None) == (self.vector is None):
            raise SceneError(where, "pressure and vector both given, or neither",
                             "give exactly one: pressure = p (pushing inward) or vector = (tx, ty[, tz])")
        if self.pressure is not None:
            object.__setattr__(self, "pressure", finite(self.pressure, f"{where}.pressure"))
        else:
            object.__setattr__(self, "vector", finite_vector(self.vector, f"{where}.vector", (2, 3)))


GapFunction = Callable[..., np.ndarray]


COVERED = 1e-12
"""Relative round-off by which a node may lie beyond a cylinder's or sphere's radius (a radius equal to
the half-width of Γ_C: the gap there is R, along a vertical tangent)."""


MOTION = ("depth", "force", "tangential_force", "normal")
SHAPE_FIELDS = {"flat": ("gap", *MOTION), "expression": ("expression", *MOTION),
                **dict.fromkeys(("parabolic", "cylinder", "sphere", "flat_punch"), ("radius", "center", *MOTION))}
"""The fields each obstacle shape reads (besides ``shape``); another one given is refused, not ignored."""


def check_shape_fields(shape: str, given) -> None:
    """Refuse the obstacle fields in ``given`` that a ``shape`` does not read (a gap given to a punch was
    ignored): the one check of the Python API and of the TOML reader, which passes the keys of [obstacle]."""
    if shape not in Obstacle.SHAPES:
        raise SceneError("obstacle.shape", f"unknown shape {shape!r}", f"use one of {Obstacle.SHAPES}")
    for name in given:
        if name != "shape" and name not in SHAPE_FIELDS[shape]:
            takers = [other for other, names in SHAPE_FIELDS.items() if name in names]
            raise SceneError(f"obstacle.{name}", f"a {shape} obstacle has no {name} (shape = {shape!r} reads "
                             f"{', '.join(SHAPE_FIELDS[shape])})",
                             f"drop {name}, or use a shape that reads it: {', '.join(takers)}")


def _same(value, default) -> bool:
    """Whether a field holds its default (a point given as a tuple or an array is never the default 0)."""
    return np.ndim(value) == 0 and np.ndim(default) == 0 and (value is default or value == default)


@dataclass(frozen=True)
class Obstacle:
    """Rigid obstacle, described by the initial gap g along the outward normal of Γ_C.

    ``shape`` (r = distance from the punch axis: in 2-D the coordinate along Γ_C minus
    ``center``; in 3-D the distance, in the mean tangent plane of Γ_C, from the axis
    through the point ``center`` along the mean normal):
      - ``"flat"``: g = ``gap`` everywhere;
      - ``"parabolic"``: g = r²/(2R) − d (a paraboloid of revolution in 3-D);
      - ``"cylinder"`` (2-D) / ``"sphere"`` (3-D; in 2-D the same circle):
        g = R − sqrt(R² − r²) − d, exact;
      - ``"expression"``: g = ``expression``(x, y[, z]), a formula string or a callable.

      - ``"flat_punch"``: a rigid flat punch with sharp edges, of half-width ``radius`` (2-D) or
        circular of that radius (3-D): g = −d under it; the contact boundary is cut to the
        facets entirely under the punch (nothing outside can touch it).

    ``normal``: what the gap and the non-penetration are measured along — ``"body"`` (default),
    the outward normal of Γ_C at each node, or ``"obstacle"``, the obstacle's normal at the
    node's closest point: g = the distance to a cylinder or sphere, whatever the node's distance
    from the axis (flat and flat punch: the obstacle's face normal, the mean normal of Γ_C).
    ``center``: a number in 2-D, a point (x, y, z) in 3-D (the default 0 is the origin).
    Exactly one of ``depth`` (indentation d, displacement control) and ``force``
    (resultant P, per unit thickness in 2-D, pressing the obstacle on the body; force
    control: d becomes an unknown) may be given for the shaped obstacles; a flat
    obstacle or an expression uses ``depth`` = 0 unless told otherwise.
    ``tangential_force`` Q (friction laws, 2-D only) pulls the obstacle along the mean
    tangent of Γ_C; its tangential translation becomes an unknown.
    A field the shape does not read (:data:`SHAPE_FIELDS`: a gap given to a punch) is refused, as in a
    scene file; with ``normal = "obstacle"`` a cylinder or sphere needs ``depth`` < ``radius`` (its centre
    in front of Γ_C, where its normal is defined).
    """

    shape: str = "flat"
    gap: float = 0.0
    radius: float | None = None
    center: float | tuple[float, float, float] = 0.0
    depth: float | None = None
    force: float | None = None
    expression: str | GapFunction | None = None
    tangential_force: float | None = None
    normal: str = "body"

    SHAPES = ("flat", "parabolic", "cylinder", "sphere", "flat_punch", "expression")
    NORMALS = ("body", "obstacle")
    CLOSEST_POINT = ("flat", "cylinder", "sphere", "flat_punch")
    """The shapes whose closest point is known (``normal = "obstacle"``)."""

    def __post_init__(self):
        defaults = {name: spec.default for name, spec in self.__dataclass_fields__.items()}
        check_shape_fields(self.shape, [name for name in ("gap", "radius", "center", "expression")
                                        if not _same(getattr(self, name), defaults[name])])
        object.__setattr__(self, "gap", finite(self.gap, "obstacle.gap", "give the gap as a number (0: touching)"))
        for name in ("radius", "depth", "force", "tangential_force"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, finite(value, f"obstacle.{name}"))
        center = finite(self.center, "obstacle.center") if np.ndim(self.center) == 0 else \
            finite_vector(self.center, "obstacle.center", 3)
        object.__setattr__(self, "center", center)
        if self.shape in ("parabolic", "cylinder", "sphere", "flat_punch") and (self.radius is None or self.radius <= 0):
            raise SceneError("obstacle.radius", f"a {self.shape} obstacle needs a positive radius, got {self.radius}",
                             "give radius = R > 0 (a length)")
        if self.normal not in self.NORMALS:
            raise SceneError("obstacle.normal", f"got {self.normal!r}", f"use one of {self.NORMALS}")
        if self.normal == "obstacle" and self.shape not in self.CLOSEST_POINT:
            raise SceneError("obstacle.normal", f"the {self.shape} obstacle has no closest point to measure along",
                             f"use normal = 'body', or a shape among {self.CLOSEST_POINT}")
        if self.normal == "obstacle" and self.shape in ("cylinder", "sphere") and (self.depth or 0.0) >= self.radius:
            raise SceneError("obstacle.depth", f"{self.depth} ≥ the radius {self.radius}: the {self.shape}'s centre "
                             "lies on or behind the contact boundary's mean plane, so its normal is undefined at the "
                             "point on the axis (obstacle.center) and points away from the body at every other node",
                             "give a depth below the radius, or normal = 'body' (the gap along Γ_C's own normal)")
        if self.shape == "expression":
            if self.expression is None:
                raise SceneError("obstacle.expression", "missing", "give a formula in x and y, e.g. 'x**2/2 - 0.01'")
            of_type(self.expression, (str, Callable), "obstacle.expression",
                    "give a formula in x and y, e.g. 'x**2/2 - 0.01', or a function g(x, y)")
            if isinstance(self.expression, str):
                compile_expression(self.expression, "obstacle.expression")
        if self.depth is not None and self.force is not None:
            raise SceneError("obstacle", "both depth and force given",
                             "give depth (displacement control) or force (force control), not both")
        if self.force is not None and self.force < 0:
            raise SceneError("obstacle.force", f"must be ≥ 0 (it presses the obstacle on the body), got {self.force}",
                             "give P ≥ 0, or depth to pull the obstacle back")

    @property
    def force_controlled(self) -> bool:
        return self.force is not None

    def axis(self, dim: int) -> np.ndarray:
        """The punch axis point in 3-D (``center``); refuses a 2-D/3-D mismatch."""
        if dim == 3 and np.ndim(self.center) == 0 and self.center != 0.0:
            raise SceneError("obstacle.center", f"a number ({self.center}) in a 3-D scene",
                             "give the point [x, y, z] the punch axis passes through")
        if dim == 2 and np.ndim(self.center) == 1:
            raise SceneError("obstacle.center", "a point in a 2-D scene", "give the coordinate along Γ_C")
        return np.zeros(3) if np.ndim(self.center) == 0 else np.array(self.center)

    def shape_gap(self, points: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Initial gap in user units before indentation (``depth`` not subtracted).

        ``points`` (m × d) are the node coordinates, ``r`` their distance from the punch axis.
        """
        dim = points.shape[1]
        if self.shape == "flat":
            return np.full(r.shape, self.gap)
        if self.shape == "flat_punch":  # Γ_C is cut to the punch (fem/contact.py)
            return np.zeros(r.shape)
        if self.shape == "expression":
            return evaluate_field(self.expression, "obstacle.expression", points, minimum=-np.inf)
        if dim == 3 and self.shape == "cylinder":
            raise SceneError("obstacle.shape", "a cylinder is a 2-D punch", "use 'sphere' or 'parabolic' in 3-D")
        if self.shape == "parabolic":
            with np.errstate(over="ignore"):  # a gap past the floats is refused by name (drivers/scales.py)
                return r**2 / (2.0 * self.radius)
        outside = np.abs(r) > self.radius * (1.0 + COVERED)
        if outside.any():
            raise SceneError(
                "obstacle.radius",
                f"the {self.shape} (radius {self.radius}) does not cover the contact boundary",
                "use a larger radius, normal = 'obstacle' (the distance to the obstacle, defined everywhere), "
                "the parabolic shape, or a smaller contact boundary",
            )
        # R − sqrt(R² − r²) written without its cancellation (R ≫ r lost every digit) or R² (overflow)
        ratio = r / self.radius
        return r * ratio / (1.0 + np.sqrt(np.maximum(1.0 - ratio**2, 0.0)))

    def closest_point(self, offset: np.ndarray, mean_normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gap, unit normals) along the obstacle's normal (``normal = "obstacle"``), in user units, the
        indentation included. ``offset`` (m × d) is each node's offset from the axis in Γ_C's mean plane.

        A cylinder or sphere touching that plane on the axis and advanced by d has its centre at
        (R − d) n̄ from the axis point: node i sees it at c_i = (R − d) n̄ − o_i, at the distance ‖c_i‖ − R
        along c_i / ‖c_i‖ (moving towards the centre closes the gap). Under force control d is an
        unknown: the frame is taken at d = 0 and the advance enters linearly, as for ``"body"``.
        """
        depth = self.depth or 0.0
        if self.shape in ("flat", "flat_punch"):
            return self.shape_gap(offset, np.zeros(len(offset))) - depth, np.tile(mean_normal, (len(offset), 1))
        # the offsets lie in the mean plane: ‖c_i‖ = hypot(R − d, ‖o_i‖), and ‖c_i‖ − R = (‖o_i‖² − d(2R − d)) /
        # (‖c_i‖ + R) in factors that neither cancel (R ≫ ‖o_i‖) nor overflow (R², ‖o_i‖²); R > d (__post_init__)
        height, across = self.radius - depth, np.linalg.norm(offset, axis=1)
        distance = np.hypot(height, across)
        gap = across * (across / (distance + self.radius)) - depth * ((self.radius + height) / (distance + self.radius))
        return gap, (height * mean_normal - offset) / distance[:, None]


@dataclass(frozen=True)
class Signorini:
    """Frictionless unilateral contact.

    ``non_penetration``: ``"nodal"`` (u_N ≤ g at every contact node, lumped),
    ``"weak"`` (Hild's continuous P1 multipliers: M(u_N − g) ≤ 0) or ``"gauss"`` (u_N ≤ g at
    the Gauss points of Γ_C, the obstacle's gap evaluated there: the limit of penalty codes
    that penalize at quadrature points; ``order``: the degree the rule integrates exactly,
    scikit-fem's default for the element when None).
    """

    non_penetration: str = "nodal"
    order: int | None = None

    def __post_init__(self):
        _check_points(self, ("nodal", "weak", "gauss"))


ORDER_PER_DEGREE = 4
"""The highest Gauss rule on Γ_C that means something is of order 4 × the element's degree (scikit-fem's
``maxdeg``; its default rule is 2 ×): it integrates exactly a penalty energy (u_N − g)₊^(p+1), p ≤ 3, of a gap
in the element's space. More points only sample a curved gap between nodes, which a finer mesh does properly
(order 10⁶ asked for 1.8 TiB)."""

ELEMENT_DEGREES = {"P1": (1, 1), "P2": (2, 2), "Q1": (2, 3), "Q2": (4, 6)}
"""scikit-fem's ``maxdeg`` of each element in 2-D and 3-D."""


def check_order(order, degree: int | None = None, body: str = "") -> int:
    """A Gauss rule's ``order`` in 1 … :data:`ORDER_PER_DEGREE` × ``degree`` (the element's ``maxdeg``; None:
    the largest of any element, before the body is known); ``body`` says which element in the message."""
    order = positive_integer(order, "contact.order", "give the degree the rule integrates exactly, e.g. 2")
    limit = ORDER_PER_DEGREE * (degree or max(max(pair) for pair in ELEMENT_DEGREES.values()))
    if order > limit:
        ranges = ", ".join(f"{name} 1 to {ORDER_PER_DEGREE * pair[0]} (3-D: to {ORDER_PER_DEGREE * pair[1]})"
                           for name, pair in ELEMENT_DEGREES.items())
        raise SceneError("contact.order", f"{order} is beyond the Gauss rules that mean anything on "
                         f"{body or 'any element'}: 1 to {limit} ({ORDER_PER_DEGREE} × the element's degree; "
                         f"{ranges})", "give an order in that range, or refine the mesh where the obstacle curves")
    return order


def _check_points(law, allowed: tuple[str, ...]) -> None:
    """The ``non_penetration`` of a frictionless law, and the Gauss rule's ``order`` that goes with "gauss"."""
    if law.non_penetration not in allowed:
        raise SceneError("contact.non_penetration", f"got {law.non_penetration!r}", f"use one of {allowed}")
    if law.order is not None:
        if law.non_penetration != "gauss":
            raise SceneError("contact.order", "a Gauss rule's order is for non_penetration = 'gauss'",
                             "drop order, or set non_penetration = 'gauss'")
        object.__setattr__(law, "order", check_order(law.order))


@dataclass(frozen=True)
class NormalCompliance:
    """Normal compliance (penalty) contact: σ_N = −c_N (u_N − g)_+^p (book, ch. 2.6).

    ``stiffness`` c_N > 0 (a pressure per length^p), ``exponent`` p ≥ 1. The energy
    Σ w_i c_N/(p+1) (u_N,i − g_i)_+^(p+1) is a QP for p = 1 and uses power cones for
    p > 1. c_N → ∞ recovers Signorini. Alone it is a frictionless law; given as
    ``compliance`` to Tresca or Coulomb it replaces their non-penetration.
    ``non_penetration``: ``"nodal"`` (the energy lumped at the nodes) or ``"gauss"``: the
    penalty at the Gauss points of Γ_C, Σ_q ω_q c_N/(p+1) (u_N(x_q) − g(x_q))_+^(p+1), the gap
    evaluated at each point — the penalty codes that integrate their contact term (sfepy's
    ``dw_contact_*``) solve this problem; ``order`` as for :class:`Signorini`. Alone only.
    """

    stiffness: float
    exponent: float = 1.0
    non_penetration: str = "nodal"
    order: int | None = None

    def __post_init__(self):
        _check_points(self, ("nodal", "gauss"))
        if finite(self.stiffness, "contact.stiffness") <= 0:
            raise SceneError("contact.stiffness", f"c_N must be positive, got {self.stiffness}",
                             "give c_N > 0 (a pressure per length^p), or Signorini() for no penetration")
        if finite(self.exponent, "contact.exponent") < 1:
            raise SceneError("contact.exponent", f"p must be ≥ 1, got {self.exponent}", "give 1 (a QP) or more")
        object.__setattr__(self, "stiffness", float(self.stiffness))
        object.__setattr__(self, "exponent", float(self.exponent))


NodalValues = float | str | np.ndarray | Callable
"""A field on Γ_C: a constant, a formula in x, y (and z), a callable f(x, y[, z]), or nodal values."""


FUNCTION_FIX = "return one value per point (or one number) from arrays x, y[, z], e.g. lambda x, y: 0.3 + 0 * x"


@dataclass(frozen=True, eq=False)
class PerPair:
    """A law's field given contact pair by contact pair: ``values[k]`` (a :data:`NodalValues`) on the
    nodes of the scene's ``contact[k]``, None where that pair has no friction (docs/bodies.md). Built by
    :func:`convexcontact.scene.bodies.combined_law` from the pairs' own laws, each already checked."""

    values: tuple

    def __eq__(self, other):
        return isinstance(other, PerPair) and len(self.values) == len(other.values) and all(
            type(a) is type(b) and (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b)
            for a, b in zip(self.values, other.values))

    __hash__ = None


def field_at_nodes(value, field_name: str, coords: np.ndarray, pieces=()) -> np.ndarray:
    """A field's values at the contact nodes ``coords`` (user units); a :class:`PerPair` field pair by pair
    on the rows of ``pieces`` (the trace's (rows, …) of each pair), 0 where a pair has none."""
    if not isinstance(value, PerPair):
        return evaluate_field(value, field_name, coords)
    values = np.zeros(len(coords))
    for index, ((rows, *_), part) in enumerate(zip(pieces, value.values, strict=True)):
        if part is not None:
            values[rows] = evaluate_field(part, f"contact[{index}].{field_name.split('.')[-1]}", coords[rows])
    return values


def check_field(value, field_name: str, minimum: float = 0.0):
    """Validate a :data:`NodalValues` field (finite, ≥ ``minimum``); return it unchanged in kind."""
    if isinstance(value, PerPair):  # its pairs' fields are checked by their own laws
        return value
    if isinstance(value, str):
        compile_expression(value, field_name)
        return value
    if callable(value):
        return value
    if np.ndim(value) == 0:
        number = finite(value, field_name)
        if number < minimum:
            raise SceneError(field_name, f"must be ≥ {minimum}, got {number}", f"give a value ≥ {minimum}")
        return number
    try:
        array = np.array(value, dtype=float)  # a copy: the user's array is never changed
    except (TypeError, ValueError):
        raise SceneError(field_name, f"expected numbers, got {value!r:.60}",
                         "give a number, a formula, a function or one number per contact node") from None
    if array.ndim != 1 or not np.isfinite(array).all() or (array < minimum).any():
        raise SceneError(field_name, f"nodal values must be a 1-D array of finite numbers ≥ {minimum}",
                         "give one number per contact node, ordered as result.contact.coords")
    return array


def evaluate_field(value, field_name: str, points: np.ndarray, minimum: float = 0.0) -> np.ndarray:
    """Values of a :data:`NodalValues` field at ``points`` (m × d: x, y[, z] columns)."""
    coordinates = dict(zip("xyz", np.asarray(points, dtype=float).T))
    shape = (len(points),)
    if isinstance(value, str):
        values = compile_expression(value, field_name)(**coordinates)
    elif callable(value):
        returned = called(value, field_name, tuple(coordinates.values()))
        if returned.shape not in ((), shape):
            raise SceneError(field_name, f"the function returned shape {returned.shape} for {shape[0]} points",
                             FUNCTION_FIX)
        values = np.broadcast_to(returned, shape).copy()
    elif np.ndim(value) == 0:
        values = np.full(shape, float(value))
    else:
        if value.size != shape[0]:
            raise SceneError(field_name, f"{value.size} nodal values for {shape[0]} contact nodes",
                             "give one value per contact node, ordered as result.contact.coords")
        values = np.array(value)
    if not np.isfinite(values).all() or (values < minimum).any():
        raise SceneError(field_name, f"values must be finite and ≥ {minimum}" if minimum > -np.inf
                         else "the function returned NaN or infinity",
                         "give a formula or function finite (and within bounds) at every point of Γ_C")
    return values


def called(function: Callable, field_name: str, coordinates: tuple[np.ndarray, ...]) -> np.ndarray:
    """``function(x, y[, z])`` as floats; whatever goes wrong in the user's function is named as the field's."""
    try:
        return np.asarray(function(*coordinates), dtype=float)
    except Exception as error:  # the user's code: any failure is a bad field, with its own words kept
        raise SceneError(field_name, f"the function failed when called with {len(coordinates)} coordinate arrays "
                         f"({type(error).__name__}: {error})", FUNCTION_FIX) from error


QUADRATURES = ("nodal", "gauss")


@dataclass(frozen=True)
class Tresca:
    """Friction with a given slip bound s(x) ≥ 0 (traction per unit length): exact SOCP.

    ``quadrature`` of the friction term Σ s|u_T|: at the contact nodes (lumped) or at
    Gauss points of Γ_C. ``regularization`` ε > 0 (a length) replaces |u_T| by
    sqrt(u_T² + ε²) (Hild's regularized law), to measure how far ε moves the answer.
    """

    slip_bound: NodalValues = 0.0
    non_penetration: str = "nodal"
    quadrature: str = "nodal"
    regularization: float | None = None
    compliance: NormalCompliance | None = None

    def __post_init__(self):
        object.__setattr__(self, "slip_bound", check_field(self.slip_bound, "contact.slip_bound"))
        _check_options(self)


@dataclass(frozen=True)
class Coulomb:
    """Coulomb friction, coefficient F(x) ≥ 0, solved by a Picard map over normal pressures.

    s ← (1 − ω) s + ω F·S(λ_N(s)), each step an exact Tresca program. ``smoothing_radius``
    ρ > 0 gives Oden–Duvaut's nonlocal law (S the mollifier ω_ρ along Γ_C); ρ = 0 is the
    local law. ``initial_pressure``: None starts from the frictionless (Signorini)
    pressures, as Oden's algorithm III; otherwise a field of pressures. ``acceleration``:
    how many earlier steps Anderson mixing combines with the relaxed one (0: the plain map).
    ``newton``: on the dual, with the solver left to the driver, seek the fixed point first by
    Newton's method on the Coulomb problem itself; the map runs where it stalls. False runs the map
    alone.
    """

    friction: NodalValues = 0.0
    non_penetration: str = "nodal"
    quadrature: str = "nodal"
    regularization: float | None = None
    smoothing_radius: float = 0.0
    relaxation: float = 1.0
    tol: float = 1e-8
    max_iterations: int = 100
    initial_pressure: NodalValues | None = None
    compliance: NormalCompliance | None = None
    acceleration: int = 5
    newton: bool = True

    def __post_init__(self):
        object.__setattr__(self, "friction", check_field(self.friction, "contact.friction"))
        _check_options(self)
        if finite(self.smoothing_radius, "contact.smoothing_radius") < 0:
            raise SceneError("contact.smoothing_radius", f"must be ≥ 0, got {self.smoothing_radius}",
                             "give 0 (the local law) or a roughness length ρ > 0")
        if not 0 < finite(self.relaxation, "contact.relaxation") <= 1:
            raise SceneError("contact.relaxation", f"ω must lie in (0, 1], got {self.relaxation}",
                             "give 1 (the plain map) or less to damp it, e.g. 0.5")
        if not 0 < finite(self.tol, "contact.tol") < 1:
            raise SceneError("contact.tol", f"a relative change of the slip bounds, in (0, 1), got {self.tol}",
                             "give e.g. 1e-8")
        positive_integer(self.max_iterations, "contact.max_iterations")
        if not (isinstance(self.acceleration, (int, np.integer)) and self.acceleration == 0):
            positive_integer(self.acceleration, "contact.acceleration", "give 0 (the plain map) or a depth such as 5")
        if not isinstance(self.newton, bool):
            raise SceneError("contact.newton", f"expected true or false, got {self.newton!r}",
                             "give True (Newton's method first) or False (the Picard map alone)")
        if self.initial_pressure is not None:
            object.__setattr__(
                self, "initial_pressure", check_field(self.initial_pressure, "contact.initial_pressure")
            )


def _check_options(law):
    if law.compliance is not None and not isinstance(law.compliance, NormalCompliance):
        raise SceneError("contact.compliance", f"expected NormalCompliance, got {law.compliance!r:.40}",
                         "give cc.NormalCompliance(stiffness, exponent)")
    if law.compliance is not None and law.compliance.non_penetration != "nodal":
        raise SceneError("contact.compliance", "a friction law's compliance is lumped node-wise",
                         "give NormalCompliance(stiffness, exponent) without non_penetration")
    if law.compliance is not None and law.non_penetration != "nodal":
        raise SceneError("contact.non_penetration", "normal compliance is lumped node-wise", "use 'nodal'")
    if law.non_penetration not in ("nodal", "weak"):
        fix = "use 'nodal' or 'weak' (Gauss-point non-penetration is built for the frictionless law only)"
        raise SceneError("contact.non_penetration", f"got {law.non_penetration!r}", fix)
    if law.quadrature not in QUADRATURES:
        raise SceneError("contact.quadrature", f"got {law.quadrature!r}", f"use one of {QUADRATURES}")
    if law.quadrature == "gauss" and law.non_penetration == "weak":
        raise SceneError("contact.quadrature", "Gauss points go with nodal non-penetration",
                         "the weak form already integrates the friction term with the boundary mass M")
    if law.regularization is not None and finite(law.regularization, "contact.regularization") <= 0:
        raise SceneError("contact.regularization", f"ε must be positive, got {law.regularization}",
                         "give ε > 0 (a length), or omit it for the exact law")


ContactLaw = Signorini | NormalCompliance | Tresca | Coulomb


def has_friction(law: ContactLaw) -> bool:
    return isinstance(law, (Tresca, Coulomb))


def compliance_of(law: ContactLaw) -> NormalCompliance | None:
    """The normal compliance of a law (None: Signorini's non-penetration)."""
    return law if isinstance(law, NormalCompliance) else getattr(law, "compliance", None)


@dataclass(frozen=True)
class Contact:
    """The contact boundary Γ_C, the obstacle facing it and the contact law."""

    boundary: str
    obstacle: Obstacle = field(default_factory=Obstacle)
    law: ContactLaw = field(default_factory=Signorini)

    def __post_init__(self):
        of_type(self.boundary, str, "contact.boundary", "name a boundary of the mesh, e.g. 'top'")
        of_type(self.obstacle, Obstacle, "contact.obstacle", "give cc.Obstacle(shape, ...)")
        of_type(self.law, (Signorini, NormalCompliance, Tresca, Coulomb), "contact.law",
                "give cc.Signorini(), cc.NormalCompliance(c), cc.Tresca(s) or cc.Coulomb(F)")
        if self.obstacle.tangential_force is not None and not has_friction(self.law):
            raise SceneError("obstacle.tangential_force", "a tangential force needs friction",
                             "use law = 'tresca' or 'coulomb', or drop the tangential force")


@dataclass(frozen=True)
class Scene:
    """A complete contact problem of 2-D or 3-D linear elastostatics (the mesh decides)."""

    body: Body
    materials: Material | dict[str, Material]
    dirichlet: tuple[Dirichlet, ...]
    contact: Contact
    tractions: tuple[Traction, ...] = ()
    body_force: tuple[float, float] = (0.0, 0.0)
    name: str = "scene"
    history: History | None = None  # a load history (scene/load_history.py); None: one static problem

    def __post_init__(self):
        of_type(self.body, Body, "body", "give cc.Body(geometry, element)")
        of_type(self.contact, Contact, "contact", "give cc.Contact(boundary, obstacle, law)")
        of_type(self.name, str, "name")
        if isinstance(self.materials, dict):
            for name, material in self.materials.items():
                of_type(name, str, "materials", "name each material by its mesh subdomain, e.g. {'steel': cc.Material(…)}")
                of_type(material, Material, f"materials.{name}", "give cc.Material(E, nu)")
        else:
            of_type(self.materials, Material, "materials", "give cc.Material(E, nu) or {subdomain: cc.Material}")
        object.__setattr__(self, "dirichlet", sequence_of(self.dirichlet, Dirichlet, "dirichlet",
                                                          "give a list of cc.Dirichlet(boundary, ux=…, uy=…)"))
        object.__setattr__(self, "tractions", sequence_of(self.tractions, Traction, "tractions",
                                                          "give a list of cc.Traction(boundary, pressure=…)"))
        object.__setattr__(self, "body_force", finite_vector(self.body_force, "body_force", (2, 3)))
        if not self.dirichlet:
            raise SceneError(
                "dirichlet",
                "no Dirichlet boundary: the body can move rigidly",
                "fix at least one boundary, e.g. [[dirichlet]] boundary = 'bottom', ux = 0, uy = 0",
            )
        self._check_dimension()
        if self.history is not None and not isinstance(self.history, History):
            raise SceneError("history", f"expected a History, got {type(self.history).__name__}",
                             "build it with cc.History(times=[...], values={'obstacle.depth': [...]})")
        if isinstance(self.materials, dict) and not self.materials:
            raise SceneError("materials", "empty", "give [material] E and nu")

    def with_law(self, law) -> Scene:
        """The same scene under another contact law (a sweep over F, slip bounds, ε, …)."""
        return replace(self, contact=replace(self.contact, law=law))

    def _check_dimension(self):
        """Components a built-in body cannot have (mesh files are checked when assembled)."""
        dim = {Rectangle: 2, Box: 3}.get(type(self.body.geometry))
        if dim != 2:
            return
        for condition in self.dirichlet:
            if condition.uz is not None:
                raise SceneError(f"dirichlet[{condition.boundary}].uz", "a 2-D body has no component 3",
                                 "prescribe only ux and uy")
        for traction in self.tractions:
            if traction.vector is not None and len(traction.vector) != 2:
                raise SceneError(f"traction[{traction.boundary}].vector", "3 components for a 2-D body",
                                 "give 2 numbers")
        if len(self.body_force) != 2 and any(self.body_force):
            raise SceneError("body_force", "3 components for a 2-D body", "give 2 numbers")
