"""Exact sensitivities of a certified answer to the scene's parameters, and gradients of objectives by the adjoint.

:func:`sensitivity` gives du/dθ, dλ_N/dθ, dλ_T/dθ and the resultants' derivatives for a parameter θ named by its
path in the scene (:data:`PARAMETERS`); :func:`gradient` gives dJ/dθ of a linear functional J of the answer (a
misfit's gradient by the chain rule) for many parameters with one transposed solve. The linear algebra is in
:mod:`.active_set`; this module reads the answer's active set off the certificate's quantities and the data's
derivatives off the scene (docs/sensitivity.md).

The data depend on loads, Dirichlet values and the obstacle's depth, gap or forces affinely: their rates are the
difference of two assemblies at the model's fixed units, exact up to round-off. K is linear in E and in the Lamé
parameters, whose derivative in ν is taken by a complex step (exact to round-off): dK is assembled once.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp
from skfem.models.elasticity import lame_parameters

from ..fem.assembly import FEModel
from ..fem.factorization import Condensation, condense
from ..fem.friction import FrictionPoints, friction_points
from ..fem.mortar import PairTrace
from ..fem.stiffness import stiffness
from ..formulations import contact_weights
from ..results.result import ContactResult, held
from ..scene.bodies import Pairs
from ..scene.checks import finite
from ..scene.history import PATH, at, check_effect
from ..scene.model import (
    Coulomb,
    Material,
    NormalCompliance,
    Scene,
    SceneError,
    Signorini,
    Tresca,
    compliance_of,
    has_friction,
    of_type,
)
from .active_set import (
    Linearization,
    NotDifferentiable,
    Rates,
    directional,
    friction_status,
    linearize,
    normal_status,
    right_side,
)
from .history import HistoryResult
from .model import CERTIFIED, contact_columns, field_at_points, frictional_rows
from .picard import pressure_map

PARAMETERS = ("E", "nu", "materials[NAME].E|nu", "friction (Coulomb)", "slip_bound (Tresca)",
              "stiffness (normal compliance)", "obstacle.depth",
              "obstacle.gap", "obstacle.force", "obstacle.tangential_force", "dirichlet[BOUNDARY].ux|uy|uz",
              "traction[BOUNDARY].pressure", "traction[BOUNDARY].vector[I]", "body_force[I]")
MATERIAL = re.compile(r"^(?:materials\[([^\]]+)\]\.)?(E|nu)$")
COMPONENT = re.compile(r"^(.*(?:vector|body_force))(?:\[(\d)\])?$")

STRICT = 1e-8
"""A contact row or friction point is strictly on one side of its law where the quantity of that side (gap,
pressure; slip, room below the bound) exceeds this fraction of its scale, or 100 × the certificate's worst
residual if larger; where neither does, it is degenerate and the derivative one-sided there."""


@dataclass
class Derivative:
    """Derivatives of the answer's fields along a parameter, in the user's units per unit of the parameter:
    the full DOF vector, the contact nodes' pressure and friction traction (as in ``result.contact``), and the
    resultants of :class:`~convexcontact.results.result.ContactResult`."""

    displacement: np.ndarray
    pressure: np.ndarray
    friction: np.ndarray | None
    contact_force: np.ndarray
    normal_force: float
    tangential_force: float | None
    obstacle_advance: float | None = None  # force control: the obstacle's unknown motions
    obstacle_shift: float | None = None


@dataclass
class Sensitivity:
    """The answer's derivatives along one parameter.

    ``right`` is the derivative as the parameter grows, ``left`` as it shrinks (lim (x(θ) − x(θ − h))/h); they
    agree where nothing is degenerate. ``degenerate`` names the contact nodes that graze (gap and pressure both 0)
    and the friction points at the stick/slip boundary (no slip, traction at the bound): there the derivative is
    one-sided. A side is None where its complementarity problem has no solution or several (Coulomb may branch):
    ``message`` says which. ``margin`` is how strictly the other rows hold their side (over their scales): the
    derivative is that of every perturbation that keeps them there.
    """

    parameter: str
    value: float
    right: Derivative | None
    left: Derivative | None
    degenerate: dict[str, np.ndarray]
    margin: float
    message: str = ""

    @property
    def differentiable(self) -> bool:
        return not any(len(v) for v in self.degenerate.values())

    @property
    def derivative(self) -> Derivative:
        """The (two-sided) derivative; a :class:`NotDifferentiable` error where the answer is degenerate."""
        if not self.differentiable:
            raise NotDifferentiable(f"{self.parameter}: the answer is not differentiable here ({describe(self)}); "
                                    "read the one-sided derivatives .right and .left")
        return self.right


def describe(sensitivity: Sensitivity) -> str:
    return ", ".join(f"{len(v)} {k.replace('_', '/')} ({list(v)[:8]})" for k, v in sensitivity.degenerate.items()
                     if len(v)) + (f"; {sensitivity.message}" if sensitivity.message else "")


@dataclass
class Point:
    """The answer in scaled units with the operators of its law, and its active set (:class:`Linearization`)."""

    result: ContactResult
    C: sp.spmatrix
    friction: FrictionPoints | None
    u: np.ndarray  # free DOFs, then the force-controlled obstacle's motions
    pressure: np.ndarray
    unit_bound: sp.csr_matrix | None  # Coulomb: ds/dF (F constant) as a map of λ_N
    linear: Linearization
    margin: float
    obstacle: int = 0  # the force-controlled obstacle's unknowns after u (advance, then shift): 0, 1 or 2
    condensation: Condensation | None = None  # K condensed onto the contact DOFs: the system is over those

    @property
    def fem(self) -> FEModel:
        return self.result.fem


def check_result(result, in_history: bool = False) -> ContactResult:
    """The result if its answer can be differentiated here, else an error naming what to change (``in_history``:
    a step of a history, differentiated with the steps before it)."""
    of_type(result, ContactResult, "result", "give the ContactResult of cc.solve(scene)")
    if not result.solved or result.status != "solved":
        raise ValueError(f"result: status {result.status!r}{', ' + result.message if result.message else ''}: only a "
                         "solved and certified answer has a derivative — solve it again more tightly (tol) or with "
                         "another solver")
    if not result.certificate.passes(CERTIFIED):
        raise ValueError(f"result: certificate {result.certificate.worst:.1e} > {CERTIFIED:g}: not an answer of the "
                         "discrete problem, so not one to differentiate — solve more tightly")
    scene, law = result.scene, result.scene.contact.law
    if scene.history is not None and not in_history:
        raise SceneError("result", "a step of a load history: its derivative depends on the earlier steps",
                         "give the whole HistoryResult to cc.sensitivity")
    if isinstance(scene.contact, Pairs):
        raise SceneError("result", "several contacts in one scene: not implemented",
                         "differentiate one pair of bodies, or a body on one rigid obstacle")
    if not isinstance(law, (Signorini, NormalCompliance, Tresca, Coulomb)):
        raise SceneError("contact.law", f"{type(law).__name__}: sensitivities are implemented for Signorini, normal "
                         "compliance, Tresca and Coulomb", "use one of these laws")
    if law.non_penetration == "gauss" or getattr(law, "quadrature", "nodal") == "gauss":
        raise SceneError("contact.non_penetration", "contact or friction at Gauss points: their multipliers need not "
                         "be unique, so neither are their derivatives", "use non_penetration and quadrature 'nodal'")
    if has_viscosity(scene):
        raise SceneError("materials", "a viscous material: not implemented", "differentiate an elastic body")
    return result


def has_viscosity(scene: Scene) -> bool:
    materials = [scene.materials] if isinstance(scene.materials, Material) else list(scene.materials.values())
    return any(m.viscosity for m in materials)


def point_of(result: ContactResult) -> Point:
    """The answer of ``result`` in scaled units, its law's operators and its active set."""
    fem, law = result.fem, result.scene.contact.law
    scaling, contact = fem.scaling, fem.contact
    C = contact_weights(contact, law.non_penetration)
    friction = None
    if has_friction(law):
        if frictional_rows(law, contact) is not None:
            raise SceneError("contact.friction", "friction laws per contact pair: not implemented", "use one law")
        friction = friction_points(contact, fem.mesh, fem.basis, law.quadrature, law.non_penetration)
    K, A, R, obstacle = with_obstacle(result, C, friction)
    u = np.concatenate([result.displacement[fem.free] / scaling.displacement, obstacle])
    pressure = result.contact.pressure / scaling.pressure
    u_ref, p_ref = max(np.abs(u).max(initial=0.0), 1.0), max(np.abs(pressure).max(initial=0.0), 1.0)
    tol = max(STRICT, 100 * result.certificate.worst)
    gap = (weighted_gap(contact, C) - A @ u) / contact.row_weights(C) / u_ref
    normal = normal_status(gap, pressure / p_ref, held(A), tol)
    unit, arguments = None, {}
    if compliance_of(law) is not None:
        normal, arguments["flexibility"] = compliant(normal, gap * u_ref, contact.row_weights(C),
                                                     result_compliance(fem, law))
    strict = [np.where(normal == "closed", pressure / p_ref, np.where(normal == "open", gap, np.inf))]
    if friction is not None:
        unit, state, room = friction_state(result, friction, R @ u + friction.offset, normal, (u_ref, p_ref), tol)
        arguments.update(state, R=R)
        strict.append(room)
    condensation, kept = condensed(fem, obstacle.size)
    if condensation is not None:  # the derivative system on the contact DOFs, K replaced by its Schur complement
        K = sp.block_diag([sp.csr_matrix(condensation.S), sp.csr_matrix((obstacle.size,) * 2)], format="csr")
        A = A[:, kept]
        if friction is not None:
            arguments["R"] = arguments["R"][:, kept]
    linear = linearize(K, A, normal, **arguments)
    margin = float(np.concatenate(strict).min(initial=np.inf))
    return Point(result, C, friction, u, pressure, unit, linear, margin, obstacle.size, condensation)


CONDENSED = 3000
"""Most contact DOFs onto which the derivative system is condensed (a dense Schur complement of K, as the dual's
W): beyond, the sparse system over every DOF is factorized instead (SuperLU)..."""

CONDENSED_DOFS = 20000
"""... and the fewest free DOFs: below, SuperLU on the whole system was faster (10⁴ DOFs, 101 contact nodes:
0.18 s against 0.56 s for PARDISO's Schur complement; 4·10⁴ DOFs, 201 nodes: 1.10 s against 0.78 s)."""


def condensed(fem: FEModel, extra: int) -> tuple[Condensation | None, np.ndarray | None]:
    """K condensed onto the DOFs the contact rows touch (one sparse factorization, PARDISO's Schur complement
    where it loads), and the columns of the augmented unknowns (u, obstacle) kept: those DOFs, then the obstacle's;
    (None, None) where condensing gains nothing."""
    columns = contact_columns(fem)
    if fem.n_free < CONDENSED_DOFS or not 0 < columns.size <= min(CONDENSED, fem.n_free // 2):
        return None, None
    return condense(fem.K, columns, dim=fem.dim), np.concatenate([columns, fem.n_free + np.arange(extra)])


def reduced(point: Point, rates: Rates) -> Rates:
    """The rates of the condensed system: the force condensed onto the contact DOFs (f_C − K_CI K_II⁻¹ f_I)."""
    if point.condensation is None:
        return rates
    n = point.fem.n_free
    return Rates(np.concatenate([point.condensation.load(rates.force[:n]), rates.force[n:]]), rates.gap, rates.offset,
                 rates.bound)


def expanded(point: Point, x: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The solution over every DOF from the condensed one: du_I = K_II⁻¹(f_I − K_IC du_C) for the force rate
    ``force`` it was solved for."""
    if point.condensation is None:
        return x
    n, kept = point.fem.n_free, point.condensation.C.size
    return np.concatenate([point.condensation.lift(x[:kept], force[:n]), x[kept:]])


def friction_state(result: ContactResult, friction: FrictionPoints, weighted: np.ndarray, normal: np.ndarray,
                   refs: tuple[float, float], tol: float):
    """The friction points' part of :func:`linearize`'s arguments from the answer's weighted slip and traction,
    the map ds/dμ of a Coulomb law (None for Tresca), and how strictly each point holds its side."""
    fem, law = result.fem, result.scene.contact.law
    scaling, (u_ref, p_ref) = fem.scaling, refs
    traction = friction.components(np.asarray(result.contact.friction).reshape(fem.contact.m, -1).T.ravel()
                                   / scaling.pressure)
    coupling, unit, fixed = None, None, np.ones(friction.count, bool)
    if isinstance(law, Tresca):
        bound = field_at_points(law.slip_bound, "contact.slip_bound", fem, friction) / scaling.pressure
    else:  # s = μ λ_N at the answer: the Coulomb law itself
        unit = pressure_map(SimpleNamespace(law=replace(law, friction=1.0), fem=fem, friction=friction))[2]
        coupling = pressure_map(SimpleNamespace(law=law, fem=fem, friction=friction))[2]
        bound = coupling @ np.maximum(result.contact.pressure / scaling.pressure, 0.0)
        moving = np.isin(normal, ("closed", "grazing")).astype(float)
        fixed = (abs(coupling) @ moving) == 0  # no closed or grazing node under the point: its bound stays 0
    weighted = friction.components(weighted)
    slip = weighted / friction.weights[:, None] / u_ref
    epsilon = None if law.regularization is None else law.regularization / scaling.displacement
    status = friction_status(slip, traction / p_ref, bound / p_ref, held(friction.R, friction.dim), fixed, tol,
                             smooth=epsilon is not None)
    room = (bound - np.linalg.norm(traction, axis=1)) / p_ref
    strict = np.where(status == "slip", np.linalg.norm(slip, axis=1), np.where(status == "stick", room, np.inf))
    arguments = {"R": None, "friction": status, "slip": weighted, "traction": traction, "bound": bound,
                 "coupling": coupling, "epsilon": None if epsilon is None else epsilon * friction.weights}
    return unit, arguments, strict


def result_compliance(fem: FEModel, law) -> tuple[float, float]:
    """(c_N, p) of the law's normal compliance in scaled units, as the model scales them."""
    compliance = compliance_of(law)
    return compliance.stiffness * fem.scaling.displacement**compliance.exponent / fem.scaling.pressure, \
        compliance.exponent


def compliant(normal: np.ndarray, gap: np.ndarray, weights: np.ndarray, compliance: tuple[float, float]):
    """Normal compliance λ = c e^p, e = −gap the excess: the rows' statuses (a grazing row of p > 1 has a zero
    derivative: open) and their flexibility φ = w/(c p e^(p−1)) (:func:`linearize`)."""
    stiffness, exponent = compliance
    excess = np.maximum(-gap, 0.0)
    if exponent > 1:
        normal = np.where(normal == "grazing", "open", normal)
    rate = stiffness * exponent * excess ** (exponent - 1)
    flexibility = np.divide(weights, rate, out=np.zeros_like(weights), where=rate > 0)
    return normal, flexibility


def with_obstacle(result: ContactResult, C: sp.spmatrix, friction: FrictionPoints | None):
    """K, A = C N and R with the force-controlled obstacle's unknowns appended as columns (its advance δ_N closes
    the gaps by C c δ_N, its shift δ_T moves the slip by −coupling δ_T; no stiffness: their equations are the
    force balances), and their values in the answer (scaled). As in :mod:`~convexcontact.formulations.primal`."""
    fem = result.fem
    contact, scaling = fem.contact, fem.scaling
    rows = friction.R.shape[0] if friction is not None else 0
    normal, tangential, values = [], [], []
    if contact.obstacle_coupling is not None:
        normal.append(C @ contact.obstacle_coupling)
        tangential.append(np.zeros(rows))
        values.append(result.obstacle_advance / scaling.displacement)
    if contact.tangential_coupling is not None:
        normal.append(np.zeros(C.shape[0]))
        tangential.append(-friction.coupling)
        values.append(result.obstacle_shift / scaling.displacement)

    def widened(matrix, columns):
        return sp.csr_matrix(sp.hstack([matrix, sp.csr_matrix(np.column_stack(columns))])) if columns else \
            sp.csr_matrix(matrix)

    K = sp.block_diag([fem.K, sp.csr_matrix((len(values), len(values)))], format="csr")
    return (K, widened(C @ contact.N, normal), None if friction is None else widened(friction.R, tangential),
            np.array(values, dtype=float))


def weighted_gap(contact, C) -> np.ndarray:
    """h = C(g − o_N): the right-hand side of the normal rows A u ≤ h."""
    return contact.weighted_gap(C) - C @ contact.normal_offset


def parameter_value(scene: Scene, parameter, field: str = "parameter") -> float:
    """The parameter's value in ``scene``, or an error (named ``field``) naming the parameters the scene has."""
    of_type(parameter, str, field, f"name one of {', '.join(PARAMETERS)}")
    law, material = scene.contact.law, MATERIAL.match(parameter)
    if material is not None:
        name, which = material.groups()
        if name is None and not isinstance(scene.materials, Material):
            raise SceneError(field, f"{parameter!r}: the scene has several materials",
                             f"name one: {[f'materials[{k}].{which}' for k in scene.materials]}")
        if name is not None and (isinstance(scene.materials, Material) or name not in scene.materials):
            known = [] if isinstance(scene.materials, Material) else list(scene.materials)
            raise SceneError(field, f"{parameter!r}: no material {name!r}",
                             f"use {which!r}" if not known else f"name one of {known}")
        chosen = scene.materials if name is None else scene.materials[name]
        return float(getattr(chosen, which))
    if parameter == "stiffness":
        if compliance_of(law) is None:
            raise SceneError(field, f"{parameter!r}: the scene's law ({type(law).__name__}) has no normal compliance",
                             "give the law a NormalCompliance (alone, or as Tresca's or Coulomb's compliance)")
        return compliance_of(law).stiffness
    if parameter in ("friction", "slip_bound"):
        kind = Coulomb if parameter == "friction" else Tresca
        if not isinstance(law, kind):
            own = {Coulomb: "use 'friction'", Tresca: "use 'slip_bound'"}.get(
                type(law), "a frictionless law has neither: name a load, support, obstacle or material parameter")
            raise SceneError(field, f"{parameter!r}: the scene's law is {type(law).__name__}, which has no "
                             f"{parameter}", own)
        value = getattr(law, parameter)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(field, f"{parameter!r}: the law's {parameter} is a field, not one number",
                             f"give contact.{parameter} as a number to differentiate by it")
        return float(value)
    path, index = vector_path(parameter, field)
    if PATH.match(path) is None or path.startswith("contact["):
        problem = "not differentiated here (contacts of several bodies)" if PATH.match(path) else "unknown parameter"
        raise SceneError(field, f"{parameter!r}: {problem}", f"use one of {', '.join(PARAMETERS)}")
    value = current(scene, path)
    if path.startswith("obstacle.") and path.endswith("force") and value is None:
        raise SceneError(field, f"{parameter!r}: the obstacle is not pressed by a force (its {path} is not given), "
                         "so the force is no parameter of this scene", "give the scene's obstacle a force to "
                         "differentiate by it, or differentiate by 'obstacle.depth'")
    try:
        check_effect(scene, path)
        at(scene, path, 0.0 if value is None else value)
    except SceneError as error:
        raise SceneError(field, f"{parameter!r}: {str(error).split(': ', 1)[1]}") from None
    if index is None:
        return float(value or 0.0)
    if index >= len(value):
        raise SceneError(field, f"{parameter!r}: component {index} of a {len(value)}-vector",
                         f"use {path}[0] … {path}[{len(value) - 1}]")
    return float(value[index])


def vector_path(parameter: str, field: str = "parameter") -> tuple[str, int | None]:
    """(path, component) of a vector's component (``body_force[1]``), (path, None) otherwise."""
    vector = COMPONENT.match(parameter)
    if vector is None:
        return parameter, None
    path, index = vector.groups()
    if index is None:
        raise SceneError(field, f"{parameter!r}: a vector: name one of its components",
                         f"use '{parameter}[0]', '{parameter}[1]', ...")
    return path, int(index)


def current(scene: Scene, path: str):
    """The scene's value of the history path ``path`` (an obstacle's depth not given is 0; None: not in the scene)."""
    _, obstacle, name, _, where, component, _, loaded, load, body_force = PATH.match(path).groups()
    if obstacle:
        given = getattr(scene.contact.obstacle, name)
        return 0.0 if given is None and name in ("depth", "gap") else given
    if body_force:
        return scene.body_force
    items = scene.dirichlet if where is not None else scene.tractions
    matching = [item for item in items if item.boundary == (where if where is not None else loaded)]
    return getattr(matching[0], component or load) if matching else None


def with_parameter(scene: Scene, parameter: str, value: float) -> Scene:
    """``scene`` with ``parameter`` (:data:`PARAMETERS`) set to ``value``: a finite difference's or a fit's scene."""
    of_type(scene, Scene, "scene", "give the cc.Scene the parameter belongs to")
    parameter_value(scene, parameter)
    value = finite(value, "value", f"give {parameter}'s new value as a number")
    material = MATERIAL.match(parameter)
    if material is not None:
        name, which = material.groups()
        if name is None:
            return replace(scene, materials=replace(scene.materials, **{which: value}))
        return replace(scene, materials={**scene.materials, name: replace(scene.materials[name], **{which: value})})
    if parameter in ("friction", "slip_bound"):
        return scene.with_law(replace(scene.contact.law, **{parameter: value}))
    if parameter == "stiffness":
        law = scene.contact.law
        if isinstance(law, NormalCompliance):
            return scene.with_law(replace(law, stiffness=value))
        return scene.with_law(replace(law, compliance=replace(law.compliance, stiffness=value)))
    return shifted(scene, parameter, value)


def shifted(scene: Scene, parameter: str, value: float) -> Scene:
    """``scene`` with the load, support or obstacle parameter set to ``value``."""
    path, index = vector_path(parameter)
    if index is None:
        return at(scene, path, value)
    vector = list(current(scene, path))
    vector[index] = value
    return at(scene, path, tuple(vector))


def unit_of(fem: FEModel, parameter: str) -> float:
    """The parameter's natural scale in the model's units (a difference step that is neither round-off nor huge)."""
    scaling = fem.scaling
    if parameter.startswith("obstacle.") and parameter.endswith("force"):
        return scaling.force
    if parameter.startswith(("obstacle", "dirichlet")):
        return scaling.displacement
    if parameter.startswith("body_force"):
        return scaling.pressure / scaling.length
    return scaling.pressure


def data_rates(point: Point, parameter: str, value: float) -> tuple[Rates, np.ndarray, np.ndarray | None]:
    """The data's derivatives along ``parameter`` (scaled data per user unit), the prescribed values' rate (full DOF
    vector, scaled) and the rate of the tangential offset at the contact nodes (None: 0; a history carries it)."""
    fem, law = point.fem, point.fem.scene.contact.law
    n = fem.n_free
    prescribed, gap = np.zeros(fem.prescribed.size), np.zeros(point.C.shape[0])
    force, offsets = np.zeros(n + point.obstacle), None if point.friction is None else np.zeros(point.friction.R.shape[0])
    if parameter == "E" and isinstance(fem.scene.materials, Material):  # K is linear in E: dK/dE = K/E
        force[:n] = -(fem.K_full @ fem.full(point.u[:n]))[fem.free] / value
        return Rates(force, gap, offsets), prescribed, None
    if MATERIAL.match(parameter):
        force[:n] = -(stiffness_rate(fem, parameter) @ fem.full(point.u[:n]))[fem.free]
        return Rates(force, gap, offsets), prescribed, None
    if parameter == "slip_bound":
        return Rates(force, gap, offsets, np.full(point.friction.count, 1.0 / fem.scaling.pressure)), prescribed, None
    if parameter == "stiffness":  # λ = c e^p: A du − φ dλ = dh − φ e^p dc = dh − φ λ dc/c on the compliant rows
        return Rates(force, -point.linear.flexibility * point.pressure / value, offsets), prescribed, None
    if parameter == "friction":
        return Rates(force, gap, offsets, point.unit_bound @ np.maximum(point.pressure, 0.0)), prescribed, None
    # the data are affine in these parameters: a forward difference is exact to round-off (and keeps a force ≥ 0);
    # both sides assembled anew (a history step's own trace has its tangential offset shifted by the last slip)
    step = max(abs(value), unit_of(fem, parameter))
    sides = [fem.at(shifted(fem.scene, parameter, value + step)), fem.at(fem.scene)]

    def rate(quantity):
        return (quantity(sides[0]) - quantity(sides[1])) / step

    force = np.concatenate([rate(lambda side: side.f), rate(lambda side: obstacle_forces(side.contact))])
    if point.friction is not None:
        offsets = rate(lambda side: friction_points(side.contact, fem.mesh, fem.basis, law.quadrature,
                                                    law.non_penetration).offset)
    return (Rates(force, rate(lambda side: weighted_gap(side.contact, point.C)), offsets),
            rate(lambda side: side.prescribed), rate(lambda side: side.contact.tangent_offset))


def obstacle_forces(contact) -> np.ndarray:
    """The force-controlled obstacle's loads (P, then Q; scaled) on its unknowns, as :func:`with_obstacle` orders
    them."""
    return np.array([force for force, coupling in ((contact.obstacle_force, contact.obstacle_coupling),
                                                   (contact.obstacle_tangential_force, contact.tangential_coupling))
                     if coupling is not None])


def stiffness_rate(fem: FEModel, parameter: str) -> sp.csr_matrix:
    """dK/dθ (full DOFs, scaled) for θ = E or ν of the material named: K is linear in the Lamé parameters, whose
    derivatives come from a complex step of (E, ν) ↦ (λ, μ), plane stress included (exact to round-off)."""
    name, which = MATERIAL.match(parameter).groups()
    scene, scaling = fem.scene, fem.scaling
    material = scene.materials if name is None else scene.materials[name]
    cells = slice(None) if name is None else fem.mesh.subdomains[name]
    step = 1e-30 * (material.E if which == "E" else 1.0)
    E = material.E + (1j * step if which == "E" else 0.0)
    nu = material.nu + (1j * step if which == "nu" else 0.0)
    lam, mu = lame_parameters(E / scaling.stress, nu)
    if scene.body.plane == "stress" and fem.dim == 2:
        lam = 2.0 * lam * mu / (lam + 2.0 * mu)
    rates = [np.zeros(fem.mesh.t.shape[1]) for _ in range(2)]
    for rate, part in zip(rates, (lam, mu)):
        rate[cells] = np.imag(part) / step
    return stiffness(fem.basis, tuple(rates))


def resultant_maps(point: Point) -> tuple[np.ndarray, np.ndarray | None]:
    """The contact force on the body (d-vector, scaled) as linear maps of λ_N and of λ_T: the nodal forces of
    :func:`~convexcontact.results.result.contact_nodes`, summed."""
    contact = point.fem.contact
    if isinstance(contact, PairTrace):  # the slave's nodal forces, from N and T over both bodies' DOFs
        return pair_resultant_maps(contact, point.C, point.friction)
    normal = -np.asarray(sp.csr_matrix(point.C).T @ contact.normals).T  # −Σ_i (Cᵀλ_N)_i n_i
    if point.friction is None:
        return normal, None
    along = np.hstack([t.T for t in contact.frame])  # d × m(d − 1), component-major like T
    return normal, np.asarray((sp.csr_matrix(contact.T) @ point.friction.R.T).T @ along.T).T


def pair_resultant_maps(contact: PairTrace, C: sp.spmatrix, friction: FrictionPoints | None):
    """:func:`resultant_maps` of a pair of bodies: the forces of :meth:`PairTrace.forces` on the slave's DOFs,
    summed per component (−N_fullᵀCᵀλ_N + T_fullᵀ(w·λ_T), as :func:`~convexcontact.results.certificate.pair_multipliers`
    weighs them)."""
    summing = sp.csr_matrix((np.ones(contact.dofs.size), (np.tile(np.arange(contact.dim), contact.m),
                                                          contact.dofs.ravel())),
                            shape=(contact.dim, contact.N_full.shape[1]))
    normal = -(summing @ contact.N_full.T @ sp.csr_matrix(C).T).toarray()
    if friction is None:
        return normal, None
    weights = np.tile(friction.weights, friction.dim)
    return normal, (summing @ contact.T_full.T).toarray() * weights


def mean_frame(fem: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """The unit mean normal and mean tangent of Γ_C along which the result's normal and tangential forces act."""
    contact = fem.contact
    normal, tangent = contact.weights @ contact.normals, contact.weights @ contact.tangents
    return normal / np.linalg.norm(normal), tangent / np.linalg.norm(tangent)


def derivative_of(point: Point, x: np.ndarray, prescribed: np.ndarray) -> Derivative:
    """The fields of the solution x = (du, dδ, dλ_N, dλ_T) of the derivative system, in user units."""
    fem = point.fem
    scaling, n, r = fem.scaling, fem.n_free, point.C.shape[0]
    displacement = prescribed.copy()
    displacement[fem.free] = x[:n]
    obstacle = dict(zip(obstacle_names(fem.contact), x[n:n + point.obstacle] * scaling.displacement))
    n += point.obstacle
    pressure = fem.contact.nodal_pressure(point.C, x[n:n + r])
    normal_map, tangential_map = resultant_maps(point)
    force = normal_map @ x[n:n + r]
    friction = None
    if point.friction is not None:
        traction = x[n + r:]
        force = force + tangential_map @ traction
        friction = point.friction.nodal_traction(fem.contact, traction) * scaling.pressure
    mean_normal, mean_tangent = mean_frame(fem)
    force = force * scaling.force
    return Derivative(displacement * scaling.displacement, pressure * scaling.pressure, friction, force,
                      float(-force @ mean_normal), None if friction is None else float(force @ mean_tangent),
                      obstacle.get("obstacle_advance"), obstacle.get("obstacle_shift"))


def obstacle_names(contact) -> list[str]:
    """The force-controlled obstacle's unknowns, in the order of :func:`with_obstacle`."""
    return [name for name, coupling in (("obstacle_advance", contact.obstacle_coupling),
                                        ("obstacle_shift", contact.tangential_coupling)) if coupling is not None]


def sensitivity(result, parameter: str | list[str]):
    """Derivatives of ``result``'s answer along ``parameter`` (a name of :data:`PARAMETERS`, or a list of them:
    a dict back, all from one factorization). Where the answer is degenerate, the one-sided derivatives.

    ``result``: a :class:`ContactResult`, or a :class:`~convexcontact.drivers.history.HistoryResult`: then a list
    of one :class:`Sensitivity` per step (per parameter), each step's slip carrying the earlier steps' derivatives."""
    names = [parameter] if isinstance(parameter, str) else parameter
    if not isinstance(names, (list, tuple)) or not names:
        raise SceneError("parameter", f"expected a name or a list of names, got {parameter!r:.60}",
                         f"name one of {', '.join(PARAMETERS)}")
    fields = ["parameter" if isinstance(parameter, str) else f"parameter[{i}]" for i in range(len(names))]
    if isinstance(result, HistoryResult):
        out = history_sensitivity(result, names, fields)
    else:
        result = check_result(result)
        values = {name: parameter_value(result.scene, name, field) for name, field in zip(names, fields)}
        point = point_of(result)
        out = {name: along(point, name, value)[0] for name, value in values.items()}
    return out[parameter] if isinstance(parameter, str) else out


def along(point: Point, parameter: str, value: float, previous: dict | None = None) -> tuple[Sensitivity, dict]:
    """The :class:`Sensitivity` of the answer at ``point`` along one parameter, and the rate of the slip at the
    contact nodes for each direction (what the next step of a history measures its slip from). ``previous``: that
    of the step before, per direction (a history step's tangential offset is minus that slip)."""
    rates, prescribed, tangent = data_rates(point, parameter, value)
    linear, sides, message, slips = point.linear, {}, [], {}
    for sign, side in ((1.0, "right"), (-1.0, "left")):
        directed = Rates(sign * rates.force, sign * rates.gap, None if rates.offset is None else sign * rates.offset,
                         None if rates.bound is None else sign * rates.bound)
        if previous is not None and previous.get(sign) is not None:
            directed.offset = directed.offset - weighted_slip_rate(point, previous[sign])
        x = directional(linear, reduced(point, directed), 1.0)
        if x is None:
            message.append(f"the {side} derivative's complementarity problem on the degenerate rows has no "
                           "solution or several (the answer may branch there)")
            sides[side], slips[sign] = None, None
            continue
        x = expanded(point, x, directed.force)
        sides[side] = derivative_of(point, sign * x, prescribed)
        slips[sign] = slip_rate(point, x, None if tangent is None else sign * tangent)
    degenerate = {"grazing": np.flatnonzero(linear.normal == "grazing")}
    if linear.friction is not None:
        degenerate["stick_slip"] = np.flatnonzero(linear.friction == "boundary")
    sensitivity = Sensitivity(parameter, value, sides["right"], sides["left"], degenerate, point.margin,
                              "; ".join(message))
    return sensitivity, slips


def slip_rate(point: Point, x: np.ndarray, tangent: np.ndarray | None) -> np.ndarray | None:
    """The rate of the slip at the contact nodes, T du + d(offset) − coupling dδ_T (scaled; as the history's
    :meth:`~convexcontact.drivers.history.State.advance` measures the slip), None without friction."""
    contact = point.fem.contact
    if point.friction is None:
        return None
    rate = contact.T @ x[:point.fem.n_free] + (0.0 if tangent is None else tangent)
    if contact.tangential_coupling is not None:
        rate = rate - contact.tangential_coupling * x[point.fem.n_free + point.obstacle - 1]
    return rate


def weighted_slip_rate(point: Point, slip: np.ndarray) -> np.ndarray:
    """The friction points' weighted offset of a slip at the contact nodes (as the offset is weighted)."""
    law, fem = point.fem.scene.contact.law, point.fem
    shifted_trace = replace(fem.contact, tangent_offset=slip)
    return friction_points(shifted_trace, fem.mesh, fem.basis, law.quadrature, law.non_penetration).offset


def history_sensitivity(history, names: list[str], fields: list[str]) -> dict[str, list[Sensitivity]]:
    """The sensitivities of every step of a load history, each step's slip rate carried to the next (forward
    mode, per direction); parameters the history sets at each step are refused."""
    scene = history.scene
    if has_viscosity(scene):
        raise SceneError("materials", "a viscous material: not implemented", "differentiate an elastic body")
    if history.status != "solved":
        raise ValueError(f"result: the history's status is {history.status!r} ({history.message}): only a history "
                         "solved and certified at every step has a derivative — solve it again more tightly")
    values = {}
    for name, field in zip(names, fields):
        path = vector_path(name, field)[0]
        if path in scene.history.values:
            raise SceneError(field, f"{name!r}: the history sets it at every step (history.{path})",
                             "differentiate by a parameter the history does not name")
        values[name] = parameter_value(scene, name, field)
    out, previous = {name: [] for name in names}, dict.fromkeys(names)
    for step in history.steps:
        point = point_of(check_result(step, in_history=True))
        for name, value in values.items():
            sensitivity, previous[name] = along(point, name, value, previous[name])
            out[name].append(sensitivity)
    return out


def gradient(result: ContactResult, parameters: list[str], *, displacement=None, pressure=None, friction=None,
             contact_force=None, normal_force: float = 0.0, tangential_force: float = 0.0,
             obstacle_advance: float = 0.0, obstacle_shift: float = 0.0) -> dict[str, float]:
    """dJ/dθ for every parameter of ``parameters`` by one adjoint solve, where
    J = ⟨displacement, u⟩ + ⟨pressure, λ_N⟩ + ⟨friction, λ_T⟩ + ⟨contact_force, F⟩ + normal_force·P + tangential_force·Q
      + obstacle_advance·δ_N + obstacle_shift·δ_T
    in the result's user units (for a nonlinear objective give its partial derivatives at the answer; the obstacle's
    motions are those of force control).

    Refused where the answer is degenerate (its derivative is one-sided there: :func:`sensitivity`)."""
    if isinstance(result, HistoryResult):
        raise SceneError("result", "a load history: the adjoint through its steps is not implemented",
                         "contract the forward derivatives of cc.sensitivity(history, parameters) instead")
    result = check_result(result)
    if isinstance(parameters, str) or not isinstance(parameters, (list, tuple)) or not parameters:
        raise SceneError("parameters", f"expected a list of names, got {parameters!r:.60}",
                         f"give e.g. ['friction', 'E'] from {', '.join(PARAMETERS)}")
    values = {name: parameter_value(result.scene, name, f"parameters[{i}]") for i, name in enumerate(parameters)}
    fem = result.fem
    weights = objective_weights(result, displacement, pressure, friction, contact_force, normal_force,
                                tangential_force, obstacle_advance, obstacle_shift)
    point = point_of(result)
    linear = point.linear
    if linear.degenerate:
        raise NotDifferentiable(f"result: {int((linear.normal == 'grazing').sum())} grazing nodes and "
                                f"{0 if linear.friction is None else int((linear.friction == 'boundary').sum())} "
                                "friction points at the stick/slip boundary make the answer one-sided: no gradient. "
                                "Use cc.sensitivity for the one-sided derivatives, or move the parameters off this "
                                "point")
    adjoint, interior = adjoint_vector(point, weights)
    out = {}
    for name, value in values.items():
        rates, prescribed, _ = data_rates(point, name, value)
        explicit = weights["displacement"] @ (prescribed * fem.scaling.displacement)  # prescribed DOFs' share
        out[name] = float(adjoint @ right_side(linear, reduced(point, rates)) + interior @ rates.force[:fem.n_free]
                          + explicit)
    return out


def objective_weights(result: ContactResult, displacement, pressure, friction, contact_force, normal_force,
                      tangential_force, obstacle_advance=0.0, obstacle_shift=0.0) -> dict:
    """The objective's weights as arrays of the answer's shapes (zeros where not given), each checked by name."""
    fem = result.fem
    contact = fem.contact
    shapes = {"displacement": (fem.prescribed.size,), "pressure": (contact.m,), "contact_force": (fem.dim,),
              "friction": None if result.contact.friction is None else result.contact.friction.shape}
    given = {"displacement": displacement, "pressure": pressure, "friction": friction, "contact_force": contact_force}
    weights = {}
    for name, value in given.items():
        shape = shapes[name]
        if value is None:
            weights[name] = None if shape is None else np.zeros(shape)
            continue
        if shape is None:
            raise ValueError(f"{name}: the result has no friction traction (a frictionless law) — drop it")
        array = np.asarray(value, dtype=float) if not isinstance(value, str) else None
        if array is None or array.shape != shape or not np.isfinite(array).all():
            raise ValueError(f"{name}: expected {shape} finite numbers (dJ/d{name} at the answer, user units), got "
                             f"{value!r:.60} — give an array of shape {shape}")
        weights[name] = array
    for name, value in (("normal_force", normal_force), ("tangential_force", tangential_force),
                        ("obstacle_advance", obstacle_advance), ("obstacle_shift", obstacle_shift)):
        weights[name] = finite(value, name, f"give dJ/d{name} at the answer as a number")
        if name.startswith("obstacle") and weights[name] != 0 and getattr(result, name) is None:
            raise ValueError(f"{name}: the obstacle's motion is given (no force control), not an unknown of the "
                             "answer — drop it (its derivative is 0)")
    return weights


def adjoint_vector(point: Point, weights: dict) -> tuple[np.ndarray, np.ndarray]:
    """y = M⁻ᵀ g (g the objective's gradient over the unknowns (du, dδ, dλ_N, dλ_T), scaled), and v with
    dJ/dθ = y·b + v·b_u. Condensed: g's displacement part condensed like a load, and v = K_II⁻¹ g_I its interior
    share (K is symmetric); else v = 0."""
    fem = point.fem
    scaling = fem.scaling
    normal_map, tangential_map = resultant_maps(point)
    mean_normal, mean_tangent = mean_frame(fem)
    force = (weights["contact_force"] - weights["normal_force"] * mean_normal
             + weights["tangential_force"] * mean_tangent) * scaling.force
    displacement = weights["displacement"][fem.free] * scaling.displacement
    interior = np.zeros(fem.n_free)
    if point.condensation is not None:
        interior = point.condensation.lift(np.zeros(point.condensation.C.size), displacement)
        displacement = point.condensation.load(displacement)
    motions = [weights[name] * scaling.displacement for name in obstacle_names(fem.contact)]
    parts = [displacement, motions, weights["pressure"] * scaling.pressure + normal_map.T @ force]
    if point.friction is not None:
        traction = weights["friction"].reshape(fem.contact.m, -1).T.ravel() * scaling.pressure
        parts.append(traction + tangential_map.T @ force)
    return point.linear.solver.solve(np.concatenate(parts), trans="T"), interior
