"""Solver adapters: thin functions from a ConicProgram to a ConicSolution.

A solver never knows mechanics. Names: ``clarabel``, ``osqp``, ``cvxpy`` or
``cvxpy:NAME`` (any solver cvxpy reaches, e.g. ``cvxpy:SCS``), ``newton-cg`` (bound-form
programs, P a matrix or an operator), and ``auto``: newton-cg when P is an operator
(a matrix-free program), else clarabel.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import scipy.sparse.linalg as spla

from ..conic import ConicProgram, ConicSolution
from . import clarabel_direct, cvxpy_model, newton_cg, osqp_direct
from .osqp_direct import ConeNotSupported

SOLVERS = ("auto", "clarabel", "osqp", "cvxpy", "newton-cg")


def check_name(name: str) -> str:
    """Return ``name`` if it names a solver path (and, for ``cvxpy:NAME``, a solver cvxpy has), else raise
    naming the choices."""
    if not isinstance(name, str) or name.split(":", 1)[0] not in SOLVERS:
        raise ValueError(f"solver: unknown {name!r}; use one of {SOLVERS} or 'cvxpy:NAME'")
    base, _, sub = name.partition(":")
    if base == "cvxpy" and sub:
        import cvxpy as cp

        if sub.upper() not in cp.installed_solvers():
            raise ValueError(f"solver: cvxpy has no solver {sub!r} installed; it has {sorted(cp.installed_solvers())}")
    return name


def _flag(value) -> bool:
    return isinstance(value, (bool, np.bool_))


OPTIONS = {  # the options every path takes: test, what is expected, an example
    "tol": (lambda v: isinstance(v, numbers.Real) and not _flag(v) and 0 < v < math.inf,
            "a positive finite number", "tol=1e-10"),
    "max_iter": (lambda v: isinstance(v, numbers.Integral) and not _flag(v) and v >= 1,
                 "a positive integer", "max_iter=500"),
    "verbose": (_flag, "True or False", "verbose=True"),
    "polishing": (_flag, "True or False", "polishing=False"),
    "progress": (callable, "a function, called after each step", "progress=print"),
}


def check_options(options: dict, solver: str | None = None) -> dict:
    """The options every path takes, checked where they enter (:data:`OPTIONS`), and the names of the
    ``solver``'s native settings (Clarabel's and OSQP's; cvxpy's solvers name theirs when they solve)."""
    for name, (valid, expected, example) in OPTIONS.items():
        if options.get(name) is not None and not valid(options[name]):
            raise ValueError(f"{name}: expected {expected}, got {options[name]!r:.60} — e.g. {example}")
    adapter = {"clarabel": clarabel_direct, "osqp": osqp_direct, "newton-cg": newton_cg}.get(solver)
    if adapter is not None:
        adapter.check_settings(set(options) - set(OPTIONS))
    return options


def session(program: ConicProgram, solver: str = "clarabel", **options):
    """A solver set up for ``program``, with ``update(q=, b=)`` and ``solve()`` for re-solves.

    Clarabel keeps its setup, OSQP its factorization and warm start; cvxpy rebuilds.
    """
    solver = resolve(solver, program)
    base, _, sub = solver.partition(":")
    operator = matrix_free(program)
    check_options(options, solver)
    if operator and base != "newton-cg":
        raise ValueError(f"solver: {solver} needs P as a matrix, and this program's P is an operator (matrix-free); "
                         "use solver='auto' or 'newton-cg', or a formulation that forms P ('dual' or 'primal')")
    if base == "newton-cg":
        return newton_cg.Session(program, **options)
    if base == "clarabel":
        return clarabel_direct.Session(program, **options)
    if base == "osqp":
        return osqp_direct.Session(program, **options)
    return cvxpy_model.Session(program, solver=sub or None, **options)


def resolve(solver: str, program: ConicProgram) -> str:
    """The solver that runs ``program``: ``auto`` is newton-cg where P is an operator, Clarabel otherwise."""
    if check_name(solver) != "auto":
        return solver
    return "newton-cg" if matrix_free(program) else "clarabel"


def matrix_free(program: ConicProgram) -> bool:
    """Whether the program's P is an operator (only products with it), not a matrix."""
    return isinstance(program.P, spla.LinearOperator)


def seedable(solver: str, options: dict, program: ConicProgram | None = None) -> bool:
    """Whether the solver's sessions are worth starting from a guess (``seed``) on ``program`` ("auto" resolved on
    it); cvxpy rebuilds its model every solve. newton-cg can be seeded but is not: from the frictionless answer a
    2-D whole-face Tresca dual took 5.5 s against 3.4 s from its own start (3-D: 3.1 s against 3.6 s)."""
    base = (resolve(solver, program) if program is not None else check_name(solver)).split(":", 1)[0]
    return base in ("clarabel", "osqp", "auto") and options.get("polishing", True)  # auto on no program: Clarabel


def solve(program: ConicProgram, solver: str = "clarabel", **options) -> ConicSolution:
    """Solve ``program`` with the named solver; ``options`` go to that adapter."""
    return session(program, solver, **options).solve()


__all__ = ["SOLVERS", "ConeNotSupported", "check_name", "check_options", "cvxpy_model", "matrix_free", "seedable",
           "solve"]
