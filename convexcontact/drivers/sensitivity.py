"""Exact sensitivities of a certified answer to the scene's parameters, and gradients of objectives by the adjoint.

:func:`sensitivity` gives du/dθ, dλ_N/dθ, dλ_T/dθ and the resultants' derivatives for a parameter θ named by its
path in the scene (:data:`~.parameters.PARAMETERS`), for one answer or every step of a load history;
:func:`gradient` gives dJ/dθ of a linear functional J of the answer (a misfit's gradient by the chain rule) for many
parameters with one transposed solve. The linear algebra is in :mod:`.active_set`, the answer's active set in
:mod:`.linearized`, the parameters and the data's rates in :mod:`.parameters` (docs/sensitivity.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..fem.friction import friction_points
from ..results.result import ContactResult
from ..scene.checks import finite
from ..scene.description import SceneError
from .active_set import (
    NotDifferentiable,
    Rates,
    directional,
    right_side,
)
from .history_run import HistoryResult
from .linearized import (
    Point,
    check_result,
    expanded,
    has_viscosity,
    mean_frame,
    obstacle_names,
    point_of,
    reduced,
    resultant_maps,
)
from .parameters import PARAMETERS, data_rates, parameter_value, vector_path


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


def sensitivity(result, parameter: str | list[str]):
    """Derivatives of ``result``'s answer along ``parameter`` (a name of :data:`PARAMETERS`, or a list of them:
    a dict back, all from one factorization). Where the answer is degenerate, the one-sided derivatives.

    ``result``: a :class:`ContactResult`, or a :class:`~convexcontact.drivers.history_run.HistoryResult`: then a list
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
    condensed = reduced(point, [rates])[0]  # linear in the rates: condensed once for both directions
    linear, sides, message, slips = point.linear, {}, [], {}
    for sign, side in ((1.0, "right"), (-1.0, "left")):
        directed = Rates(sign * condensed.force, sign * rates.gap,
                         None if rates.offset is None else sign * rates.offset,
                         None if rates.bound is None else sign * rates.bound)
        if previous is not None and previous.get(sign) is not None:
            directed.offset = directed.offset - weighted_slip_rate(point, previous[sign])
        x = directional(linear, directed, 1.0)
        if x is None:
            message.append(f"the {side} derivative's complementarity problem on the degenerate rows has no "
                           "solution or several (the answer may branch there)")
            sides[side], slips[sign] = None, None
            continue
        x = expanded(point, x, sign * rates.force)
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
    :meth:`~convexcontact.drivers.history_run.State.advance` measures the slip), None without friction."""
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
    rates, prescribed, _ = zip(*(data_rates(point, name, value) for name, value in values.items()))
    out = {}
    for name, rate, condensed, moved in zip(values, rates, reduced(point, list(rates)), prescribed):
        explicit = weights["displacement"] @ (moved * fem.scaling.displacement)  # prescribed DOFs' share
        out[name] = float(adjoint @ right_side(linear, condensed) + interior @ rate.force[:fem.n_free] + explicit)
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
