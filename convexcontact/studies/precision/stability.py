"""Stability suite: stiff and extreme cases that must give a correct answer or a clear error.

Every case builds a scene and a :class:`Check` against a reference that does not come from
the solve being judged: a closed form (uniform compression, Hertz, Hild's one-triangle
solutions), a conservation or invariance law (units, positive homogeneity of contact
problems in the load and the gap), or an independent solve (the linear elastic solve
K⁻¹f, Signorini for F = 0, a bonded solve for full stick).

A row passes when the library gives an answer within the check's tolerance (status
``solved`` or ``inaccurate``), or fails clearly (``infeasible``, ``failed``, ``not
converged`` with a message, or an input error naming a field). A ``solved`` answer with a
large error is a wrong answer reported as solved, the one outcome the suite exists to
catch. ::

    from convexcontact.studies.precision.stability import run, table
    print(table(run(quick=True)))
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
import skfem as fe
from scipy.optimize import brentq

import convexcontact as cc
from convexcontact.analytic import hertz_plane_strain, hertz_sphere, hild_one_triangle_solutions
from convexcontact.results.output import check_new_file
from convexcontact.scene.bodies_library import two_spheres
from convexcontact.scene.description import Coulomb, SceneError
from convexcontact.scene.library import HERTZ_FORCE, frictional_punch, punch_mesh
from convexcontact.scene.library import hertz_sphere as hertz_sphere_scene
from convexcontact.scene.meshing import graded, tensor_mesh

PATHS = {
    "clarabel/primal": ("clarabel", "primal"),
    "osqp/primal": ("osqp", "primal"),
    "clarabel/dual": ("clarabel", "dual"),
    "auto/dual": ("auto", "dual"),
    "cvxpy/primal": ("cvxpy", "primal"),
}
"""Solver paths: name → (solver, formulation). Every path runs with the library's defaults; auto/dual is the
default path (newton-cg first where the dual is in its bound form, else Clarabel)."""

CVXPY_MAX_DOFS = 1500
"""The cvxpy path (a transparent model, not a fast one) runs only on scenes this small."""

EXACT = 1e-5
"""Tolerance of checks against exact references: the library certifies at 1e-6, one decade is left for
the conditioning between a residual and the error of the fields."""

INVARIANT = 1e-8
"""Tolerance of invariances on the same path (units, homogeneity): the scaled programs are the same."""

ZERO = 1e-10
"""Absolute tolerance (in units of the body size and of E) of fields that must vanish."""

UNTRUSTED = 1e-5
"""Certificates above this say "do not trust pressures" (docs/certificate.md)."""

CLEAR = ("infeasible", "unbounded", "failed", "not converged")
"""Statuses that are clear failures when they come with a message."""


@dataclass
class Check:
    """How far a result is from its reference (``error``), and how far it may be (``tol``).

    ``reference`` says what the answer is compared with; ``note`` adds a line to the table
    (e.g. a locking indicator); ``known`` names a limitation of the discretization that is
    expected to give a large error (e.g. ``"locking"``): such a row is listed as known,
    not as a wrong answer, and passes once the library flags it in its own output.
    """

    error: Callable[[cc.ContactResult], float]
    tol: float
    reference: str
    note: Callable[[cc.ContactResult], str] | None = None
    known: str | None = None

    def __call__(self, result: cc.ContactResult) -> float:
        return float(self.error(result))


# ---------------------------------------------------------------- helpers on results


def same_path(scene: cc.Scene, result: cc.ContactResult, cache: dict) -> cc.ContactResult:
    """``scene`` solved on the path (solver, formulation) of ``result``, once per path."""
    key = (result.solver.split(":")[0], result.formulation)
    if key not in cache:
        cache[key] = cc.solve(scene, key[0], formulation=key[1])
    reference = cache[key]
    if not reference.solved:
        raise RuntimeError(f"the reference solve on {key} returned {reference.status}: {reference.message}")
    return reference


def relative(a: np.ndarray, b: np.ndarray) -> float:
    """max |a − b| / max |b| (absolute when b vanishes)."""
    scale = np.abs(b).max(initial=0.0)
    return float(np.abs(a - b).max(initial=0.0) / (scale if scale > 0 else 1.0))


def nodewise(a: np.ndarray, b: np.ndarray) -> float:
    """max_i |a_i − b_i| / |b_i|: every node against its own value (b ≠ 0), so that a region carrying
    1e-6 of the largest pressure is judged as strictly as the rest."""
    return float((np.abs(a - b) / np.abs(b)).max(initial=0.0))


def field_difference(result, reference, displacement=1.0, pressure=1.0) -> float:
    """Relative difference of displacement and contact pressure, ``result`` divided by the scales first."""
    return max(relative(result.displacement / displacement, reference.displacement),
               relative(result.contact.pressure / pressure, reference.contact.pressure))


def nodal_normal_force(result) -> np.ndarray:
    """Compressive normal force of the obstacle at each contact node (user units)."""
    return -np.einsum("ij,ij->i", result.contact.forces, result.contact.normals)


def moment_half_width(result) -> float:
    """a from the second moment of the contact forces: ∫p x² / ∫p = a²/4 for Hertz.

    Insensitive to the node-to-node oscillation of the pressure of near-incompressible bodies.
    """
    force, s = nodal_normal_force(result), result.contact.coordinate
    return float(np.sqrt(4 * (force @ s**2) / force.sum())) if force.sum() > 0 else 0.0


# ---------------------------------------------------------------- scenes


def hertz(nx: int = 32, element: str = "P1", nu: float = 0.3, E: float = 1.0, unit: float = 1.0,
          load: float = 1.0, grading: float = 30.0) -> cc.Scene:
    """Block [-2, 2] × [-2, 0] × ``unit``, clamped base, rigid parabolic punch under force control.

    Punch radius unit/load and force HERTZ_FORCE·E·unit·load: the Hertz half-width is
    0.1·unit for ν = 0.3 whatever ``load``, and since force and curvature both scale with
    ``load`` the discrete answer does too, exactly (u and λ ∝ load: positive homogeneity). Graded ``grading``:1 towards the axis
    and the top.
    """
    body = cc.Rectangle(4.0 * unit, 2.0 * unit, nx, nx // 2, (-2.0 * unit, -2.0 * unit),
                        (grading, grading), refine_x=0.0)
    return cc.Scene(
        name="hertz",
        body=cc.Body(body, element),
        materials=cc.Material(E, nu),
        dirichlet=(cc.Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=cc.Contact("top", cc.Obstacle("parabolic", radius=unit / load, force=HERTZ_FORCE * E * unit * load)),
    )


def hertz_error(result) -> float:
    """Hertz half-width (from the force moment) and force balance against the closed form."""
    scene = result.scene
    material, obstacle = scene.materials, scene.contact.obstacle
    a, _ = hertz_plane_strain(obstacle.force, obstacle.radius, material.E, material.nu)
    return max(abs(moment_half_width(result) / a - 1), abs(result.normal_force / obstacle.force - 1))


def compressed(geometry, element: str, materials, depth: float = 0.01) -> cc.Scene:
    """Block on rollers (bottom u_y = 0, left u_x = 0) pressed ``depth`` by a flat rigid plate on top."""
    return cc.Scene(
        name="compressed",
        body=cc.Body(geometry, element),
        materials=materials,
        dirichlet=(cc.Dirichlet("bottom", uy=0.0), cc.Dirichlet("left", ux=0.0)),
        contact=cc.Contact("top", cc.Obstacle("flat", depth=depth)),
    )


def exact_nodal_forces(result, pressure: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """∫ p ψ_i ds at the contact nodes of a straight P1/Q1 boundary, p constant per facet (at its midpoint)."""
    s = result.contact.coordinate
    order = np.argsort(s)
    x = s[order]
    half = np.diff(x) / 2
    on_facet = pressure((x[1:] + x[:-1]) / 2) * half
    forces = np.zeros(x.size)
    forces[:-1] += on_facet
    forces[1:] += on_facet
    exact = np.empty_like(forces)
    exact[order] = forces
    return exact


def uniform_compression(depth: float, layers: Iterable[tuple[float, float, float]]):
    """Check of a block compressed by ``depth``: the uniaxial stress state is exact on any mesh.

    ``layers``: (thickness, E, ν) from top to bottom (one layer, or ν = 0 so that the layers'
    lateral strains agree); the contact pressure is depth / Σ h_i (1 − ν_i²)/E_i at every node.
    """
    compliance = sum(h * (1 - nu**2) / E for h, E, nu in layers)
    p = depth / compliance

    def error(result):
        return nodewise(nodal_normal_force(result), exact_nodal_forces(result, lambda x: np.full(x.shape, p)))

    return Check(error, EXACT, f"uniform pressure {p:.3g} (uniaxial stress, exact on any mesh)")


def ceiling(nx: int, gap: float, body_force=(0.0, 0.0), element: str = "P1") -> cc.Scene:
    """Unit square clamped at the bottom, a flat rigid ceiling ``gap`` above its top."""
    return cc.Scene(
        name="ceiling",
        body=cc.Body(cc.Rectangle(1.0, 1.0, nx, nx), element),
        materials=cc.Material(1.0, 0.3),
        dirichlet=(cc.Dirichlet("bottom", ux=0.0, uy=0.0),),
        contact=cc.Contact("top", cc.Obstacle("flat", gap=gap)),
        body_force=body_force,
    )


def punch(quick: bool, law) -> cc.Scene:
    """The frictional punch (Oden's example, depth 0.02), coarse: Q1, symmetric about x = 0."""
    if quick:
        mesh = tensor_mesh(graded(-2.0, 4.0, 24, 30.0, 0.0), graded(-2.0, 2.0, 12, 30.0, 0.0), quads=True)
    else:
        mesh = punch_mesh(0.02, quads=True)
    return dataclasses.replace(frictional_punch(depth=0.02, element="Q1", law=law), body=cc.Body(mesh, "Q1"))


def triangle(F1: float, F2: float, friction: float) -> cc.Scene:
    """Hild's one-triangle example: A(0,0), B(1,0), C(0,1), [B,C] clamped, traction on [A,C]."""
    mesh = fe.MeshTri1(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.array([[0], [1], [2]]))
    mesh = mesh.with_boundaries({
        "contact": lambda x: np.isclose(x[1], 0.0),
        "clamped": lambda x: np.isclose(x[0] + x[1], 1.0),
        "loaded": lambda x: np.isclose(x[0], 0.0),
    })
    return cc.Scene(
        name="hild",
        body=cc.Body(mesh, "P1"),
        materials=cc.Material(1.0, 0.3),
        dirichlet=(cc.Dirichlet("clamped", ux=0.0, uy=0.0),),
        tractions=(cc.Traction("loaded", vector=(F1, F2)),),
        contact=cc.Contact("contact", cc.Obstacle("flat", gap=0.0), Coulomb(friction=friction)),
    )


# ---------------------------------------------------------------- cases


def units(quick: bool):
    """E = 2.1e11 Pa, millimetre geometry (SI units) against E = 1, unit geometry: p/E and u/L equal."""
    nx = 32 if quick else 64
    E, mm = 2.1e11, 1e-3
    reference, cache = hertz(nx), {}

    def error(result):
        ref = same_path(reference, result, cache)
        return field_difference(result, ref, displacement=mm, pressure=E)

    return hertz(nx, E=E, unit=mm), Check(error, INVARIANT, "the same scene with E = 1 and unit lengths, same path")


def incompressible(quick: bool, nu: float, element: str):
    """Hertz with ν → 1/2 on P2/Q2: half-width and force against Hertz with E* = E/(1 − ν²)."""
    nx = 32 if quick else 64
    scene = hertz(nx, element, nu)

    def note(result):
        a, p0 = hertz_plane_strain(HERTZ_FORCE, 1, 1, nu)
        return f"a_m/a_Hertz {moment_half_width(result) / a:.4f}, max λ/p0 {result.max_pressure / p0:.2f}"

    return scene, Check(hertz_error, 0.03 if quick else 0.01, "Hertz a (force moment) and P, E* = E/(1 − ν²)", note)


def locking(quick: bool, nu: float = 0.4999):
    """P1 at ν = 0.4999 locks: far from Hertz. The note gives the indicator against P2 on the same mesh."""
    nx = 32 if quick else 64
    quadratic, cache = hertz(nx, "P2", nu), {}

    def note(result):
        if "P2" not in cache:
            cache["P2"] = cc.solve(quadratic, "clarabel")
        a = hertz_plane_strain(HERTZ_FORCE, 1, 1, nu)[0]
        return (f"locking indicator 1 − C(P1)/C(P2) = {locking_indicator(result, cache['P2']):.2f}, "
                f"a_m/a_Hertz {moment_half_width(result) / a:.2f}")

    return hertz(nx, "P1", nu), Check(hertz_error, 0.03 if quick else 0.01, "Hertz a and P (P1 locks)", note,
                                      known="locking")


def locking_indicator(result, quadratic: cc.ContactResult) -> float:
    """1 − C(P1)/C(P2), C the compliance (punch advance per force) on the same mesh: ≈ 0 unless P1 locks."""
    return 1.0 - result.obstacle_advance / quadratic.obstacle_advance


def contrast_layers(quick: bool, soft_on_top: bool):
    """Two horizontal layers, E ratio 1e6, ν = 0 (equal lateral strains), compressed: exact uniform pressure."""
    n = 8 if quick else 32
    x, y = np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, n + 1)
    mesh = tensor_mesh(x, y).with_subdomains({"upper": lambda p: p[1] > 0.5, "lower": lambda p: p[1] < 0.5})
    soft, stiff = 1e-6, 1.0
    upper, lower = (soft, stiff) if soft_on_top else (stiff, soft)
    materials = {"upper": cc.Material(upper, 0.0, "upper"), "lower": cc.Material(lower, 0.0, "lower")}
    return (compressed(mesh, "P1", materials),
            uniform_compression(0.01, [(0.5, upper, 0.0), (0.5, lower, 0.0)]))


def contrast_columns(quick: bool, nu: float = 0.3):
    """Two columns side by side, E ratio 1e6, same ν, compressed: each carries E_i δ/((1 − ν²)H), exact."""
    n = 8 if quick else 32
    x, y = np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, n + 1)
    mesh = tensor_mesh(x, y).with_subdomains({"soft": lambda p: p[0] < 0.5, "stiff": lambda p: p[0] > 0.5})
    materials = {"soft": cc.Material(1e-6, nu, "soft"), "stiff": cc.Material(1.0, nu, "stiff")}
    depth = 0.01

    def pressure(s):
        return np.where(s < 0.5, 1e-6, 1.0) * depth / (1 - nu**2)

    def error(result):
        return nodewise(nodal_normal_force(result), exact_nodal_forces(result, pressure))

    def note(result):
        exact = exact_nodal_forces(result, pressure)
        return f"relative to the largest force: {relative(nodal_normal_force(result), exact):.1e}"

    return compressed(mesh, "P1", materials), Check(error, EXACT, "nodal forces of E_i δ/((1 − ν²)H) per column, "
                                                                  "node by node", note)


def aspect(quick: bool, ratio: float = 100.0):
    """Compressed block whose top row of elements (the contact surface) has aspect ratio 100 (own mesh)."""
    n = 8 if quick else 32
    dx = 1.0 / n
    y = np.concatenate([np.linspace(0.0, 1.0 - dx / ratio, n + 1), [1.0]])
    mesh = tensor_mesh(np.linspace(0.0, 1.0, n + 1), y)
    return compressed(mesh, "P1", cc.Material(1.0, 0.3)), uniform_compression(0.01, [(1.0, 1.0, 0.3)])


def aspect_rectangle(quick: bool, ratio: float = 100.0):
    """The same through the built-in Rectangle: y-grading chosen so that the top row has aspect ratio 100."""
    n = 8 if quick else 32

    def excess(grading):  # Σ_k grading^(k/(n−1)) = ratio·n makes the top row 1/(ratio·n) thick
        return (grading ** (np.arange(n) / (n - 1))).sum() - ratio * n

    grading = brentq(excess, 1.0, 1e6)
    geometry = cc.Rectangle(1.0, 1.0, n, n, grading=(1.0, grading), refine_y="top")
    return compressed(geometry, "P1", cc.Material(1.0, 0.3)), uniform_compression(0.01, [(1.0, 1.0, 0.3)])


def graded_patch(quick: bool, ratio: float = 1e3):
    """Compressed block on a mesh graded 1e3:1 in x and y, finest at the contact surface."""
    n = 12 if quick else 32
    geometry = cc.Rectangle(1.0, 1.0, n, n, grading=(ratio, ratio), refine_y="top")
    return compressed(geometry, "P1", cc.Material(1.0, 0.3)), uniform_compression(0.01, [(1.0, 1.0, 0.3)])


def sphere_error(result) -> float:
    """3-D Hertz on the library's quarter model (its obstacle carries a quarter of the force): the contact radius
    from the second moment of the contact forces (∫p r² / ∫p = 2a²/5) and the force balance, against the closed form."""
    material, obstacle = result.scene.materials, result.scene.contact.obstacle
    a, _ = hertz_sphere(4 * obstacle.force, obstacle.radius, material.E, material.nu)
    force, r2 = nodal_normal_force(result), (result.contact.coords[:, :2] ** 2).sum(axis=1)
    radius = math.sqrt(2.5 * (force @ r2) / force.sum()) if force.sum() > 0 else 0.0
    return max(abs(radius / a - 1), abs(result.normal_force / obstacle.force - 1))


def p2_sphere(quick: bool):
    """3-D Hertz on P2 tetrahedra with weak contact, the only rows they take (measured 3.4 % at 4 cells, 1.7 % at 6;
    with the zero-mean vertex multipliers the contact radius read 8–11 × Hertz's: docs/estimate.md, "P2 tetrahedra's
    weak multiplier")."""
    scene = hertz_sphere_scene(4 if quick else 6, "P2", law=cc.Signorini(non_penetration="weak"))
    return scene, Check(sphere_error, 0.05 if quick else 0.03, "Hertz 3-D a (force moment) and P")


def spheres_error(result) -> float:
    """Two equal spheres' caps (`two_spheres`: R₁ = R₂ = 2, E = 1, ν = 0.3, the approach δ = 0.012 given): the force
    against Hertz's (4/3) E* √R δ^{3/2} (a quarter) and the peak of p² = p₀²(1 − r²/a²) fitted above 0.3 p_max against
    Hertz's p₀ of that force."""
    hertz = 4 / 3 * (0.5 / (1 - 0.3**2)) * 0.012**1.5 / 4
    _, p0 = hertz_sphere(4 * result.normal_force, 1.0, 0.5, 0.3)
    p, r = result.contact.pressure, np.linalg.norm(result.contact.coords[:, :2], axis=1)
    inside = p > 0.3 * p.max()
    (c0, _), *_ = np.linalg.lstsq(np.column_stack([np.ones(inside.sum()), r[inside] ** 2]), p[inside] ** 2, rcond=None)
    return max(abs(result.normal_force / hertz - 1), abs(math.sqrt(max(c0, 0.0)) / p0 - 1))


def p2_spheres(quick: bool):
    """Two P2 spheres in mortar contact (3-D pairs of P2 tetrahedra: the dual basis of the transformed ψ̃; measured
    6.2 % at 4 cells, 2.6 % at 6; the caps' own limit lies 1–4 % over Hertz's half-spaces: docs/bodies.md)."""
    return (two_spheres(4 if quick else 6, element="P2"),
            Check(spheres_error, 0.08 if quick else 0.04, "Hertz 3-D force of the approach, fitted p₀"))


def graded_hertz(quick: bool, ratio: float = 1e3):
    """Hertz (P2) on a mesh graded 1e3:1 towards the punch axis and the surface."""
    scene = hertz(32 if quick else 64, "P2", grading=ratio)
    return scene, Check(hertz_error, 0.03 if quick else 0.01, "Hertz a (force moment) and P")


def coulomb_vs_signorini(quick: bool, friction: float, tol: float):
    """Coulomb with a tiny F on the frictional punch against the frictionless (Signorini) solve."""
    reference, cache = punch(quick, cc.Signorini()), {}

    def error(result):
        return field_difference(result, same_path(reference, result, cache))

    return punch(quick, Coulomb(friction=friction)), Check(error, tol, "Signorini on the same mesh, same path",
                                                            picard_note)


def full_stick(quick: bool, friction: float = 10.0):
    """F = 10: every closed node sticks, so the answer is the bonded solve (u_x = 0 on the closed nodes)."""
    scene, cache = punch(quick, Coulomb(friction=friction)), {}

    def bonded(result):
        closed = result.contact.coords[result.closed, 0]
        low, high = closed.min(), closed.max()
        tiny = 1e-9 * (high - low + 1.0)
        mesh = scene.body.geometry.with_boundaries({
            "stuck": lambda x: np.isclose(x[1], 0.0) & (x[0] > low - tiny) & (x[0] < high + tiny)})
        return dataclasses.replace(
            scene, body=cc.Body(mesh, scene.body.element),
            dirichlet=scene.dirichlet + (cc.Dirichlet("stuck", ux=0.0),),
            contact=dataclasses.replace(scene.contact, law=cc.Signorini()))

    def error(result):
        slipping = np.char.startswith(result.contact.status.astype(str), "slip").sum()
        reference = same_path(bonded(result), result, cache)
        return max(field_difference(result, reference), float(slipping))

    return scene, Check(error, EXACT, "bonded solve: Signorini with u_x = 0 on the closed nodes", picard_note)


def picard_note(result) -> str:
    picard = result.extra.get("picard")
    return "" if picard is None else f"Picard {picard['outcome']} in {picard['iterations']} steps"


def hild(quick: bool, F1: float, F2: float, friction: float):
    """Hild's one triangle: the answer must be one of Prop. 4.1's closed-form solutions."""
    solutions = hild_one_triangle_solutions(F1, F2, friction, 1.0, 0.3)

    def error(result):
        a = np.flatnonzero(np.all(np.isclose(result.contact.coords, 0.0), axis=1))[0]
        u = result.displacement[result.fem.basis.nodal_dofs[:, 0]]
        force = result.contact.forces[a]
        scale = math.hypot(F1, F2)
        return min(max(np.abs(u - s["displacement"]).max(), np.abs(force - s["contact_force"]).max()) / scale
                   for s in solutions)

    def note(result):
        regimes = ", ".join(s["regime"] for s in solutions)
        return f"solutions: {regimes}; {picard_note(result)}"

    return triangle(F1, F2, friction), Check(error, EXACT, "nearest of Hild's closed-form solutions", note)


def nothing_happens(tol: float = ZERO) -> Check:
    """Check of a scene without load: u = 0 and λ = 0 (absolute, user units of size 1 and E = 1), no node closed.

    A node reported closed counts 1 (spurious contact).
    """

    def error(result):
        return max(np.abs(result.displacement).max(), np.abs(result.contact.pressure).max(initial=0.0),
                   float(result.closed.sum()))

    def note(result):
        return (f"max u {np.abs(result.displacement).max():.1e}, max λ "
                f"{np.abs(result.contact.pressure).max(initial=0.0):.1e}, {int(result.closed.sum())} nodes closed")

    return Check(error, tol, "u = 0, λ = 0, no closed node (absolute)", note)


def zero_load(quick: bool):
    """No load, the ceiling touching (gap 0): u = 0 and λ = 0 exactly, no node reported closed."""
    return ceiling(8 if quick else 32, gap=0.0), nothing_happens()


def zero_force(quick: bool):
    """Force control with P = 0: λ = 0 and u = 0; the punch's advance is not determined (any d ≤ 0).

    The undetermined advance makes the active-set polish singular, so the interior-point
    answer stands: zero to the solver's tolerance (1e-10 relative, ~2.5e-10 absolute here),
    hence the looser check than the 1e-10 of the other unloaded scenes.
    """
    scene = dataclasses.replace(hertz(32 if quick else 64), contact=cc.Contact(
        "top", cc.Obstacle("parabolic", radius=1.0, force=0.0)))
    return scene, nothing_happens(tol=1e-8)


def separation(quick: bool):
    """Body force towards a ceiling 1000 displacements away: λ = 0 and u = K⁻¹f (a linear solve)."""
    scene = ceiling(8 if quick else 32, gap=1.0, body_force=(0.0, 1e-3))

    def error(result):
        fem = result.fem
        free = spla.spsolve(fem.K.tocsc(), fem.f) * fem.scaling.displacement
        return max(relative(result.displacement[fem.free], free),
                   result.contact.pressure.max(initial=0.0) / 1e-3)

    return scene, Check(error, EXACT, "linear elastic solve K⁻¹f (scipy), λ = 0")


def small_gap(quick: bool, gap: float = 1e-12):
    """Body force pushing the top into a ceiling 1e-12 away: the answer of gap 0 to within 1e-12/|u|."""
    nx = 8 if quick else 32
    scene, reference, cache = (ceiling(nx, gap, (0.0, 0.05)), ceiling(nx, 0.0, (0.0, 0.05)), {})

    def error(result):
        return field_difference(result, same_path(reference, result, cache))

    return scene, Check(error, INVARIANT, "the same scene with gap 0, same path")


def tiny_penetration(quick: bool, gap: float = -1e-12):
    """No load, the ceiling 1e-12 into the body: u and λ are 1e-10 × those of a 1e-2 penetration, exactly."""
    nx = 8 if quick else 32
    base = -1e-2
    scene, reference, cache = ceiling(nx, gap), ceiling(nx, base), {}

    def error(result):
        factor = gap / base
        return field_difference(result, same_path(reference, result, cache), factor, factor)

    return scene, Check(error, INVARIANT, "1e-10 × the 1e-2 penetration (positive homogeneity), same path")


def scaled_load(quick: bool, load: float):
    """Hertz with force × load and radius / load: u and λ scale exactly with load (positive homogeneity)."""
    nx = 32 if quick else 64
    reference, cache = hertz(nx), {}

    def error(result):
        return field_difference(result, same_path(reference, result, cache), load, load)

    return hertz(nx, load=load), Check(error, INVARIANT, "load × the load-1 solve, same path")


CASES: dict[str, Callable[[bool], tuple[cc.Scene, Check]]] = {
    "units: E = 2.1e11 Pa, mm": units,
    "ν = 0.49, P2": functools.partial(incompressible, nu=0.49, element="P2"),
    "ν = 0.499, P2": functools.partial(incompressible, nu=0.499, element="P2"),
    "ν = 0.4999, P2": functools.partial(incompressible, nu=0.4999, element="P2"),
    "ν = 0.4999, Q2": functools.partial(incompressible, nu=0.4999, element="Q2"),
    "ν = 0.4999, P1 (locking)": locking,
    "contrast 1e6: soft layer on stiff": functools.partial(contrast_layers, soft_on_top=True),
    "contrast 1e6: stiff layer on soft": functools.partial(contrast_layers, soft_on_top=False),
    "contrast 1e6: columns side by side": contrast_columns,
    "aspect ratio 100 at Γ_C": aspect,
    "aspect ratio 100 at Γ_C, Rectangle": aspect_rectangle,
    "graded 1e3: compression": graded_patch,
    "graded 1e3: Hertz": graded_hertz,
    "Hertz 3-D, P2 tetrahedra (weak)": p2_sphere,
    "Hertz 3-D, two P2 spheres (mortar)": p2_spheres,
    "Coulomb F = 0": functools.partial(coulomb_vs_signorini, friction=0.0, tol=EXACT),
    "Coulomb F = 1e-6": functools.partial(coulomb_vs_signorini, friction=1e-6, tol=EXACT),
    "Coulomb F = 10 (full stick)": full_stick,
    "Hild F = 2.5 (3 solutions)": functools.partial(hild, F1=-2.4, F2=-1.0, friction=2.5),
    "Hild F = 2.5 (right slip, repels ω = 1)": functools.partial(hild, F1=3.0, F2=-1.0, friction=2.5),
    "Hild F = 10 (stick)": functools.partial(hild, F1=0.5, F2=-1.0, friction=10.0),
    "zero load": zero_load,
    "zero load, force control": zero_force,
    "full separation": separation,
    "gap 1e-12": small_gap,
    "penetration 1e-12, no load": tiny_penetration,
    "load 1e-8": functools.partial(scaled_load, load=1e-8),
    "load 1e-10 (force below the resolved strain)": functools.partial(scaled_load, load=1e-10),
    "load 1e10": functools.partial(scaled_load, load=1e10),
}
"""The registry: case name → function(quick) returning (scene, check)."""


# ---------------------------------------------------------------- running and judging


def library_flags(result, word: str) -> bool:
    """Whether the library's own output mentions ``word`` (message, warnings or a key of ``extra``)."""
    said = [result.message or "", *getattr(result, "warnings", []), *map(str, result.extra)]
    return any(word in text.lower() for text in said)


def verdict(status: str, message: str, error: float, check: Check, certificate: float = math.nan,
            result=None) -> str:
    """pass, clear failure, known limitation, or FAIL (wrong answer, unclear failure, crash).

    An ``inaccurate`` answer outside the tolerance is a clear (flagged) failure when its certificate
    says not to trust it (> :data:`UNTRUSTED`) or accounts for the error (error ≤ 10 × certificate);
    otherwise the certificate understated the error, a FAIL.
    """
    if status == "crash":
        return "FAIL: crash"
    if status == "input error":
        return "clear error"
    if status in ("solved", "inaccurate"):
        if error <= check.tol:
            return "pass"
        if check.known:
            flagged = result is not None and library_flags(result, check.known)
            return f"pass ({check.known} flagged)" if flagged else f"known: {check.known}, not flagged by the library"
        if not math.isfinite(error):
            return "FAIL: check failed"
        if status == "solved":
            return "FAIL: wrong answer reported as solved"
        if certificate > UNTRUSTED or error <= 10 * certificate:
            return "clear failure (flagged inaccurate)"
        return "FAIL: inaccurate, error ≫ certificate"
    if status in CLEAR and message:
        return "clear failure"
    return "FAIL: unclear failure"


def run_one(name: str, path: str, quick: bool) -> dict | None:
    """One case on one path, as a row (None when the path does not apply: cvxpy on a large scene)."""
    scene, check = CASES[name](quick)
    solver, formulation = PATHS[path]
    row = {"case": name, "path": path, "solver": solver, "formulation": formulation, "status": "", "solver_status": "",
           "iterations": None, "certificate": math.nan, "error": math.nan, "tol": check.tol,
           "reference": check.reference, "time": math.nan, "message": "", "note": ""}
    result = None
    start = time.perf_counter()
    try:
        model = cc.prepare(scene, formulation)
        if solver == "cvxpy" and model.fem.n_free > CVXPY_MAX_DOFS:
            return None
        result = model.solve(solver)
    except (SceneError, ValueError) as error:  # bad input named by the library: a clear error
        row.update(status="input error", message=f"{type(error).__name__}: {error}")
    except Exception as error:  # noqa: BLE001 — any other exception is a crash, a finding the row records
        row.update(status="crash", message=f"{type(error).__name__}: {error}")
    row["time"] = time.perf_counter() - start
    if result is not None:
        row.update(status=result.status, solver_status=result.solver_status, iterations=result.iterations,
                   message=result.message or "")
        if result.certificate is not None:
            row["certificate"] = result.certificate.worst
        if result.solved:
            try:
                row["error"] = check(result)
                row["note"] = check.note(result) if check.note else ""
            except Exception as error:  # noqa: BLE001 — a check that cannot run is shown, not raised
                row["note"] = f"check failed: {type(error).__name__}: {error}"
        elif "picard" in result.extra:
            row["note"] = picard_note(result)
    row["verdict"] = verdict(row["status"], row["message"], row["error"], check, row["certificate"], result)
    return row


def run(cases: Iterable[str] | None = None, solvers: Iterable[str] = tuple(PATHS), quick: bool = False,
        progress: Callable[[str], None] | None = print) -> list[dict]:
    """Run ``cases`` (default: all of :data:`CASES`) on the ``solvers`` paths of :data:`PATHS`.

    ``quick`` uses coarse meshes (the whole suite in well under a minute). Returns one row
    per (case, path): status, solver status, iterations, certificate worst, error and its
    tolerance, wall time (prepare + solve) and the verdict.
    """
    names = list(CASES) if cases is None else list(cases)
    unknown = [n for n in names if n not in CASES] + [p for p in solvers if p not in PATHS]
    if unknown:
        raise ValueError(f"unknown cases or paths {unknown}; cases: {list(CASES)}, paths: {list(PATHS)}")
    rows = []
    for name in names:
        for path in solvers:
            row = run_one(name, path, quick)
            if row is None:
                continue
            rows.append(row)
            if progress is not None:
                progress(f"{name} | {path}: {row['status']}, error {row['error']:.1e}, {row['time']:.2f} s "
                         f"→ {row['verdict']}")
    return rows


def failures(rows: list[dict]) -> list[dict]:
    """Rows whose verdict is a FAIL (wrong answer, unclear failure, crash)."""
    return [row for row in rows if row["verdict"].startswith("FAIL")]


def _number(value, spec: str) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def table(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    header = ("case", "path", "status", "solver status", "iter", "certificate", "error", "tol", "time [s]", "verdict",
              "note")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        note = row["note"] or (row["message"][:90] if row["verdict"] != "pass" else "")
        cells = (row["case"], row["path"], row["status"], row["solver_status"], _number(row["iterations"], "d"),
                 _number(row["certificate"], ".1e"), _number(row["error"], ".1e"), _number(row["tol"], ".0e"),
                 _number(row["time"], ".2f"), row["verdict"], note.replace("|", "/"))
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> list[dict]:
    """``convexcontact study stability [--quick] [--cases NAME …] [--out FILE]``: the suite's table."""
    import argparse

    parser = argparse.ArgumentParser(prog="convexcontact study stability", description=main.__doc__)
    parser.add_argument("--quick", action="store_true", help="coarse meshes (about 10 s)")
    parser.add_argument("--cases", nargs="+", default=None, help="case names as in docs/stability.md")
    parser.add_argument("--out", type=Path, default=None, help="also write the markdown table here")
    parser.add_argument("--overwrite", action="store_true", help="replace the --out file of an earlier run")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.cases or ()) - set(CASES))
    if unknown:
        raise ValueError(f"--cases: no case named {', '.join(map(repr, unknown))}; the cases are "
                         f"{', '.join(map(repr, CASES))}")
    if args.out:
        check_new_file(args.out, "--out", args.overwrite, "stability.md")
    rows = run(cases=args.cases, quick=args.quick)
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return rows
