"""Active-set polish of an interior-point answer, for programs with linear cones only.

An interior-point solver stops at a tolerance relative to the whole problem, so rows
whose forces are small beside the largest (soft subdomains, tiny elements, zero load)
can stay inaccurate. Guessing the active set from the answer (z_i > s_i) and solving
the equality-constrained KKT system gives the exact answer of that guess — the idea of
OSQP's polishing. Rows the interior point left unresolved (z and s both tiny) can make
the first guess wrong, so a few primal-dual active-set rounds follow: violated rows
join, rows with negative multipliers leave. The answer is kept only if it is primal and
dual feasible.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..conic import ConicProgram, ConicSolution

FEASIBLE = 1e-10
"""Largest violation (relative to the answer's scale) a polished answer may have."""
ROUNDS = 10
"""Active-set rounds before polishing gives up (and the interior-point answer stands)."""


def polish(program: ConicProgram, solution: ConicSolution) -> ConicSolution:
    """The polished solution, or ``solution`` unchanged when polishing does not apply or fails."""
    if not program.is_linear or not solution.solved or not np.isfinite(solution.z).all():
        return solution
    equality = np.zeros(program.n_constraints, bool)
    for cone, rows in program.blocks():
        equality[rows] = cone.kind == "zero"
    A = sp.csr_matrix(program.A)
    touches = np.diff(A.indptr) > 0  # an empty row has no say in x
    active = touches & (equality | (solution.z > solution.s))
    scale_s = max(np.abs(program.b).max(initial=0.0), np.abs(solution.x).max(initial=0.0), 1.0)
    scale_z = max(np.abs(solution.z).max(initial=0.0), 1.0)
    n = program.n_variables
    for _ in range(ROUNDS):
        kkt = sp.bmat([[program.P, A[active].T], [A[active], None]], format="csc")
        try:
            answer = spla.splu(kkt).solve(np.concatenate([-program.q, program.b[active]]))
        except RuntimeError:  # singular: dependent active rows or an unheld rigid motion
            return solution
        if not np.isfinite(answer).all():
            return solution
        x, z = answer[:n], np.zeros(program.n_constraints)
        z[active] = answer[n:]
        s = np.where(equality, 0.0, program.b - A @ x)
        violated = touches & ~equality & (s < -FEASIBLE * scale_s)
        negative = active & ~equality & (z < -FEASIBLE * scale_z)
        if not violated.any() and not negative.any():
            return replace(solution, x=x, z=z, s=np.maximum(s, 0.0), info={**solution.info, "polished": True})
        active = (active | violated) & ~negative
    return solution
