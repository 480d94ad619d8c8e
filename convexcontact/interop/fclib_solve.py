"""Solve an FClib problem as the file states it: Coulomb's law on (W, q, μ), W as read (not symmetrized).

Two methods, one feeding the other, both on the scaled problem (:func:`scaled_problem`):

1. A Picard map over convex Tresca programs. A convex program sees only W's symmetric part S = ½(W + Wᵀ);
   the skew part K = ½(W − Wᵀ) goes to the linear term, evaluated at the previous iterate:

       min ½ rᵀ S r + (q + K r_prev)ᵀ r   s.t.  r_N,k ≥ 0,  ‖r_T,k‖ ≤ s_k,   s ← μ r_N,

   whose optimality conditions at a fixed point (r_prev = r, s = μ r_N) are u = S r + K r + q = W r + q and
   Coulomb's law in FClib's (De Saxcé) form: a fixed point solves the file's problem, whatever W's skew part.
   Each step goes to our solvers (:func:`convexcontact.solvers.session`, ``update(q=…, b=…)``).
2. A semismooth Newton method on Alart–Curnier's equation with the file's W (:mod:`.fclib_newton`), tried
   from the Picard iterates 1, 2, 4, 8, … and from the best one at the end: the map brings the answer near
   (globally, but linearly at best), Newton finishes it (locally, quadratically). On Capsules (286
   contacts, W 1.3e-3 non-symmetric and singular) one Picard step and 11 Newton steps reach 5e-14 in 0.4 s.

Every answer is judged on the matrices as read by fclib's merit and Siconos' error (:mod:`.fclib_error`);
``solved`` only when both are ≤ :data:`CERTIFIED`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import solvers
from ..conic import ConicProgram, nonnegative, soc, zero
from . import fclib_newton
from .fclib import GlobalProblem, LocalProblem
from .fclib_error import (
    equality_residual,
    merit,
    natural_residuals,
    per_contact,
    project_on_cone,
    siconos_error,
    siconos_error_global,
    velocity,
)

__all__ = ["CERTIFIED", "Answer", "condense", "equality_residual", "merit", "natural_residuals", "per_contact",
           "project_on_cone", "siconos_error", "siconos_error_global", "solve_global", "solve_local", "velocity"]

CERTIFIED = 1e-8
"""An answer whose FClib merit and Siconos error are both at most this is reported as solved."""
TINY = 1e-300
STILL = 1e-14
"""A relative change of the Picard map's data below this is a fixed point of the map (round-off)."""
STICK = 1e3
"""Slip bounds, in the scaled program's units (r ~ 1), that hold no friction back: the all-stick start of a
problem whose equalities involve r_T (s = 0 would leave Vᵀ r + s = 0 infeasible)."""
PATIENCE = 8
"""Picard steps without a better measure after which the map has gone as far as the inner solves' accuracy
lets it (Clarabel at tol 1e-12 on the condensed 2-D punch: merits wander between 1e-10 and 1e-8)."""
NEWTON_ITERATIONS = 50
"""Newton steps at most per attempt; a start it can finish takes few (3–6 measured), a bad one stalls sooner."""
POLISHED = ("clarabel", "osqp")
"""Solver paths with a polish of their own, switched off for the Picard steps (Newton finishes the answer)."""
BLOCK = 64
"""Columns of H per solve with M when condensing a global problem."""


@dataclass
class Scaled:
    """A local problem in the units its methods see: r = scale · x, u = β² ũ / scale, λ = β l̃ (l̃ the program's
    multiplier of its equalities, and Newton's unknown).

    Contact k's unknowns are scaled by d_k = 1/√(largest diagonal entry of its block of W) (a scalar per
    contact keeps its cone), then all by β = ‖D q‖∞: the methods see W with a unit diagonal and a unit q.
    FClib files come in any units (the fclib test file has W ~ 7e2, q ~ 5e-3, r ~ 4e-4), and an interior
    point's or Newton's tolerance means nothing in the field's unit-free measures until they are.
    """

    program: ConicProgram  # the Tresca program on W's symmetric part; slip bounds in b[bound_rows]
    bound_rows: np.ndarray
    scale: np.ndarray
    beta: float
    skew: sp.csr_matrix  # W's skew part in the program's units: the map adds skew @ x to the program's q
    equation: fclib_newton.Equation  # Alart–Curnier's equation on W as read, in the same units


def scaled_problem(problem: LocalProblem) -> Scaled:
    """The Tresca program ``min ½xᵀSx + q̃ᵀx s.t. [Ṽᵀx + s̃ = 0], x_N ≥ 0, (s_k, x_T,k) ∈ SOC`` (FClib's order) and
    Alart–Curnier's equation, both scaled (:class:`Scaled`); S = D ½(W + Wᵀ) D, the skew part kept apart."""
    d = problem.spacedim
    count = problem.q.size // d
    n = count * d
    if problem.R is not None and problem.R.count_nonzero():
        raise ValueError("fclib_local/R: a nonzero R (λ in its own equations) is not supported; R = 0 is")
    diagonal = per_contact(problem.W.diagonal(), d).max(axis=1)
    contact_scale = np.where(diagonal > 0, 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 1.0)
    D = np.repeat(contact_scale, d)
    q = D * problem.q
    beta = np.abs(q).max(initial=0.0) or 1.0
    scale = beta * D
    W = sp.csr_matrix(sp.diags(D) @ sp.csr_matrix(problem.W) @ sp.diags(D))
    normal_rows = -sp.csr_matrix((np.ones(count), (np.arange(count), np.arange(count) * d)), shape=(count, n))
    tangent = np.arange(n)[np.arange(n) % d != 0]  # unknown k·d + j, j ≥ 1, sits at SOC row count + k·d + j
    cone_rows = -sp.csr_matrix((np.ones(tangent.size), (tangent, tangent)), shape=(n, n))
    equalities = 0 if problem.V is None else problem.V.shape[1]
    V = None if problem.V is None else sp.csr_matrix(sp.diags(scale / beta) @ problem.V)
    rows = [normal_rows, cone_rows] if not equalities else [sp.csr_matrix(V.T), normal_rows, cone_rows]
    cones = ((zero(equalities),) if equalities else ()) + (nonnegative(count),) + (soc(d),) * count
    s = None if problem.s is None else problem.s / beta
    b = np.concatenate([-s if equalities else np.zeros(0), np.zeros(count + n)])
    program = ConicProgram(sp.csc_matrix(0.5 * (W + W.T)), q / beta, sp.vstack(rows).tocsc(), b, cones)
    fraction, size = fclib_newton.DENSE
    dense = W.nnz > fraction * n * n and n > size
    equation = fclib_newton.Equation(W.toarray() if dense else W, q / beta, problem.mu, d, np.ones(count), V,
                                     None if V is None else sp.csr_matrix((equalities, equalities)), s)
    return Scaled(program, equalities + count + np.arange(count) * d, scale, beta, sp.csr_matrix(0.5 * (W - W.T)),
                  equation)


def measures(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None) -> tuple[float, float]:
    """(fclib's merit, Siconos' error) of an answer; inf for one that is not finite."""
    if not (np.all(np.isfinite(r)) and (l is None or np.all(np.isfinite(l)))):
        return np.inf, np.inf
    return merit(problem, r, l), siconos_error(problem, r, l)


@dataclass
class Answer:
    """An FClib problem's answer: r, u = W r + q (and v for a global problem), how it was judged and reached."""

    r: np.ndarray
    u: np.ndarray
    merit: float
    residuals: dict[str, float]
    status: str  # solved (merit and Siconos' error ≤ CERTIFIED), inaccurate, or failed
    outcome: str  # converged, fixed point, stagnated, not converged, solver failed
    iterations: int
    history: list[dict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    v: np.ndarray | None = None
    l: np.ndarray | None = None  # multipliers λ of the equalities (FClib's name)
    extra: dict = field(default_factory=dict)
    siconos_error: float = np.inf  # fc3d/fc2d_compute_error (local), gfc3d_compute_error (global)

    def summary(self) -> dict:
        return {"status": self.status, "outcome": self.outcome, "fclib_merit": self.merit,
                "siconos_error": self.siconos_error, "residuals": self.residuals, "picard_iterations": self.iterations,
                "timings": self.timings, "history": self.history, **self.extra}


def status_of(merit_value: float, *errors: float) -> str:
    """solved when the merit and every Siconos error are at most CERTIFIED (NaN never is), else inaccurate."""
    return "solved" if all(value <= CERTIFIED for value in (merit_value, *errors)) else "inaccurate"


def solve_local(problem: LocalProblem, solver: str = "clarabel", merit_tol: float = 1e-12, max_iterations: int = 100,
                relaxation: float = 1.0, guess: np.ndarray | None = None, **options) -> Answer:
    """Coulomb's law on FC(W, q, μ), W as read: the Picard map with Newton's finish (module docstring).

    Starts from the frictionless answer of W's symmetric part (s = 0; all-stick when equalities involve r_T),
    or from ``guess``. Stops when an iterate's fclib merit and Siconos error are both at most ``merit_tol``
    (converged), when the map's data stop changing (a fixed point), when the measure has not improved for
    ``PATIENCE`` steps (stagnated), or after ``max_iterations``; returns the iterate of least measure. The
    change of s alone is no test: where W is singular (rigid bodies) r_N is not unique and s may wander among
    solutions. ``options`` go to the solver (:func:`solvers.session`; Clarabel's polish off unless asked).
    """
    check_settings(merit_tol, max_iterations, relaxation, guess, problem.q.size)
    start = time.perf_counter()
    scaled = scaled_problem(problem)
    mu, d = problem.mu, problem.spacedim
    x = np.zeros(scaled.program.n_variables) if guess is None else np.asarray(guess, dtype=float) / scaled.scale
    s = mu * np.maximum(per_contact(scaled.scale * x, d)[:, 0], 0.0)
    if guess is None and problem.V is not None and problem.V.tocsr()[np.arange(mu.size * d) % d != 0].count_nonzero():
        s = STICK * scaled.scale[::d]  # a tangential equality (a force pulling the obstacle) has no frictionless answer
    # the polish off where the adapter has one to switch off (cvxpy's path takes no such setting)
    quiet = {"polishing": False} if solvers.resolve(solver, scaled.program).split(":")[0] in POLISHED else {}
    session = solvers.session(scaled.program, solver, **{**quiet, **options})
    best, history, outcome = picard(problem, scaled, x, s, (merit_tol, max_iterations, relaxation), session)
    (value, r, l), finish = best, None
    if outcome != "converged":  # from the best iterate, or from the start if the solver failed at once
        (value, r, l), finish = newton(problem, scaled, r, l, merit_tol, history, best)
        outcome = "converged" if finish == "converged" else outcome
    merit_value, error = measures(problem, r, l)
    failed = not np.isfinite(value)
    status = "failed" if failed else status_of(merit_value, error)
    residuals = {} if failed else natural_residuals(problem, r, l)
    extra = {} if finish is None else {"newton": f"final Newton from the best iterate: {finish}"}
    return Answer(r, velocity(problem, r, l) if not failed else np.full(r.size, np.nan), merit_value, residuals,
                  status, outcome, sum("iteration" in step for step in history), history,
                  {"total": time.perf_counter() - start}, l=l, extra=extra, siconos_error=error)


def check_settings(merit_tol, max_iterations, relaxation, guess, size: int) -> None:
    """Refuse, before any work, settings that cannot run (each message names the argument and what it takes)."""
    if isinstance(merit_tol, bool) or not isinstance(merit_tol, (int, float)) or not 0 < merit_tol < np.inf:
        raise ValueError(f"merit_tol: must be a positive finite number (e.g. 1e-12), got {merit_tol!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 1:
        raise ValueError(f"max_iterations: must be a whole number ≥ 1 (e.g. 100), got {max_iterations!r}")
    if isinstance(relaxation, bool) or not isinstance(relaxation, (int, float)) or not 0 < relaxation <= 1:
        raise ValueError(f"relaxation: ω must lie in (0, 1] (1: no relaxation), got {relaxation!r}")
    if guess is not None and (np.shape(guess) != (size,) or not np.all(np.isfinite(guess))):
        raise ValueError(f"guess: must be {size} finite contact forces r (FClib's order), got shape {np.shape(guess)}")


def picard(problem: LocalProblem, scaled: Scaled, x, s, settings, session):
    """Run the map from (x, s), trying Newton from steps 1, 2, 4, …; (least measure, its r and λ), the
    history and the outcome."""
    merit_tol, max_iterations, relaxation = settings
    mu, d, scale, beta = problem.mu, problem.spacedim, scaled.scale, scaled.beta
    equalities = 0 if problem.V is None else problem.V.shape[1]
    history, best, last_better = [], (np.inf, scale * x, np.zeros(equalities) if equalities else None), 0
    for k in range(1, max_iterations + 1):
        b = scaled.program.b.copy()
        b[scaled.bound_rows] = s / scale[::d]
        session.update(q=scaled.program.q + scaled.skew @ x, b=b)
        solution = session.solve()
        if not solution.solved:
            history.append({"iteration": k, "solver_status": solution.solver_status})
            return best, history, "solver failed"
        r = scale * solution.x
        l = beta * solution.z[:equalities] if equalities else None  # ũ = W̃x + Ṽ z + q̃: z is l̃ = λ/β
        value = max(measures(problem, r, l))
        if value < best[0]:
            best, last_better = (value, r, l), k
        target = mu * np.maximum(per_contact(r, d)[:, 0], 0.0)
        change = max(relative_change(target, s), relative_change(scaled.skew @ solution.x, scaled.skew @ x))
        history.append({"iteration": k, "change": change, "measure": value,
                        "solver_status": solution.solver_status, "solver_iterations": solution.iterations})
        if value > merit_tol and k & (k - 1) == 0:  # a power of two
            best, finish = newton(problem, scaled, r, l, merit_tol, history, best)
            if finish == "converged":
                return best, history, "converged"
        s = (1.0 - relaxation) * s + relaxation * target
        x = (1.0 - relaxation) * x + relaxation * solution.x
        if value <= merit_tol or change <= STILL:
            return best, history, "converged" if value <= merit_tol else "fixed point"
        if k - last_better >= PATIENCE:
            return best, history, "stagnated"
    return best, history, "not converged"


def relative_change(new: np.ndarray, old: np.ndarray) -> float:
    return float(np.abs(new - old).max(initial=0.0) / max(np.abs(new).max(initial=0.0), TINY))


def newton(problem: LocalProblem, scaled: Scaled, r, l, merit_tol: float, history: list, best=(np.inf, None, None)):
    """Newton's method on the file's W from (r, λ); the better of its answer and ``best`` (measure, r, λ), and
    its outcome."""
    scale, beta = scaled.scale, scaled.beta

    def done(x, l_scaled):
        found = max(measures(problem, scale * x, beta * l_scaled if l is not None else None))
        return found <= merit_tol, found

    l_scaled = np.zeros(0) if l is None else l / beta
    (found, x, l_scaled), steps, outcome = fclib_newton.solve(scaled.equation, r / scale, l_scaled, done,
                                                             NEWTON_ITERATIONS)
    history.extend(steps)
    if found < best[0]:
        return (found, scale * x, beta * l_scaled if l is not None else None), outcome
    return best, outcome


def condense(problem: GlobalProblem):
    """The local problem of a global one (W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w) and M⁻¹ (a function), M as read.

    A symmetric M (exactly, as stored) goes to our SPD factorization (PARDISO or SuperLU); any other to
    SuperLU's general LU: a non-symmetric M stays non-symmetric, and so does W (never symmetrized)."""
    if problem.G is not None:
        raise ValueError("fclib_global/G: equality constraints Gᵀv + b = 0 are not supported; only M, H, f, w, μ")
    solve = inverse(problem.M)
    H = sp.csc_matrix(problem.H)
    W = np.empty((H.shape[1], H.shape[1]))
    for start in range(0, H.shape[1], BLOCK):
        W[:, start:start + BLOCK] = H.T @ solve(H[:, start:start + BLOCK].toarray())
    q = H.T @ solve(problem.f) + problem.w
    return LocalProblem(sp.csr_matrix(W), q, problem.mu, problem.spacedim, dict(problem.info)), solve


def inverse(M: sp.spmatrix):
    """b ↦ M⁻¹ b from one factorization of M as read; ValueError naming fclib_global/M if M is singular."""
    from ..fem.factorization import factorize
    from ..scene.description import SceneError

    singular = ValueError("fclib_global/M: singular (a motion costs no energy); the global problem cannot be "
                          "condensed onto its contacts")
    if (abs(M - M.T) > 0).nnz == 0:
        try:
            return factorize(M).solve
        except SceneError:
            pass  # symmetric but not positive definite: the general LU decides
    try:
        lu = spla.splu(sp.csc_matrix(M))
    except RuntimeError:  # "Factor is exactly singular"
        raise singular from None
    probe = lu.solve(np.ones(M.shape[0]))
    if not np.all(np.isfinite(probe)):
        raise singular
    return lu.solve


def solve_global(problem: GlobalProblem, solver: str = "clarabel", **options) -> Answer:
    """The global problem, condensed onto its contacts (:func:`condense`) and solved as a local one;
    v = M⁻¹(H r + f). FClib defines no global merit (``fclib_merit_global`` returns 0, marked unfinished there):
    the answer is judged by the merit of its condensed local problem and Siconos' ``gfc3d_compute_error`` on M,
    H, f, w as read, whose first term is the relative equilibrium residual; solved only when all are small."""
    start = time.perf_counter()
    local, solve = condense(problem)
    condensed = time.perf_counter() - start
    answer = solve_local(local, solver, **options)
    answer.v = solve(problem.H @ answer.r + problem.f)
    answer.u = problem.H.T @ answer.v + problem.w
    answer.timings["condensation"] = condensed
    answer.timings["total"] = time.perf_counter() - start  # the whole solve, condensation included
    forces, reactions = problem.M @ answer.v, problem.H @ answer.r
    scale = max(np.linalg.norm(forces), np.linalg.norm(reactions), np.linalg.norm(problem.f), TINY)
    answer.residuals["equilibrium"] = float(np.linalg.norm(forces - reactions - problem.f) / scale)
    answer.extra["siconos_error_local"] = answer.siconos_error
    answer.siconos_error = siconos_error_global(problem, answer.r, answer.v)
    if answer.status != "failed":
        answer.status = status_of(answer.merit, answer.extra["siconos_error_local"], answer.siconos_error)
    return answer
