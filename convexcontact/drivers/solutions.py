"""Every solution of a discrete Coulomb problem, or as many as a search finds (Hild, seed 001, Prop. 4.1).

Above a critical friction the discrete Coulomb problem may have two, three or infinitely many
solutions, and which one a Picard or Newton iteration returns depends on where it starts. On the
condensed contact unknowns r = (λ_N, λ_T) — y = h − W r holding the weighted gaps (y_N ≤ 0) and
minus the weighted slips (y_T = −v) — the local 2-D law is piecewise linear: each contact node is

- open:   λ_N = λ_T = 0,        with y_N ≤ 0;
- stick:  y_N = 0, y_T = 0,     with λ_N ≥ 0, |λ_T| ≤ F λ_N;
- slip+:  y_N = 0, λ_T = −F λ_N, with λ_N ≥ 0, v ≥ 0  (slip towards increasing coordinate);
- slip−:  y_N = 0, λ_T = F λ_N,  with λ_N ≥ 0, v ≤ 0.

A choice of state per node is a square linear system; its solution is a solution of the problem
when its inequalities hold. Enumerating the 4^m choices (vectorized, one batched solve per
chunk) is exhaustive: every solution is found, and a choice whose system is singular yet
consistent is a continuum, reported with its dimension and its end points. Beyond
``EXHAUSTIVE_LIMIT`` nodes the Picard map is started from diverse pressures instead; what it finds
is reported as found, not as complete. The dense W and the search grow fast with the contact nodes m
(8·(2m)² bytes a copy; a Picard run as m³): both are estimated from m before W is formed, and refused
beyond the memory available, or beyond an hour unless ``confirm=True``; ``progress`` hears of every run.

Each solution carries its certificate and the slope of the Picard map at it (the spectral
radius of the map's Jacobian, by finite differences of exact Tresca solves): below 1 the map
attracts, above 1 no Picard iteration converges to it.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.optimize as opt

from .. import solvers
from ..conic import ConicSolution
from ..fem.assembly import FEModel, assemble
from ..results.result import ContactResult
from ..scene.description import Coulomb, Scene, SceneError, of_type
from ..scene.meshing import available_memory
from .estimates import LONG_RUN, duration
from .prepared import Model, check_formulation_name, field_at_points, formulate, timed

EXHAUSTIVE_LIMIT = 10
"""Most contact nodes enumerated exhaustively: 4^10 ≈ 10⁶ linear systems of order 20 (seconds)."""
STATES = ("open", "stick", "slip+", "slip-")
CHUNK = 1 << 15


@dataclass
class Solution:
    """One solution: its result (certified), the state of each contact node, the dimension of the set
    of solutions through it (0: isolated) and the Picard map's slope there."""

    result: ContactResult
    states: tuple[str, ...]
    continuum: int = 0
    picard_slope: float = float("nan")

    def summary(self) -> dict:
        return {"states": list(self.states), "continuum": self.continuum, "picard_slope": self.picard_slope,
                "attracts": bool(self.picard_slope < 1), "status": self.result.status,
                "certificate": self.result.certificate.worst if self.result.certificate else None,
                "normal_force": self.result.normal_force, "tangential_force": self.result.tangential_force}


@dataclass
class SolutionSet:
    """The solutions found, and whether they are all of them."""

    solutions: list[Solution]
    complete: bool
    method: str
    examined: int
    timings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.solutions)

    @property
    def statement(self) -> str:
        ends = [s for s in self.solutions if s.continuum]
        isolated = len(self) - len(ends)
        what = f"{isolated} isolated"
        if ends:
            dim = max(s.continuum for s in ends)
            what = (f"infinitely many: {isolated} isolated and a continuum of dimension {dim} "
                    f"({len(ends)} of its end points reported)")
        if self.complete:
            return f"all solutions, {what}; {self.method}, {self.examined} states examined"
        return f"found {what}, not proven complete; {self.method}, {self.examined} starts"

    @property
    def status(self) -> str:
        """solved when the list is complete and every solution certified; else what is missing."""
        if not all(s.result.status == "solved" for s in self.solutions):
            return "inaccurate"
        return "solved" if self.complete else "not complete"

    def save(self, directory) -> list:
        """summary.json, and each solution's outputs in solution_K/."""
        from ..results.history_out import output_folder
        from ..results.output import begin

        directory, paths = begin(self, output_folder(directory))
        for k, solution in enumerate(self.solutions, start=1):
            paths += solution.result.save(directory / f"solution_{k}")
        return paths

    def summary(self) -> dict:
        return {"statement": self.statement, "status": self.status, "complete": self.complete, "method": self.method,
                "examined": self.examined, "timings": self.timings,
                "solutions": [s.summary() for s in self.solutions]}


def all_solutions(scene: Scene, solver: str = "clarabel", formulation: str = "auto", confirm: bool = False,
                  progress=None, **options) -> SolutionSet:
    """Every solution of the Coulomb ``scene`` (exhaustive up to ``EXHAUSTIVE_LIMIT`` nodes), else a search.

    ``formulation``: the condensed dual is enumerated ("auto" or "dual"). ``progress(done, count, what)`` is called
    after each Picard run of a search and each Picard slope. ``confirm=True`` runs a search estimated beyond
    :data:`LONG_RUN` seconds.
    """
    law = of_type(scene, Scene, "scene", "build cc.Scene(...) with a cc.Coulomb law").contact.law
    if not isinstance(law, Coulomb):
        raise SceneError("contact.law", "several solutions are a Coulomb question: Signorini and Tresca problems "
                         "are convex, their answer is unique", "use a Coulomb law")
    check_formulation_name(formulation, ("auto", "dual"), " for solutions='all', which lists the states of the "
                      "condensed contact unknowns")
    of_type(confirm, bool, "confirm", "give confirm=True to run a search estimated to take long, else leave it out")
    solvers.check_options({**options, "progress": progress}, solvers.check_name(solver))
    timings: dict = {}
    with timed(timings, "assembly"):
        fem = assemble(scene)
    supported(fem, law)
    check_size(fem.contact.m, confirm)  # before W is formed
    model = formulate(fem, "dual", timings)
    if model.friction.count != fem.contact.m:
        raise SceneError("contact.law", "not supported when listing every solution", "give every contact Coulomb's "
                         "law (friction = 0 where frictionless): each node's unknowns are paired")
    start = time.perf_counter()
    carries = np.flatnonzero(np.diag(model.program.P.toarray())[: model.fem.contact.m] > 0)
    if carries.size <= EXHAUSTIVE_LIMIT:
        found, examined = enumerate_pieces(model, carries)
        method, complete = f"exhaustive enumeration of the 4^{carries.size} contact states", True
    else:
        found, examined = search(model, solver, options, Progress(progress, confirm))
        method, complete = "Picard map from diverse starting pressures", False
    timings["search"] = time.perf_counter() - start
    solutions = [certified(model, r, states, continuum) for r, states, continuum in found]
    for k, solution in enumerate(solutions, start=1):
        solution.picard_slope = picard_slope(model, solution.result, solver, options)
        if progress is not None:
            progress(k, len(solutions), "Picard slope")
    timings["total"] = time.perf_counter() - start
    return SolutionSet(solutions, complete, method, examined, timings)


def supported(fem: FEModel, law: Coulomb) -> None:
    """The exhaustive law is the local 2-D nodal one with the obstacle's position given."""
    contact = fem.contact
    checks = [
        (fem.dim == 2, "contact", "the enumeration covers 2-D contact (the 3-D cone is not polyhedral)"),
        (law.quadrature == "nodal", "contact.quadrature", "use quadrature = 'nodal'"),
        (law.smoothing_radius == 0, "contact.smoothing_radius", "the nonlocal law is not enumerated: use 0"),
        (law.regularization is None, "contact.regularization", "the regularized law is smooth: drop it"),
        (law.compliance is None, "contact.compliance", "use non-penetration (Signorini) as the normal law"),
        (contact.obstacle_coupling is None and contact.tangential_coupling is None, "obstacle",
         "give the obstacle's depth, not a force"),
    ]
    for ok, name, fix in checks:
        if not ok:
            raise SceneError(name, "not supported when listing every solution", fix)


DENSE_COPIES = 3
"""Dense (2m)² matrices a search holds at once: the Schur complement of K on the contact columns, W, and the copy
whose diagonal says which nodes carry a force. One W of 20,001 nodes is 11.9 GiB."""
SEARCH_RUNS = 17
"""Picard runs of a search (:func:`search`): from the frictionless start, then 8 starts × 2 relaxations."""
PICARD_RUN = (30.0, 200)
"""(seconds, contact nodes): one Picard run measured on a 2-D block (Clarabel, 6 iterations; 0.55 s at 51 nodes,
2.2 s at 101), growing as m³ (the dense solves) — an estimate, refined by the first run's time."""


def check_size(m: int, confirm: bool) -> None:
    """Refuse, from the contact nodes alone, a search whose dense W would not fit in memory, or that would take
    more than :data:`LONG_RUN` unless ``confirm``."""
    need, have = DENSE_COPIES * 8.0 * (2 * m) ** 2, available_memory()
    if need > have:
        fit = int((have / (DENSE_COPIES * 32.0)) ** 0.5)
        raise SceneError("solutions", f"{m} contact nodes make a dense W of {2 * m} unknowns: about "
                         f"{need / 2**30:.3g} GiB with its copies, and this machine has {have / 2**30:.3g} GiB available",
                         f"give fewer contact nodes (about {fit} fit: a coarser mesh or a shorter contact boundary), or "
                         "solve it once with solutions='one'")
    if m <= EXHAUSTIVE_LIMIT:
        return
    seconds = SEARCH_RUNS * PICARD_RUN[0] * (m / PICARD_RUN[1]) ** 3
    if seconds > LONG_RUN and not confirm:
        raise SceneError("solutions", f"a search for every solution over {m} contact nodes would take about "
                         f"{duration(seconds)} ({SEARCH_RUNS} Picard runs of about {duration(seconds / SEARCH_RUNS)} "
                         f"each, estimated from the size)", "give fewer contact nodes (a coarser mesh), or "
                         "confirm=True (convexcontact run --solutions all --confirm) to run it")


class Progress:
    """Reports each Picard run of a search and, after the first, refuses the rest estimated from it beyond
    :data:`LONG_RUN` unless confirmed."""

    def __init__(self, report, confirm: bool):
        self.report, self.confirm, self.start = report, confirm, time.perf_counter()

    def __call__(self, done: int, count: int, result: ContactResult):
        if self.report is not None:
            self.report(done, count, f"Picard run: {result.status}")
        seconds = (count - done) * (time.perf_counter() - self.start)
        if done == 1 and seconds > LONG_RUN and not self.confirm:
            raise SceneError("solutions", f"the other {count - done} Picard runs of the search would take about "
                             f"{duration(seconds)} (measured on the first)", "give fewer contact nodes (a coarser "
                             "mesh), or confirm=True (convexcontact run --solutions all --confirm) to run it")


def coefficients(model: Model) -> np.ndarray:
    return field_at_points(model.law.friction, "contact.friction", model.fem, model.friction)


def enumerate_pieces(model: Model, carries: np.ndarray):
    """Solve the linear system of every choice of states; keep those whose inequalities hold."""
    m = model.fem.contact.m
    rows = np.concatenate([carries, m + carries])  # the unknowns of nodes that carry a force
    W = model.program.P.toarray()[np.ix_(rows, rows)]
    h = -model.program.q[rows]
    F = coefficients(model)[carries]
    k = carries.size
    scale_r = max(np.abs(np.linalg.lstsq(W, h, rcond=None)[0]).max(initial=0.0), 1e-300)
    scale_y = max(np.abs(h).max(initial=0.0), 1e-300)
    found = []
    patterns = np.array(list(itertools.product(range(4), repeat=k)), dtype=int).reshape(-1, k)
    for chunk in range(0, len(patterns), CHUNK):
        block = patterns[chunk: chunk + CHUNK]
        A, b = systems(block, W, h, F)
        singular = np.linalg.svd(A, compute_uv=False)
        regular = singular[:, -1] > 1e-11 * singular[:, 0]
        r = np.zeros((len(block), 2 * k))
        if regular.any():
            r[regular] = np.linalg.solve(A[regular], b[regular][:, :, None])[:, :, 0]
        for index in np.flatnonzero(regular):
            if admissible(block[index], r[index], W, h, F, scale_r, scale_y):
                found.append((r[index], block[index], 0))
        for index in np.flatnonzero(~regular):
            found += continuum(block[index], A[index], b[index], W, h, F, scale_r, scale_y)
    distinct = []  # a solution met by several choices (a grazing node) once, on a continuum if any says so
    for r, pattern, dim in found:
        same = [j for j, (kept, _, _) in enumerate(distinct) if np.abs(r - kept).max() <= 1e-7 * scale_r]
        if same:
            kept, kept_pattern, kept_dim = distinct[same[0]]
            distinct[same[0]] = (kept, kept_pattern, max(kept_dim, dim))
        else:
            distinct.append((r, pattern, dim))
    expanded = []
    for r, pattern, dim in distinct:
        full = np.zeros(model.program.n_variables)
        full[rows] = r
        states = ["open"] * m
        for node, state in zip(carries, pattern):
            states[node] = STATES[state]
        expanded.append((full, tuple(states), dim))
    return expanded, len(patterns)


def systems(patterns: np.ndarray, W: np.ndarray, h: np.ndarray, F: np.ndarray):
    """The square systems A r = b of a block of state choices (see the module docstring)."""
    count, k = patterns.shape
    A = np.zeros((count, 2 * k, 2 * k))
    b = np.zeros((count, 2 * k))
    identity = np.eye(2 * k)
    for i in range(k):
        state = patterns[:, i]
        closed = state > 0
        A[:, i] = np.where(closed[:, None], W[i], identity[i])  # y_N = 0, or λ_N = 0 when open
        b[:, i] = np.where(closed, h[i], 0.0)
        choices = np.stack([identity[k + i], W[k + i], identity[k + i] + F[i] * identity[i],
                            identity[k + i] - F[i] * identity[i]])  # per state: open, stick, slip+, slip−
        tangential = choices[state]
        A[:, k + i] = tangential  # y_T = 0 (stick), λ_T = ∓F λ_N (slip±), λ_T = 0 (open)
        b[:, k + i] = np.where(state == 1, h[k + i], 0.0)
    return A, b


def inequalities(pattern, W, h, F):
    """G r ≤ g: the signs a choice of states requires (the module docstring's 'with' clauses)."""
    k = len(pattern)
    G, g = [], []
    for i, state in enumerate(pattern):
        e_N, e_T = np.eye(2 * k)[i], np.eye(2 * k)[k + i]
        if state == 0:
            G.append(-W[i]), g.append(-h[i])  # y_N = h − W r ≤ 0
            continue
        G.append(-e_N), g.append(0.0)  # λ_N ≥ 0
        if state == 1:
            G += [e_T - F[i] * e_N, -e_T - F[i] * e_N]
            g += [0.0, 0.0]
        else:  # v = −y_T = W r − h: ≥ 0 for slip+, ≤ 0 for slip−
            sign = 1.0 if state == 2 else -1.0
            G.append(-sign * W[k + i]), g.append(-sign * h[k + i])
    return np.array(G), np.array(g)


def admissible(pattern, r, W, h, F, scale_r, scale_y) -> bool:
    G, g = inequalities(pattern, W, h, F)
    slack = G @ r - g
    scale = np.where(np.abs(G).sum(axis=1) > 0, scale_r, scale_y)
    return bool((slack <= 1e-9 * np.maximum(scale, scale_y)).all())


def continuum(pattern, A, b, W, h, F, scale_r, scale_y):
    """A singular choice: if its system is consistent, the admissible part of its affine solution set,
    as its two end points along the first null direction (marked with the set's dimension)."""
    r0, *_ = np.linalg.lstsq(A, b, rcond=None)
    if np.abs(A @ r0 - b).max(initial=0.0) > 1e-9 * max(np.abs(b).max(initial=0.0), scale_y):
        return []
    _, singular, vt = np.linalg.svd(A)
    null = vt[singular <= 1e-11 * singular[0]].T
    G, g = inequalities(pattern, W, h, F)
    tolerance = 1e-9 * max(scale_r, scale_y)
    ends = []
    for direction in (1.0, -1.0):
        objective = np.zeros(null.shape[1])
        objective[0] = -direction
        lp = opt.linprog(objective, A_ub=G @ null, b_ub=g - G @ r0 + tolerance, bounds=[(None, None)] * null.shape[1],
                         method="highs")
        if lp.status == 0:
            ends.append(r0 + null @ lp.x)
        elif lp.status == 3:  # unbounded along the null space: every multiple is a solution
            raise SceneError("contact", "an unbounded set of solutions (a rigid motion that friction cannot fix)",
                             "hold the body with more Dirichlet conditions")
    if not ends:
        return []
    dim = null.shape[1] if np.abs(ends[0] - ends[-1]).max() > 1e-8 * scale_r else 0
    return [(end, pattern, dim) for end in ends]


def certified(model: Model, x: np.ndarray, states: tuple[str, ...], dim: int) -> Solution:
    """The result of one solution, certified against the Coulomb law with s = F λ_N of itself."""
    solution = ConicSolution(x=x, z=np.zeros(model.program.n_constraints), s=np.zeros(model.program.n_constraints),
                             status="solved", solver_status="enumerated", iterations=0, solve_time=0.0,
                             solver="enumeration")
    fields = model.recover(solution)
    bound = coefficients(model) * (model.friction.interpolation @ np.maximum(fields.pressure, 0.0))
    result = model.result(solution, {}, bound, fields=fields)
    return Solution(result, states, dim)


def picard_slope(model: Model, result: ContactResult, solver: str, options: dict) -> float:
    """Spectral radius of the Jacobian of s ↦ F λ_N(Tresca(s)) at the solution, by central differences."""
    if not result.solved:
        return float("nan")
    fem = result.fem
    F = coefficients(model)
    pressure = result.contact.pressure / fem.scaling.pressure
    s = F * pressure
    step = 1e-6 * max(np.abs(s).max(initial=0.0), F.max(initial=0.0) * 1e-3, 1e-12)
    session = solvers.session(model.program, solver, **options)
    columns = []
    for j in range(s.size):
        pressures = []
        for sign in (1.0, -1.0):
            trial = s.copy()
            trial[j] = max(trial[j] + sign * step, 0.0)
            session.update(**model.bound_update(trial))
            answer = session.solve()
            if not answer.solved:
                return float("nan")
            pressures.append(model.recover(answer).pressure)
        columns.append(F * (pressures[0] - pressures[1]) / (2 * step))
    jacobian = np.column_stack(columns)
    return float(np.abs(np.linalg.eigvals(jacobian)).max(initial=0.0))


def search(model: Model, solver: str, options: dict, progress: Progress):
    """Picard from the frictionless pressure and from scaled and random pressures, with two relaxations:
    the distinct certified answers, and how many runs there were (one assembly and condensation for all)."""
    law: Coulomb = model.law
    first = model.solve(solver, **options)
    progress(1, SEARCH_RUNS, first)
    if not first.solved:
        return [], 1
    pressure = first.contact.pressure
    rng = np.random.default_rng(0)
    starts = [pressure * factor for factor in (0.0, 0.5, 2.0, 5.0)] + [pressure.max() * rng.random(pressure.size)
                                                                          for _ in range(4)]
    results = [first]
    for start, relaxation in itertools.product(starts, (1.0, 0.5)):
        trial = replace(law, initial_pressure=np.asarray(start), relaxation=relaxation)
        results.append(model.with_law(trial).solve(solver, **options))
        progress(len(results), SEARCH_RUNS, results[-1])
    found = []
    for result in results:
        if result.status != "solved":
            continue
        r = np.concatenate([result.contact.pressure, result.contact.friction]) / result.fem.scaling.pressure
        if not any(np.abs(r - kept).max() <= 1e-7 * max(np.abs(r).max(), 1e-300) for kept, _, _ in found):
            found.append((r, tuple(result.contact.status.tolist()), 0))
    return found, len(results)
