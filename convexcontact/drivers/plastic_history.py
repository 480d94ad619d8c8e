"""Histories of elasto-viscoplastic bodies (von Mises, Perzyna): each step one convex program (docs/plasticity.md).

The contact side is the elastic history's (:mod:`.history_run`: the step's loads and obstacle, friction on the slip
increment, the primal program); :class:`PlasticProcess` carries the plastic strain α and the accumulated plastic
strain from step to step, and :class:`PlasticStepper` solves each step — by Newton's method on the reduced step energy
from the last step's answer where it applies (:mod:`.plastic_polish`), else, or where Newton fails, by the conic
program extended with the plastic points (:func:`~convexcontact.formulations.plastic_step.plastic`) — and certifies
the contact and the material law. A Coulomb step is the Picard map over such steps (:mod:`.plastic_coulomb`); a scene of
several bodies is one mesh, its plastic parts' cells carrying the points.
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
from ..results.certificate import Certificate, certify
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
        field_name = "body.plane"
        if isinstance(scene.body, Bodies):  # the parts share one hypothesis: named by the first plastic part's
            field_name = next(f"parts[{part.name}].plane" for part in scene.body.parts if part.material.plastic)
        raise SceneError(field_name, "plasticity is built for plane strain and 3-D bodies (plane stress bends the "
                         "yield surface of the in-plane stresses)", "give plane = 'strain' (the default)")
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
        # a Coulomb step's map starts from the last step's pressures; the first's from none (s = 0), so that its
        # first inner step is the plastic Signorini step, not the elastic one
        self.pressure = np.zeros(fem.contact.m)

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
    as a load, and the material law's residuals (:meth:`PlasticState.residuals`).

    Where Newton's method applies (:mod:`.plastic_polish`) and ``fast``, the step is first solved by it from the last
    step's answer; the conic program is solved only where that fails (``extra["fallback"]`` says why), and its answer
    is finished by Newton as well. ``extra["path"]`` is "newton" or "conic"."""

    def __init__(self, process: PlasticProcess, solver: str, options: dict, fast: bool = True):
        self.process, self.solver, self.options, self.fast = process, solver, options, fast
        self.previous: ContactFields | None = None  # the last step's answer (scaled): the fast path's start
        self.increment: np.ndarray | None = None  # the last step's displacement increment (scaled, free DOFs)
        self.factors: dict = {}  # the tangent's factorization, its ordering kept from step to step

    def plastic(self) -> plastic_polish.Plastic:
        process = self.process
        return plastic_polish.Plastic(process.points, process.coupling, process.alpha, process.radius,
                                      process.relaxation / process.dt, self.factors)

    def solve(self, model: Model, key, timings: dict) -> PlasticResult:
        if isinstance(model.law, Coulomb):
            from .plastic_coulomb import coulomb_step

            return coulomb_step(self, model, timings)
        result, _, fields = self.answer(model, timings, *self.start(model))
        return self.kept(result, fields if result.status == "solved" else None)

    def answer(self, model: Model, timings: dict, u: np.ndarray, y: np.ndarray):
        """The certified result of the step whose contact program is ``model``'s, its solution (Newton's as a
        ConicSolution, its path in ``info["plastic"]``) and its fields (None without an answer); Newton from the
        guess (``u``, ``y``) first where it applies, the conic program where it fails."""
        newton = plastic_polish.applies(model)
        extra = {}
        if newton and self.fast:
            with timed(timings, "newton"):
                outcome = plastic_polish.newton(model, self.plastic(), u, y)
            if outcome.fields is not None:
                solution = ConicSolution(x=outcome.fields.u, z=np.zeros(0), s=np.zeros(0), status="solved",
                                         solver_status="converged", iterations=outcome.steps,
                                         solve_time=timings["newton"], solver="plastic-newton",
                                         info={"plastic": {"path": "newton", "newton_steps": outcome.steps}})
                result = self.result(model, solution, outcome.fields, timings)
                if result.status == "solved":
                    return result, solution, outcome.fields
                outcome.reason = f"Newton's answer failed its certificate ({result.certificate.worst:.1e})"
            extra = {"fallback": outcome.reason, "fallback_newton_steps": outcome.steps}
        with timed(timings, "formulation"):
            program, contact = plastic(model.program, self.process.step(model))
        with timed(timings, "solve"):
            solution = contact(solvers.solve(program, self.solver, **self.options))
        with timed(timings, "postprocess"):
            outcome = plastic_polish.Outcome(None, 0)
            usable = solution.solved and np.isfinite(solution.x).all()
            if newton and usable:
                fields = model.recover(solution)
                outcome = plastic_polish.newton(model, self.plastic(), fields.u, self.multipliers(model, fields))
            solution = replace(solution, info={**solution.info, "plastic": {"path": "conic",
                                                                             "newton_steps": outcome.steps, **extra}})
            result = self.result(model, solution, outcome.fields, timings)
        return result, solution, outcome.fields or (model.recover(solution) if usable else None)

    def start(self, model: Model) -> tuple[np.ndarray, np.ndarray]:
        """The fast path's guess: the last step's displacement, moved along its increment as far as the contact rows
        closed then ask (:func:`~.plastic_polish.secant`), and its contact multipliers (zero at the first step)."""
        rows = model.fem.contact.m + (model.friction.R.shape[0] if model.friction else 0)
        if self.previous is None:
            return np.zeros(model.fem.n_free), np.zeros(rows)
        u, y = self.previous.u.copy(), self.multipliers(model, self.previous)
        return u + plastic_polish.secant(model, u, y, self.increment), y

    @staticmethod
    def multipliers(model: Model, fields: ContactFields) -> np.ndarray:
        """The contact multipliers (pressures, then friction tractions) of ``fields``, scaled."""
        return np.concatenate([fields.pressure] + ([fields.friction] if model.friction else [])).astype(float)

    def kept(self, result: PlasticResult, fields: ContactFields | None) -> PlasticResult:
        """``result``, its fields kept as the next step's start."""
        if fields is not None:
            self.increment = fields.u - self.previous.u if self.previous is not None else fields.u
            self.previous = fields
        return result

    def loaded(self, model: Model, u: np.ndarray) -> tuple[Model, PlasticState]:
        """``model`` with the plastic strain's nodal forces Gα at the displacement ``u`` (free DOFs) as a load, and
        the plastic state there."""
        fem = model.fem
        state = self.process.state(fem.full(u))
        return replace(model, fem=keeping_K(replace(fem, f_full=fem.f_full + self.process.coupling @ state.alpha),
                                            fem)), state

    def residual(self, model: Model, fields: ContactFields, bound: np.ndarray) -> float:
        """The worst residual of the step's whole certificate (contact under the slip bound ``bound``, material)."""
        loaded, state = self.loaded(model, fields.u)
        fem = loaded.fem
        contact = certify(fem.K, fem.f, fem.contact, model.C, fields, model.friction, bound, model.epsilon,
                          model.compliance)
        return max([contact.worst, *state.residuals(fem.full(fields.u)).values()])

    def result(self, model: Model, solution: ConicSolution, fields: ContactFields | None, timings: dict,
               bound: np.ndarray | None = None, extra: dict | None = None):
        """The certified result of the step from the solver's ``solution`` of its contact program, or from Newton's
        ``fields`` where they were found; the friction law's slip bound ``bound`` (the model's where None: Coulomb's
        is the answer's own); ``solution.info["plastic"]`` goes to ``extra`` (the path, the Newton steps)."""
        fem = model.fem
        u = fields.u if fields is not None else solution.x[: fem.n_free]
        loaded, state = self.loaded(model, u)
        u_full = fem.full(u)
        result = loaded.result(solution, timings, model.slip_bound if bound is None else bound, fields=fields,
                               extra={**solution.info.get("plastic", {}), **(extra or {})})
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
