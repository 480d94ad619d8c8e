"""cvxpy: the ConicProgram as a transparent ``cvxpy.Problem`` a user can read and extend.

Build the model with :func:`model`, add constraints or change the objective with
:meth:`CvxpyModel.extended`, then :func:`solve` it with any solver cvxpy reaches.
The duals of the original cone constraints are mapped back to Clarabel's z, so
the mechanics recovered from the solution does not depend on the solver used.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution
from .polish import polish, polishable

_STATUS = {
    cp.OPTIMAL: "solved",
    cp.OPTIMAL_INACCURATE: "inaccurate",
    cp.INFEASIBLE: "infeasible",
    cp.INFEASIBLE_INACCURATE: "infeasible",
    cp.UNBOUNDED: "unbounded",
    cp.UNBOUNDED_INACCURATE: "unbounded",
}


@dataclass(frozen=True)
class CvxpyModel:
    """A cvxpy Problem over the variable ``x`` of a ConicProgram.

    ``cone_constraints`` pair each constraint of the program's cones with the rows
    it covers (consecutive second-order cones of one dimension share a single
    vectorized ``cp.SOC``); ``problem`` may hold more constraints (added by the user).
    """

    problem: cp.Problem
    x: cp.Variable
    cone_constraints: tuple

    def extended(self, constraints=(), objective=None) -> CvxpyModel:
        """A new model with extra constraints and/or another objective."""
        problem = cp.Problem(
            objective if objective is not None else self.problem.objective,
            list(self.problem.constraints) + list(constraints),
        )
        return CvxpyModel(problem, self.x, self.cone_constraints)


def _runs(program: ConicProgram):
    """(kind, dim, rows) for each cone block, consecutive equal SOCs merged (rows interleaved).

    For a power cone the second entry is its exponent α instead of the dimension.
    """
    runs = []
    for cone, rows in program.blocks():
        if cone.kind == "power":
            runs.append(("power", cone.alpha, rows))
            continue
        last = runs[-1] if runs else None
        if cone.kind == "soc" and last and last[0] == "soc" and last[1] == cone.dim and last[2].stop == rows.start:
            runs[-1] = ("soc", cone.dim, slice(last[2].start, rows.stop))
        else:
            runs.append((cone.kind, cone.dim, rows))
    return runs


def model(program: ConicProgram) -> CvxpyModel:
    """The cvxpy Problem of ``program`` (P is wrapped in psd_wrap: no dense PSD check)."""
    x = cp.Variable(program.n_variables, name="x")
    objective = 0.5 * cp.quad_form(x, cp.psd_wrap(program.P)) + program.q @ x
    A, b = sp.csr_matrix(program.A), program.b
    constraints = []
    for kind, dim, rows in _runs(program):
        if kind == "power":
            slack = b[rows] - A[rows] @ x
            constraints.append((cp.PowCone3D(slack[0], slack[1], slack[2], dim), kind, rows))
            continue
        if kind != "soc":
            slack = b[rows] - A[rows] @ x
            constraints.append(((slack == 0) if kind == "zero" else (slack >= 0), kind, rows))
            continue
        index = np.arange(rows.start, rows.stop).reshape(-1, dim).T  # (dim, cones): row of component j of cone i
        t = b[index[0]] - A[index[0]] @ x
        rest = index[1:].ravel()
        vectors = cp.reshape(b[rest] - A[rest] @ x, (dim - 1, index.shape[1]), order="C")
        constraints.append((cp.SOC(t, vectors, axis=0), kind, rows))
    problem = cp.Problem(cp.Minimize(objective), [c for c, _, _ in constraints])
    return CvxpyModel(problem, x, tuple(constraints))


def _dual(constraint, kind: str, rows: slice) -> np.ndarray:
    value = constraint.dual_value
    if kind == "power":
        return np.concatenate([np.ravel(v) for v in value])
    if kind == "soc":  # [t duals (cones,), vector duals (dim−1, cones)] → interleaved rows
        t, vectors = value
        return np.vstack([np.atleast_1d(t), np.reshape(vectors, (-1, np.size(t)))]).T.ravel()
    if kind == "zero":  # cvxpy's multiplier of slack == 0 has the opposite sign of Clarabel's z
        return -np.atleast_1d(value)
    return np.atleast_1d(value)


def solve(
    program: ConicProgram,
    solver: str | None = None,
    tol: float | None = None,
    verbose: bool = False,
    cvxpy_model: CvxpyModel | None = None,
    **native,
) -> ConicSolution:
    """Solve ``program`` (or a user's extension of its model) through cvxpy.

    ``tol`` is passed to Clarabel (cvxpy's default solver here) as its gap and
    feasibility tolerances (default: 1e-10 where the polish finishes the job, 1e-12 otherwise, as
    on the direct path); other solvers take their own options in ``native``.
    """
    m = cvxpy_model if cvxpy_model is not None else model(program)
    options = dict(native)
    name = (solver or cp.CLARABEL).upper()
    retry = name == cp.CLARABEL and tol is None  # a default tolerance may be loosened, a user's is not
    if name == cp.CLARABEL:
        tol = tol if tol is not None else 1e-10 if polishable(program) else 1e-12
    start = time.perf_counter()
    while True:
        if name == cp.CLARABEL:
            options.update(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, tol_ktratio=tol)
        try:
            with warnings.catch_warnings():  # cvxpy's "optimal_inaccurate" is the result's status, its word kept
                warnings.filterwarnings("ignore", "Solution may be inaccurate", UserWarning)
                m.problem.solve(solver=name, verbose=verbose, **options)
            word = str(m.problem.status)
            break
        except TypeError as error:  # cvxpy's words for a setting the solver does not take
            if not native:
                raise
            raise ValueError(f"{', '.join(sorted(native))}: cvxpy:{name} refused the setting ({error}) — "
                             "see that solver's settings in cvxpy's documentation") from None
        except cp.error.SolverError as error:  # a failed solve is a result that says so, as on the other paths
            word = f"SolverError: {error}"
            if not retry or tol >= 1e-8:  # Clarabel stalls at tight tolerances: as the direct path, up to 1e-8
                break
            tol *= 10.0
    elapsed = time.perf_counter() - start
    status = _STATUS.get(word, "failed")
    if status in ("solved", "inaccurate"):
        x = np.asarray(m.x.value, dtype=float)
        z = np.concatenate([_dual(c, kind, rows) for c, kind, rows in m.cone_constraints])
    else:
        x = np.full(program.n_variables, np.nan)
        z = np.full(program.n_constraints, np.nan)
    stats = m.problem.solver_stats
    solution = ConicSolution(
        x=x,
        z=z,
        s=program.b - program.A @ x,
        status=status,
        solver_status=word,
        iterations=int(stats.num_iters or 0) if stats is not None else 0,
        solve_time=elapsed,
        solver=f"cvxpy:{stats.solver_name if stats is not None else name}",
    )
    return solution if cvxpy_model is not None else polish(program, solution)  # a user's model is not the program


class Session:
    """Re-solves by rebuilding the cvxpy model: transparent, not fast (see DESIGN.md)."""

    def __init__(self, program: ConicProgram, **options):
        self.program, self._options = program, options

    def update(self, q: np.ndarray | None = None, b: np.ndarray | None = None):
        self.program = self.program.updated(q, b)

    def solve(self) -> ConicSolution:
        return solve(self.program, **self._options)
