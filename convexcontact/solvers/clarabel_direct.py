"""Clarabel through its own Python API: the ConicProgram is its native form."""

from __future__ import annotations

from dataclasses import replace

import clarabel
import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution
from .polish import polish

_CONES = {
    "zero": clarabel.ZeroConeT,
    "nonnegative": clarabel.NonnegativeConeT,
    "soc": clarabel.SecondOrderConeT,
    "power": lambda dim, alpha: clarabel.PowerConeT(alpha),
}

_STATUS = {
    "Solved": "solved",
    "AlmostSolved": "inaccurate",
    "PrimalInfeasible": "infeasible",
    "AlmostPrimalInfeasible": "infeasible",
    "DualInfeasible": "unbounded",
    "AlmostDualInfeasible": "unbounded",
}


def settings(tol: float = 1e-10, max_iter: int = 200, verbose: bool = False, **native) -> clarabel.DefaultSettings:
    """Clarabel settings with gap and feasibility tolerances set to ``tol``.

    Clarabel's defaults (1e-8) leave contact forces only ~1e-3 accurate on contact
    problems (DESIGN.md, dependency facts), hence the tighter default. One thread by
    default: on the project's 2-core machines Clarabel's threads made the Hertz demo
    2–3.5× slower (6.5k DOFs: 1.48 s vs 0.42 s; 26k DOFs: 5.1 s vs 2.0 s, machine under
    load); pass ``max_threads=0`` for Clarabel's own choice.
    """
    s = clarabel.DefaultSettings()
    s.verbose = verbose
    s.max_threads = 1
    s.max_iter = max_iter
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = tol
    s.tol_ktratio = min(s.tol_ktratio, tol)
    for name, value in native.items():
        if not hasattr(s, name):
            raise ValueError(f"clarabel has no setting {name!r}")
        setattr(s, name, value)
    return s


class Session:
    """A Clarabel solver set up once; :meth:`update` changes q and b, keeping the setup.

    ``polishing`` (default on) refines the answer of a program with linear cones on its
    active set (:mod:`.polish`), as OSQP does.

    Clarabel has no warm start; an update saves the setup (symbolic work), not
    iterations. When presolve removed rows the data cannot be updated and the
    session sets the solver up again.
    """

    def __init__(self, program: ConicProgram, tol: float = 1e-10, max_iter: int = 200, verbose: bool = False,
                 polishing: bool = True, **native):
        self.program = program
        self._polishing = polishing
        self._settings = settings(tol, max_iter, verbose, **native)
        self._solver = self._setup(program)

    def _setup(self, program: ConicProgram):
        return clarabel.DefaultSolver(
            sp.triu(program.P, format="csc"),
            program.q,
            sp.csc_matrix(program.A),
            program.b,
            [_CONES[c.kind](c.dim, c.alpha) if c.kind == "power" else _CONES[c.kind](c.dim) for c in program.cones],
            self._settings,
        )

    def update(self, q: np.ndarray | None = None, b: np.ndarray | None = None):
        self.program = replace(self.program, q=self.program.q if q is None else q, b=self.program.b if b is None else b)
        if self._solver.is_data_update_allowed():
            self._solver.update(**{k: v for k, v in (("q", q), ("b", b)) if v is not None})
        else:
            self._solver = self._setup(self.program)

    def solve(self) -> ConicSolution:
        result = self._solver.solve()
        word = str(result.status).split(".")[-1]
        solution = ConicSolution(
            x=np.asarray(result.x),
            z=np.asarray(result.z),
            s=np.asarray(result.s),
            status=_STATUS.get(word, "failed"),
            solver_status=word,
            iterations=int(result.iterations),
            solve_time=float(result.solve_time),
            solver="clarabel",
        )
        return polish(self.program, solution) if self._polishing else solution


def solve(program: ConicProgram, **options) -> ConicSolution:
    """Solve ``program`` with Clarabel (upper triangle of P, sparse CSC); options as :class:`Session`."""
    return Session(program, **options).solve()
