"""OSQP through its own Python API: l ≤ Ax ≤ u, linear cones only.

A 2-D second-order cone t ≥ |x| is written exactly as the two inequalities
t − x ≥ 0 and t + x ≥ 0; a larger cone is refused, never approximated.
"""

from __future__ import annotations

import numpy as np
import osqp
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution

_STATUS = {
    "solved": "solved",
    "solved inaccurate": "inaccurate",
    "primal infeasible": "infeasible",
    "primal infeasible inaccurate": "infeasible",
    "dual infeasible": "unbounded",
    "dual infeasible inaccurate": "unbounded",
}


class ConeNotSupported(ValueError):
    """The program has a cone OSQP cannot take exactly."""


def _linear_rows(program: ConicProgram):
    """Rows (A, l, u) of OSQP's form and the map from its duals y back to z."""
    blocks, lower, upper, to_z = [], [], [], []
    row = 0
    for cone, rows in program.blocks():
        A, b = program.A[rows], program.b[rows]
        if cone.kind == "zero":
            blocks.append(A), lower.append(b), upper.append(b)
            to_z.append(("copy", row, cone.dim))
            row += cone.dim
        elif cone.kind == "nonnegative":
            blocks.append(A), lower.append(np.full(cone.dim, -np.inf)), upper.append(b)
            to_z.append(("copy", row, cone.dim))
            row += cone.dim
        elif cone.dim == 2:
            # b − Ax = (s0, s1), s0 ≥ |s1|  ⇔  (A0 ∓ A1) x ≤ b0 ∓ b1
            blocks.append(sp.vstack([A[0] - A[1], A[0] + A[1]]))
            lower.append(np.full(2, -np.inf)), upper.append(np.array([b[0] - b[1], b[0] + b[1]]))
            to_z.append(("soc2", row, 2))
            row += 2
        else:
            raise ConeNotSupported(
                f"OSQP takes linear cones only; got a second-order cone of dimension {cone.dim}. "
                "Use solver='clarabel' or 'cvxpy' for 3-D friction or ε-regularized friction."
            )
    A = sp.vstack(blocks, format="csc") if blocks else sp.csc_matrix((0, program.n_variables))
    return A, np.concatenate(lower or [[]]), np.concatenate(upper or [[]]), to_z


def _duals(y: np.ndarray, to_z) -> np.ndarray:
    z = []
    for kind, row, dim in to_z:
        if kind == "copy":
            z.append(y[row : row + dim])
        else:  # minus/plus inequality duals of one 2-D cone: z = (y₋ + y₊, y₊ − y₋)
            minus, plus = y[row], y[row + 1]
            z.append(np.array([minus + plus, plus - minus]))
    return np.concatenate(z) if z else np.zeros(0)


def solve(
    program: ConicProgram, tol: float = 1e-9, max_iter: int = 100_000, verbose: bool = False, **native
) -> ConicSolution:
    """Solve ``program`` with OSQP, polishing on (an active-set answer when it succeeds)."""
    A, lower, upper, to_z = _linear_rows(program)
    solver = osqp.OSQP()
    options = {"eps_abs": tol, "eps_rel": tol, "max_iter": max_iter, "polishing": True, "verbose": verbose}
    options.update(native)
    solver.setup(sp.triu(program.P, format="csc"), program.q, A, lower, upper, **options)
    result = solver.solve()
    word = str(result.info.status)
    x = np.asarray(result.x, dtype=float)
    z = _duals(np.asarray(result.y, dtype=float), to_z)
    return ConicSolution(
        x=x,
        z=z,
        s=program.b - program.A @ x,
        status=_STATUS.get(word, "failed"),
        solver_status=word,
        iterations=int(result.info.iter),
        solve_time=float(result.info.solve_time + result.info.polish_time),
        solver="osqp",
        info={"polished": int(result.info.status_polish) == 1, "setup_time": float(result.info.setup_time)},
    )
