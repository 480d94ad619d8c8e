"""Coulomb and nonlocal Coulomb friction: a Picard map over normal pressures.

    s^{k+1} = (1 − ω) s^k + ω F·S(λ_N(s^k)),

λ_N(s) the pressure of the exact Tresca program with slip bound s (Oden's
algorithm III/IV, Hild's map Φ), its steps combined by Anderson mixing (:class:`Anderson`;
``Coulomb(acceleration=0)`` runs the plain map). On the dual, Newton's method on the Coulomb
problem itself is tried first (:func:`coulomb_newton`); the map runs where it stalls. Only the
slip bounds change between steps: the program, the factorization (dual) and the solver's setup
are built once, and each step updates the data of one solver session (OSQP also warm-starts).

The map converges only for small enough F (Hild); otherwise it may stagnate, cycle
or diverge. The driver adapts: an oscillating, cycling or diverging map is run again with
half the relaxation ω; one that fails otherwise (stagnates, inaccurate or failed inner
solves) with the other formulation, then the other solvers. Each run is an *attempt*,
recorded in ``extra["picard"]["attempts"]``.
The map stops when its relative change is below max(tol, NOISE × the inner solve's own
residual): never below what the inner solver can reach. What no attempt solves is a
reported outcome — with the best iterate, its Coulomb residuals and the whole history —
never an exception and never a silent success. A driver whose inner problem is no program of the
model's (a plastic step) gives the map an :class:`InnerStep` in place of the solver session.
"""

from __future__ import annotations

import hashlib
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..conic import ConicSolution
from ..fem.mollifier import mollifier
from ..formulations.dual import normal_multipliers
from ..results.certificate import certify
from ..scene.description import Coulomb, SceneError, evaluate_field
from ..solvers.newton_cg import bound_form_of
from .prepared import CERTIFIED, CHOSEN, LAW_DRIVERS, Model, field_at_points, formulate, timed

CYCLE_PERIODS = (2, 3, 4)
WINDOW = 8
"""Iterations looked back on to call the map cycling, diverging or stagnating."""
HALVINGS = 4
"""Times ω is halved on an oscillating, cycling or diverging map before another formulation or solver is tried
(Hild's triangle, unique solutions up to F = 4 > F_c = 1.8: ω = 1 cycles, ω = ½ converges)."""
NOISE = 10.0
"""A change of the slip bounds below NOISE × the inner solve's residual (its certificate against
the bound it was given) is the inner solver's noise: the map has converged as far as it can."""
ALTERNATIVES = ("clarabel", "osqp")
"""Solvers tried, at their defaults, after the user's one fails on both formulations."""
START_TOL = 1e-8
"""Natural residual of the frictionless solve that only gives Newton's Coulomb solve on the matrix-free dual its
start: on a 2-D strip of 4001 nodes (10⁶ DOFs) the Newton solve took 141 products with W from it at 1e-2, 137 from the
frictionless answer at 1e-4 and 250 from newton-cg's own start (the whole solve 17.0, 18.2 and 27.8 s). Not looser:
newton-cg's residual is relative to max(‖v‖, ‖c q‖), and on a strip 400 : 1 clamped at its ends ‖c q‖ is 10³ ‖v‖
(LOAD_SCALE), so at 1e-2 the start was no answer (1,400–2,000 of 4,400 nodes open where the answer has none; the tol
also floors the CG of the empty face's first point, FIRST_FORCING): Newton on the Coulomb problem stalled there and the
Picard map ran (5·10⁴ DOFs 7 Picard steps, 16–40 s; 10⁵ a failed inner solve, then the primal map, 179 s). At 1e-8:
3 Newton steps, 2.6 and 4.0 s (docs/performance.md, "The clamped strip 400 : 1's Coulomb row"). Where W is a matrix
only: where it is an operator, the stick start (STICK_START)."""
STICK_START = 1
"""Where W is an operator, Newton's Coulomb solve starts from the STICK_START first Newton points of its own program
with every ball unbounded (every point sticking: the empty face's point, grown by the bounds it leaves; FIRST_FORCING,
GROW), each point outside its Coulomb disc then put on its edge (:func:`stick_start`): no frictionless program is
solved (with its own step lengths and preconditioner). Products with W of start + Newton, Newton steps, matrix-free,
from the frictionless start → the stick start (docs/performance.md, "The Coulomb start on the clamped strips"):
clamped strip 400 : 1 at 10⁵ DOFs 42 + 65, 3 → 15 + 33, 3; at 2·10⁴ 24 + 33, 4 → 8 + 16, 2; 100 : 1 28 + 31, 4 →
10 + 21, 3; the clamped plate 20 : 20 : 1 12 + 51, 5 → 8 + 20, 3; where most points slip (3-D, forced matrix-free):
tall block 10 + 126, 7 → 10 + 61, 5; flat block 9 + 44, 6 → 9 + 36, 5; the pair of spheres at 10⁴ 47 + 8372, 11 →
106 + 156, 9; but the 2-D pair at 2·10⁴ 48 + 87, 6 → 46 + 117, 7. Not where W is a matrix: there the first point is
no empty face's (FIRST_FORCING), and from the stick point the 3-D tall block at 2·10⁴ DOFs stalled after 5 Newton
steps (the Picard map answered) where it takes 6 from the frictionless start. Where the stick program's solve begins
from newton-cg's coarse program (COARSE_SETS: the 2-D pair), that answer is the step (:meth:`Session.trial`): the fine
step after it took 50 of the stick start's 89 products on the pair at 1.4·10⁶ DOFs, and the Tresca start and Newton's
Coulomb solve after it were no shorter for it. Products stick start + Tresca start + Newton, the Tresca start then to
START_TOL (docs/performance.md, "Coulomb's starts on the pair from the coarse answer"): the pair at 1.4·10⁶ DOFs
89 + 90 + 135 = 314 → 43 + 82 + 66 = 191, 3.2·10⁵ 51 + 49 + 57 = 157 → 40 + 44 + 59 = 143; forced matrix-free at 10⁵
138 → 106, 5·10⁴ 193 → 175, but 2·10⁴ 199 → 235 (Newton's Coulomb solve 112 → 156 products: its path has plateaus
whichever start)."""
TRESCA_SLIP = 0.5
"""Where more than this fraction of the stick start's points lie outside their Coulomb disc (most slip: its point is
far from the answer's), one Tresca solve with the slip bounds F G S λ_N of the stick start's pressure follows it
(:func:`tresca_start`) and Newton's Coulomb solve starts from its answer. Products with W (stick start + Tresca +
Newton), Newton's Coulomb steps, forced matrix-free (docs/performance.md, "Coulomb's start on the pair"): the 2-D pair
at 2·10⁴ DOFs (74 % outside) 45 + 208, 9 → 45 + 30 + 108, 7; at 10⁵ (66 %) 48 + 164, 6 → 47 + 36 + 46, 2. Not on the
clamped and free strips (under 1 % outside): there the Tresca solve cost 21–30 products and saved none. Only where
the balls are intervals (2-D): the 3-D pair of spheres at 10⁴ DOFs (every point outside) took 128 + 160, 9 from the
stick start and 128 + 32 + 16,602, 13 from the Tresca answer."""
TRESCA_TOL = 1e-4
"""Natural residual the Tresca start (TRESCA_SLIP) is solved to: below the first residual of Newton's Coulomb solve
after it, the pressure's change from the stick start's (the 2-D pair, forced matrix-free at 2·10⁴ / 5·10⁴ / 10⁵ DOFs,
`auto` at 3.2·10⁵ / 1.4·10⁶: 7.4e-3, 9.0e-3, 4.0e-3, 1.5e-3, 5.8e-4), the Tresca answer's last digits go unused:
Newton's Coulomb path was the same in each of these rows from an answer to START_TOL, and the Tresca start took one
step fewer in four of them (products 26 → 25, 30 → 25, 32 → 25, 44 → 35, 82 → 75; docs/performance.md, "Coulomb's
starts on the pair from the coarse answer"). It was START_TOL (1e-8) before; 1e-6, measured then on one row (6 products
fewer at 1.4·10⁶), was not taken. The test is newton-cg's own, relative to ‖v‖∞ (LOAD_SCALE), not to the residual it
prints: at 1.4·10⁶ DOFs from the stick start it took a third step from a printed 3.5e-5 to 4.4e-9 (20 products), and
stopped at 3.5e-5 Newton's Coulomb solve took 10 steps and 247 products instead of 6 and 73 (docs/performance.md,
"The Tresca start from the coarse program on its own bounds")."""
TRESCA_COARSE = 10_000
"""Where the Tresca start's program (TRESCA_SLIP) has at least this many unknowns it is solved from no start, so from
the coarse program on its own bounds (newton-cg's COARSE_SETS), not from the stick start it follows: from there its
first steps' faces moved the slip and opening fronts a face at a time, each face a product and a refactorization
(faces 60–1,070 terms apart, past the low-rank update's reach, UPDATE_RANK / UPDATE_SOLVES). The Tresca start's Newton
steps / products with W / refactorizations, from the stick start → from the coarse answer (docs/performance.md, "The
Tresca start from the coarse program on its own bounds"): the 2-D pair at 1.4·10⁶ DOFs (19,632 unknowns) 3 / 72 / 18
→ 1 / 49 / 4, Newton's Coulomb solve after it 6 Newton steps and 73 products from either; not below, where the coarse
program's products outweighed the faces it saved: at 3.5·10⁵ (4,910 unknowns) 2 / 35 / 4 → 1 / 40 / 2, forced
matrix-free at 10⁵ (1,434) 1 / 22 / 3 → 1 / 32 / 1 and at 2·10⁴ (296) 2 / 22 / 1 → 1 / 47 / 1, Newton's Coulomb solve
unchanged. The threshold lies between the rows measured, not at a measured crossing."""
STICK_RADIUS = np.sqrt(np.finfo(float).max)
"""The slip bound of the stick start: one no multiplier reaches (its square still finite)."""


def pressure_map(model: Model):
    """s(λ_N) = F · G S max(λ_N, 0) at the friction points (scaled units), the slip bound of a unit
    pressure (the scale below which changes of s are measured absolutely), and F · G S as a matrix."""
    law: Coulomb = model.law
    fem, friction = model.fem, model.friction
    coefficient = field_at_points(law.friction, "contact.friction", fem, friction)
    smoothing = None
    if law.smoothing_radius > 0:
        smoothing = mollifier(fem.contact.coords, fem.contact.weights, law.smoothing_radius / fem.scaling.length)

    def bound(pressure):
        smoothed = pressure if smoothing is None else smoothing @ pressure
        return coefficient * (friction.interpolation @ np.maximum(smoothed, 0.0))

    linear = sp.diags(coefficient) @ friction.interpolation @ (sp.identity(fem.contact.m) if smoothing is None
                                                                else sp.csr_matrix(smoothing))
    return bound, max(coefficient.max(initial=0.0), 1e-300), sp.csr_matrix(linear)


def initial_pressure(model: Model, solver: str, options: dict) -> np.ndarray:
    """The frictionless (Signorini) pressure, or the law's initial pressure field."""
    law: Coulomb = model.law
    fem = model.fem
    if law.initial_pressure is not None:
        points = fem.contact.coords * fem.scaling.length
        return evaluate_field(law.initial_pressure, "contact.initial_pressure", points) / fem.scaling.pressure
    # frictionless first step: the obstacle is not pulled tangentially yet
    frictionless, recover = model.frictionless(solver, options)
    return recover(frictionless).pressure


def reused_session(model: Model, solver: str, options: dict):
    """One solver session per program structure, shared by the models of a sweep (Model.with_law):
    only q or b differ between their programs, and the last answer warm-starts the next run."""
    program = model.program
    A = sp.csr_matrix(program.A)
    key = ("session", solver, repr(sorted(options.items())), program.q.size, program.cones,
           hashlib.sha1(A.indptr.tobytes() + A.indices.tobytes() + A.data.tobytes()).hexdigest())
    if key not in model.cache:
        model.cache[key] = solvers.session(program, solver, **options)
    return model.cache[key]


def oscillating(changes: list[float], states: list[np.ndarray]) -> bool:
    """Each of the last three steps turns back on the one before (cosine < −½) while the change shrinks by
    less than ½ over two steps: the relaxation overshoots the fixed point."""
    if len(states) < 5:
        return False
    steps = np.diff(np.array(states[-5:]), axis=0)
    steps /= np.maximum(np.linalg.norm(steps, axis=1, keepdims=True), 1e-300)
    return max(a @ b for a, b in itertools.pairwise(steps)) < -0.5 and changes[-1] > 0.5 * changes[-3]


def outcome(changes: list[float], stop: float, states: list[np.ndarray]) -> str | None:
    """converged / oscillating / cycling (period p) / diverging / stagnated, or None to go on.

    Converged: the change is below ``stop``, max(tol, the inner solver's noise). Oscillating
    and cycling are judged while the change is large (above sqrt(stop)): the steps keep
    reversing, or the state returns to itself after p steps without the step shrinking.
    Stagnated: over the last WINDOW steps the change came no closer than 10 % below its earlier
    minimum (a rate slower than 0.987 a step; slow but steady convergence is not stagnation).
    """
    if changes[-1] < stop:
        return "converged"
    if changes[-1] > np.sqrt(stop) and oscillating(changes, states):
        return "oscillating"
    if len(changes) > 2 * WINDOW and min(changes[-WINDOW:]) > 0.9 * min(changes[:-WINDOW]):
        return "stagnated"
    scale = max(np.abs(states[-1]).max(), 1e-300)
    for period in CYCLE_PERIODS:
        if (
            len(changes) > 2 * period
            and changes[-1] > np.sqrt(stop)
            and np.abs(states[-1] - states[-1 - period]).max() < stop * scale
            and changes[-1] > 0.5 * changes[-1 - period]
        ):
            return f"cycling (period {period})"
    recent = changes[-WINDOW:]
    if len(recent) == WINDOW and all(b > a for a, b in itertools.pairwise(recent)) and recent[-1] > 1:
        return "diverging"
    return None


UNFINISHED = "not converged (still decreasing: raise max_iterations)"


def rank(iterate: tuple) -> tuple:
    """Order of iterates (Coulomb residual, iteration, solution, …): certified ones first, among them those the
    inner solver called solved, then usable inner answers (inaccurate by the solver's own measure), then by residual."""
    return not certified(iterate), iterate[2].status != "solved", not iterate[2].solved, iterate[0]


def certified(iterate: tuple) -> bool:
    """A usable inner answer that passes the Coulomb certificate: the certificate judges it, not the inner
    solver's word (Clarabel called the last steps of the Cattaneo–Mindlin example AlmostSolved on one machine
    and Solved on another, while their Coulomb residual was 1e-7 on both)."""
    return iterate[0] <= CERTIFIED and iterate[2].solved


@dataclass
class Attempt:
    """One run of the map: a formulation (``model``), a solver with its options, a relaxation ω."""

    model: Model
    solver: str
    options: dict
    relaxation: float
    outcome: str = "not started"
    iterations: int = 0
    stop: float = 0.0  # the change it stopped at: max(tol, NOISE × inner residual)
    time: float = 0.0
    required: bool = False  # the user's own formulation and solver: errors of its setup are raised
    newton: bool = False  # first try Newton's method on the Coulomb problem itself (coulomb_newton)
    newton_outcome: str | None = None
    best: tuple | None = None  # (Coulomb residual, iteration, solution, fields, bound) of its best iterate
    last: tuple | None = None
    failed: tuple | None = None  # (inner solution, its slip bounds) of a solve that failed, if one did
    inner: InnerStep | None = None  # its inner step: a driver's own (a plastic step), else the program's (iterate)

    @property
    def answer(self) -> tuple | None:
        """The fixed point (last iterate) of a converged run if certified and solved, else the best iterate."""
        last = self.last
        return last if self.outcome == "converged" and certified(last) and last[2].status == "solved" else self.best

    @property
    def solved(self) -> bool:
        return self.outcome == "converged" and certified(self.answer)

    def keep(self, iterate: tuple):
        """Keep the last iterate and the one closest to the Coulomb law (solved inner programs first)."""
        self.last = iterate
        if self.best is None or rank(iterate) <= rank(self.best):
            self.best = iterate

    @property
    def oscillates(self) -> bool:
        return self.outcome.startswith(("oscillating", "cycling", "diverging"))

    def record(self) -> dict:
        return {"formulation": self.model.formulation, "solver": self.solver, "relaxation": self.relaxation,
                "outcome": self.outcome, "iterations": self.iterations, "stop_change": self.stop,
                "best_residual": None if self.best is None else self.best[0], "time": self.time,
                "newton": self.newton_outcome}


def inaccurate(noise: list[float]) -> str | None:
    """The last three inner solves missed their own certificate: no fixed point of theirs can pass it."""
    if len(noise) >= 3 and min(noise[-3:]) > CERTIFIED:
        return f"inner solves inaccurate (residual {min(noise[-3:]):.1e} > {CERTIFIED:g})"
    return None


def residual(model: Model, fields, bound: np.ndarray) -> float:
    """Worst certificate residual of ``fields`` under the slip bound ``bound``."""
    fem = model.fem
    return certify(fem.K, fem.f, fem.contact, model.C, fields, model.friction, bound, model.epsilon,
                   model.compliance).worst


def iterate(attempt: Attempt, s, steps: range, pressure_bound, history: list, timings: dict, progress) -> np.ndarray:
    """Run the map from the slip bounds ``s`` for at most ``steps``; fill ``attempt``, return the last bounds.
    ``s`` may be a function giving them: it is called only if Newton's method does not answer from the start
    (the frictionless solve it makes is then not needed)."""
    model, law = attempt.model, attempt.model.law
    bound, unit_bound, linear = pressure_bound
    session = None

    def opened():  # the map's solver session, made where it is needed (not where Newton answers at once)
        nonlocal session
        if session is None:
            session = reused_session(model, attempt.solver, attempt.options)
            model.seed(session, attempt.solver, attempt.options)
        return session

    step = attempt.inner = attempt.inner or ProgramStep(model, opened)
    try:
        newton = newton_session(model, attempt, opened, linear) if attempt.newton else None
        if newton is None:
            step.open()
    except solvers.ConeNotSupported as error:  # OSQP and a 3-D cone: the user's choice is the user's error
        if attempt.required:
            raise
        attempt.outcome = f"refused ({error})"
        return s
    states, changes, noise = [] if callable(s) else [s], [], []
    mixing = Anderson(law.acceleration)
    attempt.outcome = UNFINISHED
    for k in steps:
        start, solution = time.perf_counter(), None
        if newton is not None:  # once, from its start (the map's first answer is no better: measured)
            solution, newton = coulomb_newton(model, newton, linear), None
            attempt.newton_outcome = (f"{'solved' if solution.solved else solution.solver_status} after "
                                      f"{solution.iterations} Newton steps")
            if solution.solved:  # a fixed point of the map: the next bounds are the ones it reached
                s = solution.info["radii"]
            else:
                solution = None
        by_newton = solution is not None
        if solution is None:
            if callable(s):
                paused = time.perf_counter()
                s = s()
                states.append(s)
                start += time.perf_counter() - paused
            solution = step.solve(s)
        inner = time.perf_counter() - start
        timings["solve"] = timings.get("solve", 0.0) + inner
        if not solution.solved:
            attempt.outcome, attempt.failed = f"failed (inner solve {solution.solver_status})", (solution, s)
            break
        fields = step.recover(solution)
        target = bound(fields.pressure)
        changes.append(float(np.abs(target - s).max() / max(np.abs(target).max(), unit_bound)))
        coulomb_residual, inner_residual = step.residual(model, fields, target), step.residual(model, fields, s)
        noise.append(inner_residual)
        attempt.stop = max(law.tol, NOISE * inner_residual)
        attempt.iterations += 1
        history.append({"iteration": k, "relative_change": changes[-1], "coulomb_residual": coulomb_residual,
                        "inner_residual": inner_residual, "inner_iterations": solution.iterations,
                        "inner_time": inner, "relaxation": attempt.relaxation, "coulomb_newton": by_newton,
                        **({"newton_residuals": solution.info["residuals"]} if by_newton else {})})
        attempt.keep((coulomb_residual, k, solution, fields, target))
        if progress is not None:
            progress(k, changes[-1])
        s = mixing.step(s, target, attempt.relaxation)
        states.append(s)
        found = outcome(changes, attempt.stop, states) or inaccurate(noise)
        if found is not None:
            attempt.outcome = found
            break
    return s


def newton_session(model: Model, attempt: Attempt, opened, linear: sp.spmatrix):
    """A newton-cg session for the Coulomb problem's own Newton solve (:func:`coulomb_newton`): the map's own
    session where it is one (``opened()``), else one on the model's program (whose radius rows Newton's
    coupling replaces) started from its last answer, or where the map's session would start. None where it does
    not apply: the primal, whose slip bounds are no linear map of its unknowns; a program not in bound form;
    friction at Gauss points, where Newton stalled on the singular systems. ``linear``: the slip bounds' map of the
    pressures (:func:`pressure_map`)."""
    if model.formulation != "dual" or model.friction.count > model.fem.contact.m:
        return None  # more friction points than nodes (Gauss points): λ_T is not unique, W singular on it
    if attempt.solver == "newton-cg":
        # the map's own session, from the stick start where W is an operator (STICK_START), else from every point
        # sticking under the frictionless pressure (START_TOL): 8 Newton steps on a 2-D strip of 4001 nodes, 14 from
        # newton-cg's own start
        newton = opened()
        if newton.started:  # a sweep's or a load history's session: from its last answer
            return newton
        if not (solvers.matrix_free(model.program) and stick_start(model, newton, linear)):
            model.seed(newton, "newton-cg", {}, start={"tol": START_TOL})
        return newton
    try:  # kept like the map's session: a load history's or a sweep's next solve starts from this answer
        newton = reused_session(model, "newton-cg", {})
    except ValueError:  # a force-controlled obstacle's equality
        return None
    newton.update(q=model.program.q, b=model.program.b)
    # at first: every point sticking under the frictionless pressure, which newton-cg finds too (auto left it the
    # solver: 3-D punch, 8.5·10⁴ DOFs, 0.2 s against 1.1 s by Clarabel)
    model.seed(newton, "newton-cg", {}, start={})
    return newton


def stick_start(model: Model, newton, linear: sp.spmatrix) -> bool:
    """Seed ``newton`` with the stick start (STICK_START): its program's first Newton points with every ball unbounded,
    each point outside its Coulomb disc (radius F G S λ_N there) put on its edge, then, where most points were outside
    and the balls are intervals (TRESCA_SLIP), the Tresca answer for those discs; whether it did (not where a point is
    not finite). The session's program and preconditioner serve, and are left for Newton's solve."""
    stuck = newton.trial(model.bound_update(np.full(model.friction.count, STICK_RADIUS))["b"], STICK_START)
    if not np.isfinite(stuck.x).all():
        return False
    balls = bound_form_of(model.program).ball_vars
    x, radii = stuck.x.copy(), np.maximum(radius_coupling(model, linear) @ stuck.x, 0.0)
    norms = np.linalg.norm(x[balls], axis=1)
    outside = norms > radii
    x[balls[outside]] *= (radii[outside] / norms[outside])[:, None]
    newton.seed(replace(stuck, x=x))
    if balls.shape[1] == 1 and outside.mean() > TRESCA_SLIP:
        tresca_start(model, newton, radii)
    return True


def tresca_start(model: Model, newton, radii: np.ndarray):
    """Solve, from the session's start (from no start where the program is large, TRESCA_COARSE), its program with the
    slip bounds ``radii`` (F G S λ_N of the start's pressure; TRESCA_SLIP): its answer, if solved, becomes the start
    of Newton's Coulomb solve, whose coupling replaces these bounds."""
    newton.update(b=model.bound_update(radii)["b"])
    newton.solve(TRESCA_TOL, fresh=model.program.n_variables >= TRESCA_COARSE)


def radius_coupling(model: Model, linear: sp.spmatrix) -> sp.csr_matrix:
    """The slip bounds s = F G S λ_N as a linear map of the dual's unknowns (newton-cg's ``coupling``)."""
    return sp.csr_matrix(linear @ normal_multipliers(model.program, model.C, model.fem.contact))


def coulomb_newton(model: Model, newton, linear: sp.spmatrix) -> ConicSolution:
    """The Coulomb problem's answer by Newton's method on the dual whose ball radii move with its unknowns,
    s = F G S λ_N (a quasi-variational inequality), from the session's start. Where it stalls the answer is
    "failed" and the map goes on: Newton's method is only local."""
    return newton.coupled(radius_coupling(model, linear))


class Anderson:
    """Anderson mixing of the map s ↦ Φ(s) (Walker & Ni 2011): the next s combines the last steps so that
    the combined residual Φ(s) − s is least, then takes the relaxed step from there. A residual that grows
    restarts it from the plain step; slip bounds stay ≥ 0 (a negative one is no cone)."""

    def __init__(self, depth: int):
        self.depth, self.points, self.residuals = depth, [], []

    def step(self, s: np.ndarray, target: np.ndarray, relaxation: float) -> np.ndarray:
        residual = target - s
        if self.residuals and np.linalg.norm(residual) > np.linalg.norm(self.residuals[-1]):
            self.points, self.residuals = [], []
        self.points, self.residuals = (self.points + [s])[-self.depth - 1:], (self.residuals + [residual])[-self.depth - 1:]
        plain = s + relaxation * residual
        if self.depth == 0 or len(self.points) < 2:
            return plain
        dS, dR = np.diff(self.points, axis=0).T, np.diff(self.residuals, axis=0).T
        gamma = np.linalg.lstsq(dR, residual, rcond=None)[0]
        return np.maximum(plain - (dS + relaxation * dR) @ gamma, 0.0)


def other_formulation(model: Model, timings: dict) -> Model | None:
    """The model of the same scene in the other formulation, or None where it does not apply (the dual
    needs a nonsingular K and takes no normal compliance)."""
    name = "primal" if model.formulation == "dual" else "dual"
    try:
        return formulate(model.fem, name, timings, model.condensation,
                         f"tried after the {model.formulation} Picard map failed")
    except SceneError:
        return None


def paths(model: Model, solver: str, options: dict, timings: dict):
    """(model, solver, options) to try in turn: the user's, the other formulation with the user's
    solver, then the other solvers at their defaults on each formulation. Only what the user left to
    the driver changes: the formulation if "auto" chose it, the solver if no solver options were given
    (a study that asks for one formulation, solver and tol gets that one)."""
    yield model, solvers.resolve(solver, model.program), options  # the attempt names the solver that ran
    models = [model]
    if model.reason != CHOSEN and (other := other_formulation(model, timings)) is not None:
        models.append(other)
        yield other, solvers.resolve(solver, other.program), options
    for name in ALTERNATIVES if not options else ():  # these need P as a matrix
        yield from ((each, name, {}) for each in models
                    if name != solvers.resolve(solver, each.program) and not solvers.matrix_free(each.program))


class InnerStep(Protocol):
    """The map's inner problem: ``open()`` before the first solve (where it can refuse), ``solve(s)`` its answer for
    the slip bounds s, ``recover(solution)`` the answer's fields, ``residual(model, fields, bound)`` the worst residual
    of the whole certificate under ``bound``, ``result(solution, timings, bound, fields, extra)`` the certified result;
    ``name`` for the record. :class:`ProgramStep` is the model's program's; a driver whose inner problem is no program
    of the model's gives its own (:mod:`.plastic_coulomb`: a plastic Tresca step)."""

    name: str | None

    def open(self) -> None: ...

    def solve(self, s: np.ndarray) -> ConicSolution: ...

    def recover(self, solution: ConicSolution): ...

    def residual(self, model: Model, fields, bound: np.ndarray) -> float: ...

    def result(self, solution: ConicSolution, timings: dict, bound: np.ndarray, fields, extra: dict): ...


class ProgramStep:
    """The model's own program as the map's inner step, solved in the session ``opened()`` makes where it is needed."""

    name = None

    def __init__(self, model: Model, opened: Callable):
        self.model, self.open = model, opened

    def solve(self, s: np.ndarray) -> ConicSolution:
        session = self.open()
        session.update(**self.model.bound_update(s))
        return session.solve()

    def recover(self, solution: ConicSolution):
        return self.model.recover(solution)

    def residual(self, model: Model, fields, bound: np.ndarray) -> float:
        return residual(model, fields, bound)

    def result(self, solution: ConicSolution, timings: dict, bound: np.ndarray, fields, extra: dict):
        return self.model.result(solution, timings, bound, fields=fields, extra=extra)


def coulomb(model: Model, solver: str = "clarabel", progress=None, inner: InnerStep | None = None, **options):
    """Run the Picard map for the model's Coulomb law, adapting ω, solver and formulation as it fails;
    return the result of the first certified fixed point, or of the best iterate of all attempts. ``inner``: the
    inner step of a driver of its own (one path: only ω is adapted)."""
    law: Coulomb = model.law
    timings = dict(model.timings)
    with timed(timings, "initial"):
        pressure_bound = pressure_map(model)

    def s():  # the first slip bounds, made only where Newton's method does not answer from the start
        with timed(timings, "initial"):
            return pressure_bound[0](initial_pressure(model, solver, options))

    history, attempts = [], []
    tries = paths(model, solver, options, timings) if inner is None else iter([(model, inner.name, {})])
    path, relaxation, halvings = next(tries), law.relaxation, 0
    while path is not None and len(history) < law.max_iterations:
        # Newton's method once, in the first attempt, where the user left the solver to the driver (a study that
        # names a solver gets that solver's map)
        newton = law.newton and not attempts and solver in ("auto", "newton-cg") and inner is None
        attempt = Attempt(*path, relaxation, required=not attempts, newton=newton, inner=inner)
        attempts.append(attempt)
        start = time.perf_counter()
        end = iterate(attempt, s, range(len(history) + 1, law.max_iterations + 1), pressure_bound, history, timings,
                      progress)
        attempt.time = time.perf_counter() - start
        if attempt.outcome == "converged" and not attempt.solved:
            attempt.outcome = f"converged, not certified (best residual {attempt.best[0]:.1e})"
        if attempt.solved or attempt.outcome == UNFINISHED:
            break
        s = end if attempt.best is None else attempt.best[4]  # the next attempt starts from the best iterate
        if attempt.oscillates and halvings < HALVINGS:
            relaxation, halvings = relaxation / 2, halvings + 1
        else:  # the map is the same with another inner solver: ω starts again from the law's
            path, relaxation, halvings = next(tries, None), law.relaxation, 0
    return report(attempts, history, timings, law)


def report(attempts: list[Attempt], history: list, timings: dict, law: Coulomb):
    """The result of the solved attempt, or of the best iterate of all, with every attempt recorded."""
    final = attempts[-1]
    tried = [attempt for attempt in attempts if attempt.best is not None]
    failed = [attempt for attempt in attempts if attempt.failed is not None]
    chosen = final if final.solved else min(tried, key=lambda attempt: rank(attempt.best), default=None) or failed[-1]
    if chosen.answer is not None:
        _, iteration, solution, fields, bound = chosen.answer
    else:  # only a failed inner solve: reported, and certified, against the slip bounds it was given
        iteration, fields, (solution, bound) = None, None, chosen.failed
    extra = {"picard": {"outcome": final.outcome, "iterations": len(history), "relaxation": final.relaxation,
                        "tol": law.tol, "stop_change": final.stop, "reported_iteration": iteration,
                        "attempts": [attempt.record() for attempt in attempts]}, "history": history}
    with timed(timings, "postprocess"):
        result = chosen.inner.result(solution, timings, bound, fields=fields, extra=extra)
    if not final.solved and chosen.best is not None:  # else the failed inner solve's own status
        result.status = "not converged"
        result.message = failure_message(attempts, history, law)
    elif final.solved and final.stop > law.tol and not result.message:  # the map could not reach tol: say so
        result.message = (f"the Picard map stopped at a relative change of {final.stop:.1e}, above tol = {law.tol:g}: "
                          f"{NOISE:g} × its inner solves' certificate ({final.stop / NOISE:.1e}) bounds what it can "
                          "reach; the certificate says how far this answer is")
    return result


def failure_message(attempts: list[Attempt], history: list, law: Coulomb) -> str:
    tried = "; ".join(f"{a.model.formulation}/{a.solver} ω={a.relaxation:g}: {a.outcome}" for a in attempts)
    smallest = min((step["relative_change"] for step in history), default=float("nan"))
    return (f"Picard map not converged after {len(history)} iterations in {len(attempts)} attempts ({tried}); "
            f"smallest relative change {smallest:.1e}, tol {law.tol:g}; best iterate reported. A map that "
            "cycles at every relaxation may have several fixed points or none (the map contracts only for "
            "small F); one still decreasing needs a larger max_iterations")


LAW_DRIVERS[Coulomb] = coulomb
