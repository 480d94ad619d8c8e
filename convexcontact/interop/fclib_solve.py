"""Solve an FClib problem exactly: Coulomb's law as a Picard map over Tresca programs on (W, q, μ).

Each Picard step is the convex program, in bound form and in FClib's own ordering
(per contact [N, T1(, T2)]),

    min ½ rᵀ W r + qᵀ r   s.t.  r_N,k ≥ 0,  ‖r_T,k‖ ≤ s_k          (Tresca, slip bounds s given)

whose optimality conditions are u = W r + q, 0 ≤ u_N ⊥ r_N ≥ 0 and r_T,k = −‖r_T,k‖ u_T,k/‖u_T,k‖
where ‖r_T,k‖ = s_k, u_T,k = 0 where ‖r_T,k‖ < s_k. With s = μ r_N this is Coulomb's law in FClib's
(De Saxcé) form, so a fixed point of s ← (1 − ω) s + ω μ r_N(s) solves the FClib problem. The
program goes to our solvers (:func:`convexcontact.solvers.session`, ``update(b=…)`` per step).

Every answer is judged by FClib's merit function (:func:`merit`, ``fclib_merit_local`` MERIT_1)
beside our natural-map residuals (:func:`natural_residuals`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..conic import ConicProgram, nonnegative, soc, zero
from .fclib import GlobalProblem, LocalProblem

CERTIFIED = 1e-8
"""An answer whose FClib merit is at most this is reported as solved."""
TINY = 1e-300
STILL = 1e-14
"""A relative change of the slip bounds below this is a fixed point of the Picard map (round-off)."""
STICK = 1e3
"""Slip bounds, in the scaled program's units (r ~ 1), that hold no friction back: the all-stick start of a
problem whose equalities involve r_T (s = 0 would leave Vᵀ r + s = 0 infeasible)."""
PATIENCE = 8
"""Picard steps without a better merit after which the map has gone as far as the inner solves' accuracy
lets it (Clarabel at tol 1e-12 on the condensed 2-D punch: merits wander between 1e-10 and 1e-8)."""


def per_contact(x: np.ndarray, spacedim: int) -> np.ndarray:
    return np.asarray(x, dtype=float).reshape(-1, spacedim)


def project_on_cone(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Euclidean projection of each row [x_N, x_T] onto C_μ = {‖x_T‖ ≤ μ x_N}."""
    normal, tangent = x[:, 0], x[:, 1:]
    size = np.linalg.norm(tangent, axis=1)
    inside = size <= mu * normal
    polar = mu * size <= -normal  # in the polar cone: projects to 0
    on_axis = (mu * size + normal) / (mu * mu + 1.0)  # the projection's normal component on the boundary
    out = np.zeros_like(x)
    out[inside] = x[inside]
    edge = ~inside & ~polar
    out[edge, 0] = on_axis[edge]
    out[edge, 1:] = (mu * on_axis / np.maximum(size, TINY))[edge, None] * tangent[edge]
    return out


def velocity(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> np.ndarray:
    """u = W r + q (+ V λ for a mixed problem)."""
    u = problem.W @ r + problem.q
    if problem.V is None:
        return u
    if l is None:
        raise ValueError("fclib_local/V: a problem with equalities needs their multipliers l (λ) as well as r")
    return u + problem.V @ l


def equality_residual(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None) -> np.ndarray:
    """Vᵀ r + R λ + s (empty without equalities)."""
    if problem.V is None:
        return np.zeros(0)
    residual = problem.V.T @ r + problem.s
    return residual if problem.R is None else residual + problem.R @ l


def merit(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> float:
    """FClib's merit function MERIT_1 (``fclib_merit_local``), for spacedim 2 and 3.

    ‖r − Π_C_μ(r − û)‖ / (1 + √‖q‖), û = W r + V λ + q + [μ‖u_T‖, 0, 0] per contact, plus, with
    equalities, ‖Vᵀ r + R λ + s‖ / (1 + ‖s‖). The normalization is fclib's as coded,
    ``sqrt(error)/(1.0 + sqrt(dnrm2(q)))``: 1 + the square root of ‖q‖ (not 1 + ‖q‖). fclib itself
    computes it for spacedim 3 only; the formula is the same in 2-D.
    """
    d = problem.spacedim
    u = per_contact(velocity(problem, r, l), d)
    z = per_contact(r, d)
    shifted = u.copy()
    shifted[:, 0] += problem.mu * np.linalg.norm(u[:, 1:], axis=1)
    error = z - project_on_cone(z - shifted, problem.mu)
    value = np.linalg.norm(error) / (1.0 + np.sqrt(np.linalg.norm(problem.q)))
    if problem.V is not None:
        value += np.linalg.norm(equality_residual(problem, r, l)) / (1.0 + np.linalg.norm(problem.s))
    return float(value)


def natural_residuals(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> dict[str, float]:
    """Our certificate of the answer: the largest violation of each condition, by natural maps.

    Forces are measured against p_ref = max(‖r‖∞, ‖q‖∞/max|W|), velocities against u_ref = max(‖u‖∞,
    ‖q‖∞); friction by ‖r_T − Π_B(μ r_N)(r_T − ρ u_T)‖ with ρ = p_ref/u_ref (DESIGN.md, discrete certificate);
    equalities against max(‖s‖∞, ‖Vᵀ r‖∞).
    """
    d, mu = problem.spacedim, problem.mu
    u = per_contact(velocity(problem, r, l), d)
    z = per_contact(r, d)
    scale_W = abs(problem.W).max() if problem.W.nnz else 0.0
    q_max = np.abs(problem.q).max(initial=0.0)
    p_ref = max(np.abs(z).max(initial=0.0), q_max / scale_W if scale_W > 0 else 0.0, TINY)
    u_ref = max(np.abs(u).max(initial=0.0), q_max, TINY)
    bound = mu * np.maximum(z[:, 0], 0.0)
    trial = z[:, 1:] - (p_ref / u_ref) * u[:, 1:]
    shrink = np.minimum(1.0, bound / np.maximum(np.linalg.norm(trial, axis=1), TINY))
    values = {
        "pressure_sign": np.maximum(-z[:, 0], 0.0).max(initial=0.0) / p_ref,
        "non_penetration": np.maximum(-u[:, 0], 0.0).max(initial=0.0) / u_ref,
        "complementarity": np.abs(np.minimum(z[:, 0] / p_ref, u[:, 0] / u_ref)).max(initial=0.0),
        "friction_bound": np.maximum(np.linalg.norm(z[:, 1:], axis=1) - bound, 0.0).max(initial=0.0) / p_ref,
        "friction_law": np.linalg.norm(z[:, 1:] - shrink[:, None] * trial, axis=1).max(initial=0.0) / p_ref,
    }
    if problem.V is not None:
        size = max(np.abs(problem.s).max(initial=0.0), np.abs(problem.V.T @ r).max(initial=0.0), TINY)
        values["equalities"] = np.abs(equality_residual(problem, r, l)).max(initial=0.0) / size
    return {k: float(v) for k, v in values.items()}


def tresca_program(problem: LocalProblem) -> tuple[ConicProgram, np.ndarray, np.ndarray, float]:
    """min ½rᵀWr + qᵀr s.t. [Vᵀ r + s = 0], r_N ≥ 0, (s_k, r_T,k) ∈ SOC, in FClib's order, scaled; the rows
    of b holding the slip bounds (in the program's units: s_k / scale_k), the scale of each unknown
    (r = scale · x) and β (the equalities' multipliers are λ = β² z).

    Scaling: contact k's unknowns by d_k = 1/√(largest diagonal entry of its block of W) (a scalar per
    contact keeps its cone), then all by ‖D q‖∞, so that the solver sees a unit diagonal and a unit q:
    FClib files come in any units (the fclib test file has W ~ 7e2, q ~ 5e-3, r ~ 4e-4).
    """
    d = problem.spacedim
    count = problem.q.size // d
    n = count * d
    diagonal = per_contact(problem.W.diagonal(), d).max(axis=1)
    contact_scale = np.where(diagonal > 0, 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 1.0)
    D = np.repeat(contact_scale, d)
    q = D * problem.q
    beta = np.abs(q).max(initial=0.0) or 1.0
    scale = beta * D
    W = sp.diags(D) @ sp.csr_matrix(0.5 * (problem.W + problem.W.T)) @ sp.diags(D)
    normal_rows = -sp.csr_matrix((np.ones(count), (np.arange(count), np.arange(count) * d)), shape=(count, n))
    tangent = np.arange(n)[np.arange(n) % d != 0]  # unknown k·d + j, j ≥ 1, sits at SOC row count + k·d + j
    cone_rows = -sp.csr_matrix((np.ones(tangent.size), (tangent, tangent)), shape=(n, n))
    equalities = 0 if problem.V is None else problem.V.shape[1]
    if problem.R is not None and problem.R.count_nonzero():
        raise ValueError("fclib_local/R: a nonzero R (λ in its own equations) is not supported; R = 0 is")
    rows = [normal_rows, cone_rows] if not equalities else [sp.csr_matrix(problem.V.T) @ sp.diags(scale),
                                                             normal_rows, cone_rows]
    cones = ((zero(equalities),) if equalities else ()) + (nonnegative(count),) + (soc(d),) * count
    b = np.concatenate([-problem.s if equalities else np.zeros(0), np.zeros(count + n)])
    program = ConicProgram(sp.csc_matrix(W), q / beta, sp.vstack(rows).tocsc(), b, cones)
    return program, equalities + count + np.arange(count) * d, scale, beta


@dataclass
class Answer:
    """An FClib problem's answer: r, u = W r + q (and v for a global problem), how it was judged and reached."""

    r: np.ndarray
    u: np.ndarray
    merit: float
    residuals: dict[str, float]
    status: str  # solved (merit ≤ CERTIFIED), inaccurate, or failed
    outcome: str  # converged, fixed point, stagnated, not converged, solver failed
    iterations: int
    history: list[dict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    v: np.ndarray | None = None
    l: np.ndarray | None = None  # multipliers λ of the equalities (FClib's name)
    extra: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"status": self.status, "outcome": self.outcome, "fclib_merit": self.merit, "residuals": self.residuals,
                "picard_iterations": self.iterations, "timings": self.timings, "history": self.history, **self.extra}


def solve_local(problem: LocalProblem, solver: str = "clarabel", merit_tol: float = 1e-12, max_iterations: int = 100,
                relaxation: float = 1.0, guess: np.ndarray | None = None, **options) -> Answer:
    """Coulomb's law on FC(W, q, μ) by the Picard map over Tresca programs (module docstring).

    Starts from the frictionless answer (s = 0; all-stick when equalities involve r_T), or from the
    slip bounds μ r_N of ``guess``. Stops when an iterate's FClib merit is at most ``merit_tol``
    (converged), when s stops changing (a fixed point: the merit is then what the inner solves reach),
    when the merit has not improved for ``PATIENCE`` steps (stagnated), or after ``max_iterations``;
    returns the iterate of least merit. The change of s alone is no test: where W is singular (rigid
    bodies) r_N is not unique and s may wander among solutions, each with a merit of 1e-13 (the fclib
    test file). ``options`` go to the solver (:func:`solvers.session`).

    Unless ``polishing`` is given, the map runs without Clarabel's polish first (on the fclib test file
    the polish made every step 20× slower and ended less accurate, 5e-9 against 4e-13) and, if that
    stops above ``merit_tol``, again with it from the best answer, keeping the better one (the 2-D punch:
    4e-9 → 5e-14); a polish that raises (on a 3-D punch the cone polish met NaNs once slip bounds were 0
    at open contacts) leaves the first answer, and ``extra["polish"]`` says so.
    """
    if not 0 < relaxation <= 1:
        raise ValueError(f"relaxation: ω must lie in (0, 1], got {relaxation}")
    start = time.perf_counter()
    program, bound_rows, scale, beta = tresca_program(problem)
    mu, d = problem.mu, problem.spacedim
    s = np.zeros(mu.size) if guess is None else mu * np.maximum(per_contact(guess, d)[:, 0], 0.0)
    if guess is None and problem.V is not None and problem.V.tocsr()[np.arange(mu.size * d) % d != 0].count_nonzero():
        s = STICK * scale[::d]  # a tangential equality (a force pulling the obstacle) has no frictionless answer
    settings = (merit_tol, max_iterations, relaxation, beta)
    (value, r, l), history, outcome = picard(problem, program, bound_rows, scale, s, settings,
                                          solvers.session(program, solver, **{"polishing": False, **options}))
    extra = {}
    if "polishing" not in options and value > merit_tol and outcome != "solver failed":
        s = mu * np.maximum(per_contact(r, d)[:, 0], 0.0)
        try:
            session = solvers.session(program, solver, polishing=True, **options)
            polished, more, how = picard(problem, program, bound_rows, scale, s, settings, session)
            extra["polish"] = f"rerun with the polish: {how}, merit {polished[0]:.1e}"
            history += [{**step, "polished": True} for step in more]
            if polished[0] < value:
                (value, r, l), outcome = polished, how
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as error:
            extra["polish"] = f"rerun with the polish failed: {error}"
    if not np.isfinite(value):
        value = merit(problem, r, l)
    status = "failed" if outcome == "solver failed" and len(history) == 1 else \
        "solved" if value <= CERTIFIED else "inaccurate"
    return Answer(r, velocity(problem, r, l), value, natural_residuals(problem, r, l), status, outcome, len(history),
                  history, {"total": time.perf_counter() - start}, l=l, extra=extra)


def picard(problem: LocalProblem, program: ConicProgram, bound_rows, scale, s, settings, session):
    """Run the map from slip bounds ``s``; (least merit, its r and λ), the history and the outcome."""
    merit_tol, max_iterations, relaxation, beta = settings
    mu, d = problem.mu, problem.spacedim
    equalities = 0 if problem.V is None else problem.V.shape[1]
    zero_l = np.zeros(equalities) if equalities else None
    history, outcome, best, last_better = [], "not converged", (np.inf, np.zeros(program.n_variables), zero_l), 0
    for k in range(1, max_iterations + 1):
        b = program.b.copy()
        b[bound_rows] = s / scale[::d]
        session.update(b=b)
        solution = session.solve()
        if not solution.solved:
            history.append({"iteration": k, "solver_status": solution.solver_status})
            return best, history, "solver failed"
        r = scale * solution.x
        l = beta**2 * solution.z[:equalities] if equalities else None
        value = merit(problem, r, l)
        if value < best[0]:
            best, last_better = (value, r, l), k
        target = mu * np.maximum(per_contact(r, d)[:, 0], 0.0)
        change = float(np.abs(target - s).max(initial=0.0) / max(np.abs(target).max(initial=0.0), TINY))
        history.append({"iteration": k, "change": change, "merit": value,
                        "solver_status": solution.solver_status, "solver_iterations": solution.iterations})
        s = (1.0 - relaxation) * s + relaxation * target
        if value <= merit_tol or change <= STILL:
            return best, history, "converged" if value <= merit_tol else "fixed point"
        if k - last_better >= PATIENCE:
            return best, history, "stagnated"
    return best, history, outcome


def condense(problem: GlobalProblem):
    """The local problem of a global one (W = Hᵀ M⁻¹ H, q = Hᵀ M⁻¹ f + w) and M's factorization."""
    from ..fem.factorization import factorize
    from ..scene.model import SceneError

    if problem.G is not None:
        raise ValueError("fclib_global/G: equality constraints Gᵀv + b = 0 are not supported; only M, H, f, w, μ")
    try:
        factorization = factorize(problem.M)
    except SceneError:
        raise ValueError("fclib_global/M: singular (a motion costs no energy); the global problem cannot be "
                         "condensed onto its contacts") from None
    W = factorization.schur(sp.csr_matrix(problem.H.T))
    q = problem.H.T @ factorization.solve(problem.f) + problem.w
    return LocalProblem(sp.csr_matrix(W), q, problem.mu, problem.spacedim, dict(problem.info)), factorization


def solve_global(problem: GlobalProblem, solver: str = "clarabel", **options) -> Answer:
    """The global problem, condensed onto its contacts (:func:`condense`) and solved as a local one;
    v = M⁻¹(H r + f). FClib defines no global merit (``fclib_merit_global`` returns 0, marked unfinished there): the
    answer is judged by the merit of its condensed local problem and the equilibrium residual."""
    start = time.perf_counter()
    local, factorization = condense(problem)
    condensed = time.perf_counter() - start
    answer = solve_local(local, solver, **options)
    answer.v = factorization.solve(problem.H @ answer.r + problem.f)
    answer.u = problem.H.T @ answer.v + problem.w
    answer.timings["condensation"] = condensed
    forces = problem.M @ answer.v
    scale = max(np.abs(forces).max(initial=0.0), np.abs(problem.f).max(initial=0.0), TINY)
    answer.residuals["equilibrium"] = float(np.abs(forces - problem.H @ answer.r - problem.f).max() / scale)
    return answer
