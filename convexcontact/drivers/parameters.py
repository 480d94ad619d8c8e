"""A scene's differentiable parameters: their names, their values, the scene at another value, and the rates of
the discrete problem's data along each (scaled data per unit of the user's parameter).

The data depend on loads, Dirichlet values and the obstacle's depth, gap or forces affinely: their rates are the
difference of two assemblies at the model's fixed units, exact up to round-off. K is linear in E and in the Lamé
parameters, whose derivative in ν is taken by a complex step (exact to round-off): dK is assembled once."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from skfem.models.elasticity import lame_parameters

from ..fem.assembly import FEModel
from ..fem.friction import friction_points
from ..fem.stiffness import stiffness
from ..scene.checks import finite
from ..scene.description import Coulomb, Material, NormalCompliance, Scene, SceneError, Tresca, compliance_of, of_type
from ..scene.load_history import PATH, at, check_effect
from .active_set import Rates
from .linearized import Point, weighted_gap

PARAMETERS = ("E", "nu", "materials[NAME].E|nu", "friction (Coulomb)", "slip_bound (Tresca)",
              "stiffness (normal compliance)", "obstacle.depth",
              "obstacle.gap", "obstacle.force", "obstacle.tangential_force", "dirichlet[BOUNDARY].ux|uy|uz",
              "traction[BOUNDARY].pressure", "traction[BOUNDARY].vector[I]", "body_force[I]")


MATERIAL = re.compile(r"^(?:materials\[([^\]]+)\]\.)?(E|nu)$")


COMPONENT = re.compile(r"^(.*(?:vector|body_force))(?:\[(\d)\])?$")


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
