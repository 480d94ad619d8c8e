"""Built-in scenes of two bodies: the verification cases of docs/bodies.md."""

from __future__ import annotations

import numpy as np
import skfem as fe

from .bodies import Pair, Part, bodies_scene, facet_index
from .checks import SceneError, finite, positive_integer
from .description import Body, Box, Dirichlet, Material, Rectangle, Scene, Signorini, Traction
from .library import punch_mesh
from .meshing import build_mesh, check_memory

FINE, ROWS = 0.15, 10
"""The cylinder meshes' zone of cells of size h: |x| < FINE, ROWS rows deep (:func:`punch_mesh`)."""


def positive(value, field_name: str, fix: str) -> float:
    number = finite(value, field_name, fix)
    if number <= 0:
        raise SceneError(field_name, f"must be positive, got {number:g}", fix)
    return number


def check_cylinders(h: float, radii, width: float, height: float, master_h: float | None) -> None:
    """Arguments :func:`cylinder_mesh` can build on, checked before any mesh is: cells that fit the fine zone and the
    body (else numpy's "Geometric sequence cannot include zero"), faces that are graphs over the width (else NaN
    nodes), and a size that fits in memory (h = 1e-7 was killed for want of it)."""
    width, height = positive(width, "width", "give the bodies' width"), positive(height, "height", "give their height")
    if width <= 2 * FINE:
        raise SceneError("width", f"{width:g} leaves no room beside the fine zone |x| < {FINE}", f"give width > {2 * FINE}")
    for name, step in (("h", h), ("master_h", master_h)):
        if step is None:
            continue
        step = positive(step, name, f"give a cell size below {FINE}, e.g. 0.01")
        if step > FINE or ROWS * step >= height:
            raise SceneError(name, f"{step:g} does not fit the fine zone (|x| < {FINE}, {ROWS} rows deep in a body "
                             f"{height:g} high)", f"give a cell size of at most {min(FINE, height / (ROWS + 1)):.3g}")
        check_memory(2 * (2 * FINE / step + 50) * (ROWS + 32), 2, name, f"cells of {step:g} across |x| < {FINE}",
                     "use larger cells")
    if np.ndim(radii) != 1 or len(radii) != 2:
        raise SceneError("radii", f"expected two radii (R₁ above, R₂ below), got {radii!r:.60}", "e.g. radii=(1.0, 1.0)")
    for k, radius in enumerate(radii):
        if radius != np.inf:  # convex faces only
            radius = positive(radius, f"radii[{k}]", f"give a radius above {width / 2:g}, or inf for a flat face")
        if radius <= width / 2:
            raise SceneError(f"radii[{k}]", f"{radius:g} does not span the face of width {width:g} (the circle's arc "
                             "must cover it)", f"give a radius above {width / 2:g}, or a narrower width")


def patch_pair(slave_cells: int = 5, master_cells: int = 7, method: str = "mortar", element: str = "P1",
               pressure: float = 0.01, law=None) -> Scene:
    """The contact patch test (Taylor–Papadopoulos): a unit block on another, ``slave_cells`` against
    ``master_cells`` across the interface, a uniform ``pressure`` on top; rollers on the left sides and
    under the lower block. The exact interface pressure is ``pressure`` everywhere."""
    positive_integer(slave_cells, "slave_cells", "give the upper block's cells across, e.g. 5")
    positive_integer(master_cells, "master_cells", "give the lower block's cells across, e.g. 7")
    finite(pressure, "pressure", "give the pressure on top, e.g. 0.01")
    material = Material(E=1.0, nu=0.3)
    parts = [Part("upper", Rectangle(1.0, 1.0, slave_cells, slave_cells, origin=(0.0, 1.0)), material, element),
             Part("lower", Rectangle(1.0, 1.0, master_cells, master_cells), material, element)]
    return bodies_scene(
        parts, Pair("upper.bottom", master="lower.top", method=method, law=law or Signorini()),
        dirichlet=[Dirichlet("lower.bottom", uy=0.0), Dirichlet("lower.left", ux=0.0), Dirichlet("upper.left", ux=0.0)],
        tractions=[Traction("upper.top", pressure=pressure)], name="patch_pair",
    )


def cylinder_mesh(h: float, radius: float, width: float, height: float, upper: bool, fine: float = 0.15,
                  quads: bool = False) -> fe.Mesh:
    """A body of ``width`` × ``height`` whose face on y = 0 is bent into the circle of ``radius`` touching the
    origin (flat for an infinite radius), cells of size h over |x| < ``fine`` near it: the ``upper`` body lies
    above y = 0. Boundaries: ``face`` (the curved one), ``back`` (opposite), ``left``, ``right``."""
    base = punch_mesh(h, fine=fine, width=width, depth=height, quads=quads)  # [−w/2, w/2] × [−height, 0]
    x, y = base.p

    def sag(x):
        return radius - np.sqrt(radius**2 - x**2) if np.isfinite(radius) else 0.0 * x

    sign = 1.0 if upper else -1.0
    p = np.vstack([x, sign * (-y + sag(x) * (1 + y / height))])
    mesh = type(base)(p, base.t[::-1] if upper else base.t)
    names = {"face": "top", "back": "bottom", "left": "left", "right": "right"}
    return mesh.with_boundaries({name: facet_index(mesh, np.sort(base.facets[:, base.boundaries[side]], axis=0))
                                 for name, side in names.items()})


def two_cylinders(h: float = 0.01, radii=(1.0, 1.0), moduli=(1.0, 1.0), nu=(0.3, 0.3), approach: float = 0.01,
                  method: str = "mortar", law=None, width: float = 1.2, height: float = 1.0, master_h: float | None = None,
                  element: str = "P1", shift: float = 0.0) -> Scene:
    """Two bodies with faces of ``radii`` (R₁ above, the slave; R₂ below, the master; inf = flat) pressed together by
    ``approach``: the back of each is moved by half of it towards the other, with its x fixed (plane strain
    Hertz, docs/bodies.md). ``master_h``: the lower body's cell size (default ``h``: non-matching all the same,
    the faces differ). ``shift``: the upper back's x displacement (Cattaneo–Mindlin)."""
    check_cylinders(h, radii, width, height, master_h)
    finite(approach, "approach", "give the approach of the two backs, e.g. 0.01")
    finite(shift, "shift", "give the upper back's x displacement, e.g. 0.0")
    quads = element in ("Q1", "Q2")
    parts = [Part("upper", cylinder_mesh(h, radii[0], width, height, True, quads=quads),
                  Material(E=moduli[0], nu=nu[0]), element),
             Part("lower", cylinder_mesh(master_h or h, radii[1], width, height, False, quads=quads),
                  Material(E=moduli[1], nu=nu[1]), element)]
    return bodies_scene(
        parts, Pair("upper.face", master="lower.face", method=method, law=law or Signorini()),
        dirichlet=[Dirichlet("upper.back", ux=shift, uy=-approach / 2), Dirichlet("lower.back", ux=0.0, uy=approach / 2)],
        name="two_cylinders",
    )


def punch_on_foundation(h: float = 0.01, law=None, approach: float = 0.01, moduli=(10.0, 1.0)) -> Scene:
    """A stiffer cylindrical punch (R = 1, its own mesh) pressed into a flat elastic foundation by ``approach``:
    the dissimilar materials make the normal load shear the interface, so Coulomb friction sticks in the middle
    and slips outside."""
    return two_cylinders(h, radii=(1.0, np.inf), moduli=moduli, approach=approach, law=law, width=1.0,
                         master_h=1.3 * h)



CAP_SAG = 0.9
"""The most a cap's face may sag at its corner, as a fraction of the cap's height: corner cells keep a tenth of it."""

CAP_RADIUS = 1.57
"""The least radius whose sag at the corner, R − √(R² − 2), is at most :data:`CAP_SAG` (1.5611…, rounded up)."""


def sphere_cap_mesh(cells: int, radius: float, upper: bool, grading: float = 12.0, half: bool = False) -> fe.Mesh:
    """A quarter [0, 1]² × [0, 1] (``upper``) or × [−1, 0] of P1 tetrahedra whose face on z = 0 is bent into the
    sphere of ``radius`` touching the origin; cells graded ``grading``:1 towards the origin. Boundaries as
    :class:`~convexcontact.scene.description.Box`'s (the bent face is ``bottom`` above, ``top`` below). ``half``: the
    quarter and its mirror image across x = 0, [−1, 1] × [0, 1] across; ``left`` is then the side on x = −1."""
    base = build_mesh(Body(Box(size=(1.0, 1.0, 1.0), cells=(cells,) * 3, origin=(0.0, 0.0, 0.0 if upper else -1.0),
                               grading=(grading,) * 3, refine=(0.0, 0.0, 0.0))))
    x, y, z = base.p
    sag = radius - np.sqrt(radius**2 - x**2 - y**2)
    sign = 1.0 if upper else -1.0
    bent = type(base)(np.vstack([x, y, z + sign * sag * (1 - sign * z)]), base.t)
    boundaries = {name: np.sort(base.facets[:, facets], axis=0) for name, facets in base.boundaries.items()}
    if half:
        bent, boundaries = mirrored_across_x(bent, boundaries)
    return bent.with_boundaries({name: facet_index(bent, np.sort(vertices, axis=0)) for name, vertices in boundaries.items()})


def mirrored_across_x(mesh: fe.Mesh, boundaries: dict) -> tuple[fe.Mesh, dict]:
    """``mesh`` (on x ≥ 0, a side on x = 0 named ``left``) joined to its mirror image across x = 0, the nodes on the
    plane shared; ``boundaries`` (name → facets' vertices) carried to both halves, the image's ``right`` becoming
    ``left`` and the old ``left`` (now inside) dropped. By hand, not scikit-fem's ``mirrored`` and ``+``: that joins
    by coordinates rounded to 8 decimals (moving every node off its place) and drops the named boundaries."""
    plane = mesh.p[0] == 0.0  # the Box's side on x = 0, built exactly there
    image = np.where(plane, np.arange(mesh.nvertices), mesh.nvertices + np.cumsum(~plane) - 1)
    points = np.hstack([mesh.p, mesh.p[:, ~plane] * np.array([[-1.0], [1.0], [1.0]])])
    joined = type(mesh)(points, np.hstack([mesh.t, image[mesh.t[[1, 0, 2, 3]]]]))  # two rows swapped: orientation kept
    carried = {name: np.hstack([vertices, image[vertices]]) for name, vertices in boundaries.items()
               if name not in ("left", "right")}
    carried["right"], carried["left"] = boundaries["right"], image[boundaries["right"]]
    return joined, carried


def two_spheres(cells: int = 12, radii=(2.0, 2.0), moduli=(1.0, 1.0), nu=(0.3, 0.3), approach: float = 0.012,
                law=None, master_cells: int | None = None, element: str = "P1", half: bool = False,
                shift: float = 0.0) -> Scene:
    """A quarter of two spheres' caps (R₁ above, the slave; R₂ below) pressed together by ``approach`` (3-D
    Hertz), symmetry rollers on x = 0 (``left``) and y = 0 (``front``), the backs moved by half the approach; tetrahedra
    of ``element`` P1 or P2. Radii from :data:`CAP_RADIUS` (below it the quarter's corner cells flatten). ``half``: the
    half model (x from −1 to 1, rollers on y = 0 only, the backs' x held), which ``shift``, the upper back's x
    displacement, needs (Cattaneo–Mindlin: a shear along x breaks the symmetry across x = 0)."""
    for name, value in (("cells", cells), ("master_cells", master_cells)):
        if value is not None:
            positive_integer(value, name, "give the cells along each side, e.g. 12")
    if np.ndim(radii) != 1 or len(radii) != 2:
        raise SceneError("radii", f"expected two radii (R₁ above, R₂ below), got {radii!r:.60}", "e.g. radii=(2.0, 2.0)")
    for k, radius in enumerate(radii):
        radius = positive(radius, f"radii[{k}]", f"give a radius of at least {CAP_RADIUS}")  # convex caps only
        if radius < CAP_RADIUS:  # sag R − √(R² − 2) at the corner, √2 from the axis: 1 (a flat corner cell) at R = 1.5
            problem = (f"bends the quarter's corner (√2 from the axis) by {radius - np.sqrt(radius**2 - 2.0):.3g}, more "
                       f"than {CAP_SAG} of the cap's height 1 (its corner cells flatten or fold)" if radius > np.sqrt(2)
                       else "does not span the unit quarter (its corner lies √2 from the axis)")
            raise SceneError(f"radii[{k}]", f"{radius:g} {problem}", f"give a radius of at least {CAP_RADIUS}")
    finite(approach, "approach", "give the approach of the two backs, e.g. 0.012")
    if element not in ("P1", "P2"):
        raise SceneError("element", f"the caps are tetrahedra, {element!r:.30} is not their element", "element='P1' or 'P2'")
    if half not in (True, False):
        raise SceneError("half", f"expected True or False, got {half!r:.30}", "half=True for the half model")
    if finite(shift, "shift", "give the upper back's x displacement, e.g. 0.0") != 0 and not half:
        raise SceneError("shift", "a shear along x breaks the quarter's symmetry across x = 0 (its rollers hold x there)",
                         "give half=True with a shift")
    parts = [Part("upper", sphere_cap_mesh(cells, radii[0], True, half=half), Material(E=moduli[0], nu=nu[0]), element),
             Part("lower", sphere_cap_mesh(master_cells or cells, radii[1], False, half=half),
                  Material(E=moduli[1], nu=nu[1]), element)]
    sides = (("front", "uy"),) if half else (("left", "ux"), ("front", "uy"))
    rollers = [Dirichlet(f"{part}.{side}", **{axis: 0.0}) for part in ("upper", "lower") for side, axis in sides]
    held = {"ux": shift} if half else {}  # the half model has no roller holding x: the backs do
    return bodies_scene(
        parts, Pair("upper.bottom", master="lower.top", law=law or Signorini()),
        dirichlet=[Dirichlet("upper.top", uz=-approach / 2, **held),
                   Dirichlet("lower.bottom", uz=approach / 2, **({"ux": 0.0} if half else {})), *rollers],
        name="two_spheres",
    )
