"""cvxpy: the ConicProgram as a transparent ``cvxpy.Problem`` a user can read and extend.

Build the model with :func:`model`, add constraints or change the objective with
:meth:`CvxpyModel.extended`, then :func:`solve` it with any solver cvxpy reaches.
The duals of the original cone constraints are mapped back to Clarabel's z, so
the mechanics recovered from the solution does not depend on the solver used.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from ..conic import ConicProgram, ConicSolution

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

    ``cone_constraints`` are the constraints of the program's cone blocks, in order;
    ``problem`` may hold more (added by the user).
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


def model(program: ConicProgram) -> CvxpyModel:
    """The cvxpy Problem of ``program`` (P is wrapped in psd_wrap: no dense PSD check)."""
    x = cp.Variable(program.n_variables, name="x")
    objective = 0.5 * cp.quad_form(x, cp.psd_wrap(program.P)) + program.q @ x
    constraints = []
    for cone, rows in program.blocks():
        slack = program.b[rows] - program.A[rows] @ x
        if cone.kind == "zero":
            constraints.append(slack == 0)
        elif cone.kind == "nonnegative":
            constraints.append(slack >= 0)
        else:
            constraints.append(cp.SOC(slack[0], slack[1:]))
    return CvxpyModel(cp.Problem(cp.Minimize(objective), constraints), x, tuple(constraints))


def _dual(constraint, kind: str) -> np.ndarray:
    value = constraint.dual_value
    if kind == "soc":
        return np.concatenate([np.atleast_1d(v) for v in value])
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
    feasibility tolerances; other solvers take their own options in ``native``.
    """
    m = cvxpy_model if cvxpy_model is not None else model(program)
    options = dict(native)
    name = (solver or cp.CLARABEL).upper()
    if tol is not None and name == cp.CLARABEL:
        options.update(tol_gap_abs=tol, tol_gap_rel=tol, tol_feas=tol, tol_ktratio=tol)
    start = time.perf_counter()
    m.problem.solve(solver=name, verbose=verbose, **options)
    elapsed = time.perf_counter() - start
    status = _STATUS.get(m.problem.status, "failed")
    if status in ("solved", "inaccurate"):
        x = np.asarray(m.x.value, dtype=float)
        z = np.concatenate([_dual(c, cone.kind) for c, cone in zip(m.cone_constraints, program.cones)])
    else:
        x = np.full(program.n_variables, np.nan)
        z = np.full(program.n_constraints, np.nan)
    stats = m.problem.solver_stats
    return ConicSolution(
        x=x,
        z=z,
        s=program.b - program.A @ x,
        status=status,
        solver_status=str(m.problem.status),
        iterations=int(stats.num_iters or 0) if stats is not None else 0,
        solve_time=elapsed,
        solver=f"cvxpy:{stats.solver_name if stats is not None else name}",
    )
