"""Coulomb and nonlocal Coulomb friction: a Picard map over normal pressures.

    s^{k+1} = (1 − ω) s^k + ω F·S(λ_N(s^k)),

λ_N(s) the pressure of the exact Tresca program with slip bound s (Oden's
algorithm III/IV, Hild's map Φ). Only the slip bounds change between steps: the
program, the factorization (dual) and the solver's setup are built once, and each
step updates the data of one solver session (OSQP also warm-starts).

The map converges only for small enough F (Hild); otherwise it may stagnate, cycle
or diverge. That is a reported outcome — with the best iterate, its Coulomb
residuals and the whole history — never an exception and never a silent success.
"""

from __future__ import annotations

import hashlib
import itertools
import time

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..fem.mollifier import mollifier
from ..results.certificate import certify
from ..scene.model import Coulomb, evaluate_field
from .solve import CERTIFIED, Model, field_at_points, timed

CYCLE_PERIODS = (2, 3, 4)
WINDOW = 8
"""Iterations looked back on to call the map cycling, diverging or stagnating."""


def pressure_map(model: Model):
    """s(λ_N) = F · G S λ_N at the friction points (scaled units), and the slip bound of a unit
    pressure (the scale below which changes of s are measured absolutely)."""
    law: Coulomb = model.law
    fem, friction = model.fem, model.friction
    coefficient = field_at_points(law.friction, "contact.friction", fem, friction)
    smoothing = None
    if law.smoothing_radius > 0:
        smoothing = mollifier(fem.contact.coords, fem.contact.weights, law.smoothing_radius / fem.scaling.length)

    def bound(pressure):
        smoothed = pressure if smoothing is None else smoothing @ pressure
        return coefficient * (friction.interpolation @ np.maximum(smoothed, 0.0))

    return bound, max(coefficient.max(initial=0.0), 1e-300)


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


def outcome(changes: list[float], tol: float, states: list[np.ndarray]) -> str | None:
    """converged / cycling (period p) / diverging / stagnated, or None to go on.

    Cycling: the state returns to itself after p steps while the step size stays large
    (above sqrt(tol)) and does not shrink. Smaller steps that stop shrinking are the
    inner solver's noise: the map has stagnated at the solver's accuracy.
    """
    if changes[-1] < tol:
        return "converged"
    if len(changes) > 2 * WINDOW and min(changes[-WINDOW:]) > 0.5 * min(changes[:-WINDOW]):
        return "stagnated"
    scale = max(np.abs(states[-1]).max(), 1e-300)
    for period in CYCLE_PERIODS:
        if (
            len(changes) > 2 * period
            and changes[-1] > np.sqrt(tol)
            and np.abs(states[-1] - states[-1 - period]).max() < tol * scale
            and changes[-1] > 0.5 * changes[-1 - period]
        ):
            return f"cycling (period {period})"
    recent = changes[-WINDOW:]
    if len(recent) == WINDOW and all(b > a for a, b in itertools.pairwise(recent)) and recent[-1] > 1:
        return "diverging"
    return None


def unfinished(changes: list[float]) -> str:
    """The iteration limit was reached while the change still decreased."""
    return "not converged (still decreasing: raise max_iterations)"


def coulomb(model: Model, solver: str = "clarabel", progress=None, **options):
    """Run the Picard map for the model's Coulomb law; return the best iterate's result."""
    law: Coulomb = model.law
    fem = model.fem
    timings = dict(model.timings)
    with timed(timings, "initial"):
        bound, unit_bound = pressure_map(model)
        s = bound(initial_pressure(model, solver, options))
    session = reused_session(model, solver, options)
    model.seed(session, solver, options)
    history, states, changes = [], [s], []
    best = None
    status = None
    for k in range(1, law.max_iterations + 1):
        start = time.perf_counter()
        session.update(**model.bound_update(s))
        solution = session.solve()
        inner = time.perf_counter() - start
        timings["solve"] = timings.get("solve", 0.0) + inner
        if not solution.solved:
            status = f"failed (inner solve {solution.solver_status})"
            break
        fields = model.recover(solution)
        target = bound(fields.pressure)
        change = float(np.abs(target - s).max() / max(np.abs(target).max(), unit_bound))
        residual = certify(fem.K, fem.f, fem.contact, model.C, fields, model.friction, target, model.epsilon,
                           model.compliance)
        history.append({"iteration": k, "relative_change": change, "coulomb_residual": residual.worst,
                        "inner_iterations": solution.iterations, "inner_time": inner})
        if best is None or residual.worst <= best[0]:
            best = (residual.worst, k, solution, fields, target)
        last = (residual.worst, k, solution, fields, target)
        if progress is not None:
            progress(k, change)
        changes.append(change)
        s = (1.0 - law.relaxation) * s + law.relaxation * target
        states.append(s)
        status = outcome(changes, law.tol, states)
        if status is not None:
            break
    else:
        status = unfinished(changes)
    extra = {"picard": {"outcome": status, "iterations": len(history), "relaxation": law.relaxation,
                        "tol": law.tol, "reported_iteration": None}, "history": history}
    if best is None:  # the first inner solve failed: report it, judged against the bounds it was given
        return model.result(solution, timings, s, extra=extra)
    # converged: the last iterate (the fixed point) if it passes the certificate; otherwise, or when an
    # ill-conditioned inner solve left it failing, the iterate closest to the Coulomb law
    chosen = last if status == "converged" and last[0] <= CERTIFIED else best
    _, extra["picard"]["reported_iteration"], solution, fields, target = chosen
    with timed(timings, "postprocess"):
        result = model.result(solution, timings, target, fields=fields, extra=extra)
    if status != "converged":
        result.status = "not converged"
        result.message = (
            f"Picard map {status} after {len(history)} iterations (smallest relative change "
            f"{min(changes, default=float('nan')):.1e}, tol {law.tol:g}); best iterate reported. A change that stalls "
            "near the inner solver's accuracy needs a tighter solver tol or a looser Picard tol; a large one, "
            "a smaller relaxation or a smaller friction coefficient (the map contracts only for small F)"
        )
    return result
