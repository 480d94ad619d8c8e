"""Histories of elasto-viscoplastic bodies (von Mises, Perzyna): each step one conic program (docs/plasticity.md).

The contact side is the elastic history's (:mod:`.history_run`: the step's loads and obstacle, friction on the slip
increment, the primal program); :class:`PlasticProcess` carries the plastic strain α and the accumulated plastic
strain from step to step, and :class:`PlasticStepper` extends each step's program with the plastic points
(:func:`~convexcontact.formulations.plastic_step.plastic`), solves it and certifies the contact and the material law.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .. import solvers
from ..conic import ConicSolution
from ..fem.plasticity import material_per_element, plastic_points
from ..formulations.fields import ContactFields
from ..formulations.plastic_step import PlasticStep, plastic
from ..results.certificate import Certificate
from ..results.plastic_state import PlasticResult, PlasticState
from ..scene.bodies import Bodies
from ..scene.description import Coulomb, Material, Scene, SceneError
from ..scene.load_history import VISCOUS_RATIO, power
from . import plastic_polish
from .history_run import PROCESSES, Process, keeping_K
from .prepared import CERTIFIED, Model, judge, timed

CONIC_SOLVERS = ("auto", "clarabel", "cvxpy")
"""The solver paths that take the plastic points' second-order cones."""


def plastic_scene(scene: Scene) -> bool:
    """Whether a material of ``scene`` has a yield stress."""
    materials = scene.materials.values() if isinstance(scene.materials, dict) else (scene.materials,)
    return any(isinstance(m, Material) and m.plastic for m in materials)


def check_plastic_scene(scene: Scene, formulation: str, solver: str) -> None:
    """Refuse, before any assembly, what the plastic steps are not built for."""
    if scene.body.plane != "strain":  # 2-D only: a 3-D body refuses plane stress itself
        raise SceneError("body.plane", "plasticity is built for plane strain and 3-D bodies (plane stress bends the "
                         "yield surface of the in-plane stresses)", "give plane = 'strain' (the default)")
    if isinstance(scene.body, Bodies):
        raise SceneError("materials", "a yield stress in a scene of several bodies: plasticity is built for one body",
                         "drop yield_stress from the parts' materials, or model one body against a rigid obstacle")
    if isinstance(scene.contact.law, Coulomb):
        raise SceneError("contact.law", "Coulomb friction on a plastic body is not built (each step would run the "
                         "Picard map over a plastic program)", "use 'signorini' or 'tresca' with a plastic body")
    if formulation not in ("auto", "primal"):
        raise SceneError("formulation", f"{formulation!r}: a plastic body's strains couple all its DOFs, so its steps "
                         "are posed in the primal only", "use formulation='primal' or 'auto'")
    check_plastic_steps(scene)
    if solver.partition(":")[0] not in CONIC_SOLVERS:
        raise ValueError(f"solver: {solver!r} cannot take the plastic points' second-order cones; use 'clarabel' "
                         "(or 'auto'), or 'cvxpy:NAME' with a conic solver such as 'cvxpy:CLARABEL'")


def check_plastic_steps(scene: Scene) -> None:
    """Refuse a step Δt so short against a material's plastic relaxation time η_p/E that the viscous term drowns the
    elastic one (:data:`~convexcontact.scene.load_history.VISCOUS_RATIO`, as for Kelvin–Voigt steps); compared by
    logarithms, the ratio may be beyond the floats."""
    materials = scene.materials.values() if isinstance(scene.materials, dict) else (scene.materials,)
    viscous = [math.log10(m.plastic_viscosity) - math.log10(m.E) for m in materials if m.plastic_viscosity > 0]
    steps = np.diff((0.0, *scene.history.times))
    k = int(np.argmin(steps))
    if viscous and max(viscous) - math.log10(steps[k]) > math.log10(VISCOUS_RATIO):
        raise SceneError(f"history.times[{k}]", f"a step of Δt = {steps[k]:.3g} against a plastic relaxation time "
                         f"η_p/E = {power(max(viscous))}: the plastic increment is lost in round-off",
                         f"take steps of at least {power(max(viscous) - 12)}, or a smaller plastic_viscosity")


class PlasticProcess(Process):
    """:class:`~.history_run.Process` with the plastic state: α and the accumulated plastic strain at the points."""

    def __init__(self, scene: Scene, timings: dict):
        super().__init__(scene, "primal", timings)
        fem = self.fem
        with timed(timings, "plastic points"):
            self.points = plastic_points(fem)
            self.coupling = self.points.coupling()
        sigma, eta = (self.points.per_point(values) for values in material_per_element(fem))
        self.radius = np.sqrt(2.0 / 3.0) * sigma / fem.scaling.pressure  # inf at elastic points
        self.relaxation = eta / fem.scaling.stress  # η_p/E, a time
        self.yielding = np.isfinite(self.radius)
        self.columns = np.repeat(self.yielding, self.points.components)
        self.alpha = np.zeros(self.columns.size)
        self.accumulated = np.zeros(self.points.count)

    def step_model(self, k: int, timings: dict) -> Model:
        times = self.history.times
        self.dt = times[k] - (times[k - 1] if k else 0.0)
        return super().step_model(k, timings)

    def step(self, model: Model) -> PlasticStep:
        """The plastic data of the step whose contact program is ``model``'s."""
        points, yielding, columns = self.points, self.yielding, self.columns
        weights = np.repeat(points.weights, points.components)[columns]
        coupling = self.coupling[:, columns]
        return PlasticStep(
            coupling=coupling[model.fem.free], prescribed=coupling.T @ model.fem.prescribed,
            stiffness=np.repeat(points.shear, points.components)[columns] * weights,
            viscosity=np.repeat(self.relaxation / self.dt, points.components)[columns] * weights,
            dissipation=points.weights[yielding] * self.radius[yielding], old=self.alpha[columns],
            components=points.components)

    def state(self, u_full: np.ndarray) -> PlasticState:
        return PlasticState.of(self.points, u_full, self.alpha, self.accumulated, self.radius, self.relaxation / self.dt)

    def advance(self, result: PlasticResult):
        super().advance(result)
        self.alpha, self.accumulated = result.plastic.alpha, result.plastic.accumulated


class PlasticStepper:
    """Solves a plastic step and certifies it: the contact certificate, with the plastic strain's nodal forces Gα
    as a load, and the material law's residuals (:meth:`PlasticState.residuals`). Where Newton's method applies
    (:mod:`.plastic_polish`) it finishes the interior point's answer."""

    def __init__(self, process: PlasticProcess, solver: str, options: dict):
        self.process, self.solver, self.options = process, solver, options

    def solve(self, model: Model, key, timings: dict) -> PlasticResult:
        process = self.process
        with timed(timings, "formulation"):
            program, contact = plastic(model.program, process.step(model))
        with timed(timings, "solve"):
            solution = contact(solvers.solve(program, self.solver, **self.options))
        with timed(timings, "postprocess"):
            polished = None
            if plastic_polish.applies(model) and solution.solved and np.isfinite(solution.x).all():
                polished = plastic_polish.polish(model, process.points, process.coupling, process.alpha,
                                                 process.radius, process.relaxation / process.dt, model.recover(solution))
            return self.result(model, solution, *(polished or (None, 0)), timings)

    def result(self, model: Model, solution: ConicSolution, fields: ContactFields | None, newton_steps: int,
               timings: dict):
        """The certified result of the step from the solver's ``solution`` of its contact program, or from Newton's
        ``fields`` where they were found."""
        process, fem = self.process, model.fem
        u_full = fem.full(fields.u if fields is not None else solution.x[: fem.n_free])
        state = process.state(u_full)
        loaded = keeping_K(replace(fem, f_full=fem.f_full + process.coupling @ state.alpha), fem)
        result = replace(model, fem=loaded).result(solution, timings, model.slip_bound, fields=fields,
                                                   extra={"newton_steps": newton_steps})
        result.fem = fem
        if result.certificate is None:
            return result
        result.certificate = Certificate({**result.certificate.residuals, **state.residuals(u_full)})
        status, result.message = judge(solution, result.certificate, False)
        if solution.status == status == "inaccurate" and result.certificate.passes(CERTIFIED):
            # the residuals are those of the step's whole optimality system (equilibrium, flow rule, contact): passing,
            # they certify the answer whatever the solver's word (Clarabel's AlmostSolved at tol 1e-12)
            status, result.message = "solved", f"{solution.solver} reported {solution.solver_status}; certified"
        result.status = status or solution.status
        if status is None:
            result.displacement = result.contact = None
        return PlasticResult.of(result, state)


def build(scene: Scene, formulation: str, solver: str, options: dict, timings: dict):
    """The process and stepper of a plastic history (:data:`.history_run.PROCESSES`)."""
    check_plastic_scene(scene, formulation, solver)
    process = PlasticProcess(scene, timings)
    return process, PlasticStepper(process, solver, options)


PROCESSES.append((plastic_scene, build))
