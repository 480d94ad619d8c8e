"""OSQP through its own Python API: l ≤ Ax ≤ u, linear cones only.

A 2-D second-order cone t ≥ |x| is written exactly as the two inequalities
t − x ≥ 0 and t + x ≥ 0; a larger cone is refused, never approximated.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

import numpy as np
import osqp
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution
from .polish import polish

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
    """OSQP's constraint matrix, and per block how b maps to (l, u) and y back to z."""
    blocks, plan = [], []
    for cone, rows in program.blocks():
        A = program.A[rows]
        if cone.kind in ("zero", "nonnegative"):
            blocks.append(A)
            plan.append((cone.kind, rows))
        elif cone.kind == "soc" and cone.dim == 2:
            # b − Ax = (s0, s1), s0 ≥ |s1|  ⇔  (A0 ∓ A1) x ≤ b0 ∓ b1
            blocks.append(sp.vstack([A[0] - A[1], A[0] + A[1]]))
            plan.append(("soc2", rows))
        else:
            name = {
                "power": "a power cone (normal compliance with exponent p > 1)",
                3: "a second-order cone of dimension 3 (the exact 3-D friction cone ‖λ_T‖ ≤ s, or 2-D "
                   "ε-regularized friction)",
                4: "a second-order cone of dimension 4 (ε-regularized 3-D friction)",
            }.get("power" if cone.kind == "power" else cone.dim, f"a second-order cone of dimension {cone.dim}")
            raise ConeNotSupported(
                f"OSQP takes linear cones only; got {name}. It is not approximated by a polygon: use "
                "solver='clarabel' or 'cvxpy' (3-D Signorini without friction is a QP and works with OSQP)."
            )
    return sp.vstack(blocks, format="csc"), plan


def _bounds(b: np.ndarray, plan):
    lower, upper = [], []
    for kind, rows in plan:
        part = b[rows]
        if kind == "zero":
            lower.append(part), upper.append(part)
        elif kind == "nonnegative":
            lower.append(np.full(part.size, -np.inf)), upper.append(part)
        else:
            lower.append(np.full(2, -np.inf)), upper.append(np.array([part[0] - part[1], part[0] + part[1]]))
    return np.concatenate(lower), np.concatenate(upper)


def _duals(y: np.ndarray, plan) -> np.ndarray:
    z = y.copy()
    for kind, rows in plan:
        if kind == "soc2":  # minus/plus inequality duals of one 2-D cone: z = (y₋ + y₊, y₊ − y₋)
            minus, plus = y[rows.start], y[rows.start + 1]
            z[rows] = (minus + plus, plus - minus)
    return z


@contextmanager
def silenced(active: bool):
    """Send the C library's stdout to /dev/null: OSQP 1.1 prints "Polishing not needed …" even with
    verbose off (it ended up in tables and JSON written from stdout). Python's own prints are kept."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class Session:
    """OSQP set up once (one LDL of its KKT matrix); :meth:`update` changes q and b and warm-starts."""

    def __init__(self, program: ConicProgram, tol: float = 1e-9, max_iter: int = 100_000, verbose: bool = False,
                 **native):
        self.program = program
        A, self._plan = _linear_rows(program)
        lower, upper = _bounds(program.b, self._plan)
        options = {"eps_abs": tol, "eps_rel": tol, "max_iter": max_iter, "polishing": True, "verbose": verbose}
        options.update(native)
        self._solver, self._verbose, self._setup_error = osqp.OSQP(), options["verbose"], None
        try:
            self._solver.setup(sp.triu(program.P, format="csc"), program.q, A, lower, upper, **options)
        except (ValueError, TypeError) as error:  # a name or a type OSQP's settings do not take
            raise _refused(native, error if isinstance(error, ValueError) else "a value of the wrong type") from None
        except osqp.OSQPException as error:
            if error == SETTINGS_REFUSED:
                raise _refused(native, "a value out of range; OSQP's log above says which") from None
            self._setup_error = f"OSQPException: setup failed, {_error_name(error)}"

    def update(self, q: np.ndarray | None = None, b: np.ndarray | None = None):
        changes = {}
        if q is not None:
            changes["q"] = q
        if b is not None:
            changes["l"], changes["u"] = _bounds(b, self._plan)
        self.program = self.program.updated(q, b)
        if self._setup_error is None:  # a solver that failed its setup has nothing to update: it says so again
            try:
                self._solver.update(**changes)
            except osqp.OSQPException as error:
                self._setup_error = f"OSQPException: update failed, {_error_name(error)}"

    def seed(self, guess: ConicSolution):
        """Start OSQP's iterations from ``guess``'s primal point."""
        self._solver.warm_start(x=guess.x)

    def solve(self) -> ConicSolution:
        if self._setup_error is not None:
            return failed(self.program, self._setup_error)
        try:
            with silenced(not self._verbose):
                result = self._solver.solve(raise_error=False)  # a failure is a status, read below
        except osqp.OSQPException as error:
            return failed(self.program, f"OSQPException: {_error_name(error)}")
        word = str(result.info.status)
        x = np.asarray(result.x, dtype=float)
        solution = ConicSolution(
            x=x,
            z=_duals(np.asarray(result.y, dtype=float), self._plan),
            s=self.program.b - self.program.A @ x,
            status=_STATUS.get(word, "failed"),
            solver_status=word,
            iterations=int(result.info.iter),
            solve_time=float(result.info.solve_time + result.info.polish_time),
            solver="osqp",
            info={"polished": int(result.info.status_polish) == 1, "setup_time": float(result.info.setup_time)},
        )
        # OSQP's own polish stops at its first active-set guess (and may skip rows it deems inactive);
        # ours iterates on the guess, and returns the same answer when OSQP's was exact already
        return polish(self.program, solution)


SETTINGS_REFUSED = 2
"""OSQP's error code for settings out of range (OSQP_SETTINGS_VALIDATION_ERROR)."""


def check_settings(names) -> None:
    """Refuse a name that is no field of OSQP's settings."""
    unknown = sorted(set(names) - set(dir(osqp.OSQP().ext.OSQPSettings())))
    if unknown:
        raise _refused(unknown[:1], "a name it does not know")


def _refused(native, cause) -> ValueError:
    names = ", ".join(sorted(native)) or "solver options"
    return ValueError(f"{names}: OSQP refused the setting ({cause}) — see OSQP's settings (eps_abs, eps_rel, "
                      "max_iter, rho, sigma, polishing, …) for their names, types and ranges")


def _error_name(error: osqp.OSQPException) -> str:
    code = error.args[0] if error.args else None
    names = {int(kind): name for name, kind in osqp.OSQP().ext.osqp_error_type.__members__.items()}
    return names.get(code, f"error {code}")


def failed(program: ConicProgram, word: str) -> ConicSolution:
    """A solve that ended in an exception, as a result that says so (no point, the solver's words)."""
    x = np.full(program.n_variables, np.nan)
    return ConicSolution(x=x, z=np.full(program.n_constraints, np.nan), s=np.full(program.n_constraints, np.nan),
                         status="failed", solver_status=word, iterations=0, solve_time=0.0, solver="osqp")


def solve(program: ConicProgram, **options) -> ConicSolution:
    """Solve ``program`` with OSQP, polishing on (an active-set answer when it succeeds)."""
    return Session(program, **options).solve()
