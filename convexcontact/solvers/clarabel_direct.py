"""Clarabel through its own Python API: the ConicProgram is its native form."""

from __future__ import annotations

import time
from dataclasses import replace

import clarabel
import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution
from .polish import dense, polish, polishable

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


def check_settings(names) -> None:
    """Refuse a name that is no field of clarabel.DefaultSettings."""
    unknown = sorted(set(names) - set(dir(clarabel.DefaultSettings())))
    if unknown:
        raise ValueError(f"{unknown[0]}: clarabel has no such setting — the settings are the fields of "
                         "clarabel.DefaultSettings (e.g. max_threads, static_regularization_constant)")


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
    check_settings(native)
    for name, value in native.items():
        try:
            setattr(s, name, value)
        except (TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"{name}: clarabel refused {value!r:.40} ({error}) — give the type of "
                             f"clarabel.DefaultSettings().{name}, {getattr(s, name)!r:.40}") from None
    return s


def default_tol(program: ConicProgram, polishing: bool) -> float:
    """The tolerance at which the certificate passes. With a polish to finish the job: 1e-10 on sparse FE
    programs, 1e-8 on dense (condensed) ones (a 3-D Tresca punch, 1452 unknowns: 14 iterations instead
    of 20, polished to the same certificate, 5e-15). Without one, 1e-12: on a 3-D Tresca punch (SOC(3)
    primal, 2k DOFs) 1e-10 left the friction law's natural residual at 1.3e-6 (forces 4e-6 off the exact
    dual's) and 1e-11 at 3.3e-7; a Coulomb punch's Picard map stagnated at changes of 1e-7 with 1e-10."""
    if polishing and polishable(program):
        return 1e-8 if dense(program.P) else 1e-10
    return 1e-12


RETRY_BELOW = 1e-8
"""Tolerances below which a stalled solve (InsufficientProgress) is retried at 10× the tolerance, up to this."""


class Session:
    """A Clarabel solver set up once; :meth:`update` changes q and b, keeping the setup.

    ``polishing`` (default on) refines the answer of a program with linear cones on its
    active set (:mod:`.polish`), as OSQP does.

    Clarabel has no warm start; an update saves the setup (symbolic work), not
    iterations. When presolve removed rows the data cannot be updated and the
    session sets the solver up again. With polishing, a re-solve after an update is
    warm-started instead: the active-set rounds of :mod:`.polish` run from the previous
    answer, and the interior point runs only if they do not end at a feasible KKT point
    (a Picard step or a sweep changes the active set little, so this usually takes one
    or two linear solves).
    """

    def __init__(self, program: ConicProgram, tol: float | None = None, max_iter: int = 200, verbose: bool = False,
                 polishing: bool = True, **native):
        self.program = program
        self._polishing = polishing
        # Clarabel's supernodal faer solves dense (condensed) programs several times faster than qdldl
        # (1500 dense unknowns: 2.3 s against 18 s; the Delassus program of a 26k-DOF punch: 0.12 s
        # against 0.22 s), but on sparse near-incompressible FE programs it stopped short of qdldl's accuracy
        native.setdefault("direct_solve_method", "faer" if dense(program.P) else "qdldl")
        # a default tolerance relaxed because the polish was to finish the job: tightened if it does not
        self._tight_tol = default_tol(program, False) if tol is None and polishing and dense(program.P) else None
        if tol is None:
            tol = default_tol(program, polishing)
        self._tol, self._options = tol, dict(max_iter=max_iter, verbose=verbose, **native)
        self._settings = settings(tol, **self._options)
        self._solver = self._setup(program)
        self._previous: ConicSolution | None = None

    def _setup(self, program: ConicProgram):
        return clarabel.DefaultSolver(*self._data(program), self._settings)

    @staticmethod
    def _data(program: ConicProgram) -> tuple:
        cones = [_CONES[c.kind](c.dim, c.alpha) if c.kind == "power" else _CONES[c.kind](c.dim) for c in program.cones]
        return sp.triu(program.P, format="csc"), program.q, sp.csc_matrix(program.A), program.b, cones

    def update(self, q: np.ndarray | None = None, b: np.ndarray | None = None):
        self.program = self.program.updated(q, b)
        if self._solver.is_data_update_allowed():
            self._solver.update(**{k: v for k, v in (("q", q), ("b", b)) if v is not None})
        else:
            self._solver = self._setup(self.program)

    def seed(self, guess: ConicSolution):
        """Start the next solve from ``guess`` (the answer of a related program, such as its frictionless
        counterpart) unless the session has an answer of its own: the polish's rounds run from it first."""
        if self._polishing and self._previous is None:
            self._previous = guess

    def solve(self) -> ConicSolution:
        if self._polishing and self._previous is not None:
            start = time.perf_counter()
            guess = replace(self._previous, s=self.program.b - self.program.A @ self._previous.x, info={})
            warm = polish(self.program, guess)
            if warm is not guess:
                self._previous = replace(warm, iterations=0, solve_time=time.perf_counter() - start,
                                         info={**warm.info, "warm_start": True})
                return self._previous
        solution = self._interior_point(self._solver, self._tol)
        if not self._polishing:
            return solution
        polished = polish(self.program, solution)
        if polished is solution and self._tight_tol is not None and self._tight_tol < self._tol:
            # the polish could not settle the active set (a degenerate program: multipliers that are not
            # unique, Gauss-point friction): the interior point's answer must then be accurate on its own
            tight = clarabel.DefaultSolver(*self._data(self.program), settings(self._tight_tol, **self._options))
            solution = self._interior_point(tight, self._tight_tol)
            polished = polish(self.program, solution)
        self._previous = polished if polished.info.get("polished") else None
        return polished

    def _interior_point(self, solver, tol: float) -> ConicSolution:
        """Run Clarabel's interior point (set up at ``tol``; if it stalls, again at 10× ``tol``, up to 1e-8)."""
        result = solver.solve()
        word = str(result.status).split(".")[-1]
        while word == "InsufficientProgress" and tol < RETRY_BELOW:
            # Clarabel sometimes stalls short of a tight gap and returns an iterate far from the answer
            # (a 3k-DOF punch at 1e-10: certificate 0.6; a 3-D Tresca block at 1e-12 and 1e-11: 0.85); a
            # looser tolerance then solves it (1e-10: certificate 2e-11) and the polish, where it applies,
            # restores full accuracy (1e-14)
            tol *= 10.0
            result = clarabel.DefaultSolver(*self._data(self.program), settings(tol, **self._options)).solve()
            word = str(result.status).split(".")[-1]
        return ConicSolution(
            x=np.asarray(result.x),
            z=np.asarray(result.z),
            s=np.asarray(result.s),
            status=_STATUS.get(word, "failed"),
            solver_status=word,
            iterations=int(result.iterations),
            solve_time=float(result.solve_time),
            solver="clarabel",
        )


def solve(program: ConicProgram, **options) -> ConicSolution:
    """Solve ``program`` with Clarabel (upper triangle of P, sparse CSC); options as :class:`Session`."""
    return Session(program, **options).solve()
