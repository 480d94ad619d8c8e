"""Quasistatic contact processes: a load history solved step by step (seed 002, eq. 2.2.1).

Inertia is neglected; friction depends on the slip *rate*, discretized by backward Euler:
at step k the friction energy acts on the slip increment u_T^k − u_T^{k−1},

    min ½uᵀKu − fᵀu + Σ s |R u + c^k − v^{k−1}|   s.t. non-penetration at step k,

i.e. today's exact program with the tangential offset shifted by the previous step's slip
v^{k−1} (relative to the obstacle). A point that sticks keeps its position; reverse slip on
unloading comes out of the law. Kelvin–Voigt bodies (σ = A ε(u̇) + B ε(u), eq. 2.3.3, with
A = τ B per material, τ = η/E) take the matrix K + K_A/Δt and the load f^k + K_A u^{k−1}/Δt.

Everything that does not change is built once: the mesh, K and the formulation's choice, and
K's condensation (W) for each distinct Δt; one solver session runs the whole history, each step
updating q and b and starting from the previous answer (Clarabel's polish, OSQP's warm start).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .. import solvers
from ..fem.assembly import FEModel, assemble, viscous_stiffness
from ..results.result import ContactResult
from ..scene.description import Coulomb, Scene, SceneError, of_type
from ..scene.load_history import History
from ..scene.meshing import available_memory
from .estimates import LONG_RUN, duration, footprint, reachable
from .prepared import CERTIFIED, Model, ProgramSession, check_formulation_name, condensed, formulate, timed


@dataclass
class HistoryResult:
    """The answers of every step of a history, with the reuse that made them cheap."""

    scene: Scene
    history: History
    steps: list[ContactResult]
    timings: dict = field(default_factory=dict)

    @property
    def times(self) -> tuple[float, ...]:
        return self.history.times[: len(self.steps)]

    @property
    def status(self) -> str:
        """solved when every step is; else the first step's status that is not."""
        for step in self.steps:
            if step.status != "solved":
                return step.status
        return "solved" if len(self.steps) == len(self.history) else "failed"

    @property
    def message(self) -> str:
        for k, step in enumerate(self.steps):
            if step.status != "solved":
                return f"step {k + 1} (t = {self.times[k]:g}): {step.status}: {step.message}"
        return ""

    def series(self) -> dict[str, list]:
        """Per-step scalars: forces, zones, obstacle motion, certificate (None where a step has no answer)."""
        names = ("normal_force", "tangential_force", "max_pressure", "contact_half_width", "obstacle_advance",
                 "obstacle_shift")
        out = {"time": list(self.times), "status": [s.status for s in self.steps]}
        plastic = ("max_equivalent_plastic_strain", "max_von_mises") if any(hasattr(s, "plastic") for s in self.steps) \
            else ()
        for name in names + plastic:
            out[name] = [value(step, name) for step in self.steps]
        out["n_closed"] = [int(s.closed.sum()) if s.solved else None for s in self.steps]
        for state in ("stick", "slip"):
            out[f"n_{state}"] = [int(np.char.startswith(s.contact.status.astype(str), state).sum())
                                 if s.solved else None for s in self.steps]
        out["certificate"] = [s.certificate.worst if s.certificate else None for s in self.steps]
        return out

    def summary(self) -> dict:
        return {"scene": self.scene.name, "status": self.status, "message": self.message, "steps": len(self.steps),
                "timings": self.timings, "series": self.series(), "step": [s.summary() for s in self.steps]}

    def save(self, directory, formats=("json", "vtk", "png")) -> list:
        """summary.json, one solution_NNNN.vtu per step with a solution.pvd time series, history plots."""
        from ..results.history_out import save_history

        return save_history(self, directory, formats)


def value(step: ContactResult, name: str):
    if not step.solved:
        return None
    number = getattr(step, name)
    return None if number is None or (name == "tangential_force" and step.contact.friction is None) else float(number)


class Process:
    """The state a history carries from step to step: the last displacement and slip, and what is reused."""

    def __init__(self, scene: Scene, formulation: str, timings: dict):
        self.scene, self.history = scene, scene.history
        with timed(timings, "assembly"):
            self.fem = assemble(self.history.envelope(scene))  # units from the largest load of the history
            self.viscous = viscous_stiffness(self.fem)  # None for elastic bodies
        self.model = formulate(self.fem, formulation, timings)
        self.condensations = {None: self.model.condensation}  # per Δt (Kelvin–Voigt changes K)
        self.u = np.zeros(self.fem.basis.N)  # t0 = 0: undeformed
        self.slip = None  # absolute tangential positions relative to the obstacle, at the contact nodes
        self.pressure = None  # nodal pressures of the last step, user units

    def step_model(self, k: int, timings: dict) -> Model:
        """The program of step k: this step's loads, K (viscous), and the slip measured from step k − 1.
        A Coulomb law's Picard map starts from the pressures of step k − 1."""
        scene = self.history.scene(self.scene, k)
        law = scene.contact.law
        if isinstance(law, Coulomb) and self.pressure is not None and law.initial_pressure is None:
            scene = scene.with_law(replace(law, initial_pressure=self.pressure))
        fem = self.fem.at(scene)
        self.key = None  # what K depends on: Δt for viscous bodies
        if self.viscous is not None:
            dt = self.history.times[k] - (self.history.times[k - 1] if k else 0.0)
            fem, self.key = viscous_step(fem, self.viscous, dt, self.u), dt
        self.absolute = fem.contact
        if self.slip is not None:
            fem = keeping_K(replace(fem, contact=replace(fem.contact, tangent_offset=fem.contact.tangent_offset -
                                                         self.slip)), fem)
        if self.model.formulation == "dual" and self.key not in self.condensations:
            self.condensations[self.key] = condensed(fem, timings)
        condensation = self.condensations.get(self.key)
        return formulate(fem, self.model.formulation, timings, condensation, self.model.reason)

    def advance(self, result: ContactResult):
        """Keep the step's displacement and slip for the next step."""
        fem = result.fem
        u = result.displacement / fem.scaling.displacement
        self.u, self.pressure = u, result.contact.pressure
        contact = self.absolute
        if contact.tangential_coupling is None and self.model.friction is None:
            return
        shift = 0.0 if result.obstacle_shift is None else result.obstacle_shift / fem.scaling.displacement
        coupling = 0.0 if contact.tangential_coupling is None else contact.tangential_coupling * shift
        self.slip = contact.T @ u[fem.free] + contact.tangent_offset - coupling


def keeping_K(copy: FEModel, fem: FEModel) -> FEModel:
    """``copy`` (of ``fem`` with another contact trace) with ``fem``'s K, not its own: each step held a K of its own
    (42 kB of a 306-DOF block's 57 kB a step)."""
    copy.__dict__.update({"K": fem.__dict__["K"]} if "K" in fem.__dict__ else {})
    return copy


def viscous_step(fem: FEModel, viscous, dt: float, u_previous: np.ndarray) -> FEModel:
    """Backward Euler for Kelvin–Voigt: K + K_A/Δt and f + K_A u^{k−1}/Δt (full DOF vectors)."""
    step = replace(fem, K_full=(fem.K_full + viscous / dt).tocsr(), f_full=fem.f_full + viscous @ u_previous / dt)
    return step


def run(scene: Scene, solver: str = "clarabel", formulation: str = "auto", progress=None, confirm: bool = False,
        **options) -> HistoryResult:
    """Solve ``scene``'s history step by step; ``progress(step, count, result)`` after each step.

    A step that fails ends the history there (later steps start from its state): the result
    holds the steps solved so far, and its status and message name the failing step. Every step's
    result is kept. After :data:`MEASURED_STEPS` steps the rest is estimated from the last one (time, and the
    memory its result holds): beyond the memory available it is refused, beyond :data:`LONG_RUN` seconds it
    needs ``confirm=True`` (``convexcontact run --confirm``).
    """
    of_type(scene, Scene, "scene", "build cc.Scene(...) or cc.bodies_scene(...) with history=cc.History(...)")
    if scene.history is None:
        raise SceneError("history", "the scene has no history", "give history = {times = [...], ...} or solve it statically")
    solvers.check_options({**options, "progress": progress}, solvers.check_name(solver))
    check_formulation_name(formulation, what=" for a history")
    of_type(confirm, bool, "confirm", "give confirm=True to run a history estimated to take long, else leave it out")
    scene.history.check(scene)
    timings: dict = {}
    build = next((build for applies, build in PROCESSES if applies(scene)), None)
    process, stepper = build(scene, formulation, solver, options, timings) if build else \
        (Process(scene, formulation, timings), Stepper(solver, options))
    results, count = [], len(scene.history)
    for k in range(count):
        step_timings: dict = {}
        start = time.perf_counter()
        with timed(timings, "steps"):
            model = process.step_model(k, step_timings)
            result = stepper.solve(model, process.key, step_timings)
        result.extra["time"] = scene.history.times[k]
        judge_on_its_own_scale(result, process.fem)
        results.append(result)
        if progress is not None:
            progress(k + 1, count, result)
        if not result.solved:
            break
        process.advance(result)
        if k + 1 == MEASURED_STEPS and count > MEASURED_STEPS:
            check_cost(count, results, time.perf_counter() - start, confirm)
    return HistoryResult(scene, scene.history, results, timings)


PROCESSES: list[tuple[Callable, Callable]] = []
"""(applies(scene), build(scene, formulation, solver, options, timings) → (process, stepper)) of the bodies whose steps
are no elastic program, registered by their modules (:mod:`.plastic_history`)."""


def judge_on_its_own_scale(result: ContactResult, envelope: FEModel) -> None:
    """Mark "inaccurate" a step certified only on the history's scale. The units are the largest step's, and the
    certificate measures residuals against at least one unit, so a step loaded with 10⁻⁹ of the largest load passed
    with its contact force 13 % off (10⁻¹²: reported 0). Divided by the step's own scale — its loads, prescribed
    motion and obstacle motion against the largest ones (:func:`drive`), or its own pressures (a state locked in by
    friction), at most one unit — its certificate must pass as well."""
    if result.status != "solved":
        return
    scaling, worst = result.fem.scaling, result.certificate.worst
    pressure = np.abs(result.contact.pressure).max(initial=0.0) / scaling.pressure
    scale = min(1.0, max([pressure, *(a / b for a, b in zip(drive(result.fem), drive(envelope)) if b > 0)]))
    own = worst / scale if scale > 0 else (0.0 if worst == 0 else np.inf)
    if own > CERTIFIED:
        result.status = "inaccurate"
        result.message = (f"its loads, motion and pressures are {scale:.2g} of the history's largest: its certificate "
                          f"{worst:.2g} passes on the history's scale, but is {own:.2g} on its own (over {CERTIFIED:g}); "
                          "run the small steps as a history of their own, or give a smaller tol")


def drive(fem: FEModel) -> tuple[float, ...]:
    """What drives a step, in magnitudes: its load vector, its prescribed displacements, and its rigid obstacles'
    depths, gaps and forces."""
    contact = fem.scene.contact
    obstacles = [c.obstacle for c in getattr(contact, "pairs", (contact,)) if not hasattr(c, "master")]
    motion = [max((abs(getattr(obstacle, name) or 0.0) for obstacle in obstacles), default=0.0)
              for name in ("depth", "force", "tangential_force", "gap")]
    return (np.abs(fem.f_full).max(initial=0.0), np.abs(fem.prescribed).max(initial=0.0), *motion)


MEASURED_STEPS = 2
"""Steps solved before the rest of a history is estimated: the first sets up the solver session, the second
starts from the first's answer, as every later step does."""


def check_cost(count: int, steps: list[ContactResult], seconds: float, confirm: bool) -> None:
    """Refuse the rest of a history whose steps, estimated from the last one, would not fit in memory, or would take
    more than :data:`LONG_RUN` unless ``confirm``."""
    done, remaining = len(steps), count - len(steps)
    held = footprint(steps[-1], reachable(steps[:-1]))
    measured = f"measured on step {done}: {seconds:.3g} s and {held / 1e3:.3g} kB held"
    need, have = remaining * held, available_memory()
    if need > have:
        raise SceneError("history.times", f"{count} steps would hold about {need / 2**30:.3g} GiB (every step's "
                         f"result is kept; {measured}), and this machine has {have / 2**30:.3g} GiB available",
                         f"give fewer steps (about {done + int(have // held)} fit), or a coarser mesh")
    if remaining * seconds > LONG_RUN and not confirm:
        raise SceneError("history.times", f"{count} steps would take about {duration(remaining * seconds)} more "
                         f"({measured}; {need / 2**30:.3g} GiB held in all)",
                         "give fewer steps, or confirm=True (convexcontact run --confirm) to run them all")


class Stepper:
    """The solver session of the history, kept while K is (one per Δt for viscous bodies): each step
    updates q and b and starts from the last answer. Coulomb steps run the Picard driver, whose
    sessions are kept the same way (each update carries the step's q and b besides the slip bounds).
    The session is a :class:`ProgramSession`, as :meth:`Model.solve`'s (left to ``auto``: newton-cg on a dense dual)."""

    def __init__(self, solver: str, options: dict):
        self.solver, self.options = solver, options
        self.key, self.session, self.cache = object(), None, {}

    def solve(self, model: Model, key, timings: dict) -> ContactResult:
        if key != self.key:
            self.key, self.session, self.cache = key, ProgramSession(self.solver, self.options), {}
        if isinstance(model.law, Coulomb):
            from .picard import coulomb

            program, bounds = model.program, model.bound_update
            model.cache = self.cache
            model.bound_update = lambda s: {"q": program.q, "b": program.b, **bounds(s)}
            return coulomb(model, self.solver, **self.options)
        return self.session.solve(model, timings)
