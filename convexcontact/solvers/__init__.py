"""Solver adapters: thin functions from a ConicProgram to a ConicSolution.

A solver never knows mechanics. Names: ``clarabel``, ``osqp``, ``cvxpy`` or
``cvxpy:NAME`` (any solver cvxpy reaches, e.g. ``cvxpy:SCS``).
"""

from __future__ import annotations

from ..conic import ConicProgram, ConicSolution
from . import clarabel_direct, cvxpy_model, osqp_direct
from .osqp_direct import ConeNotSupported

SOLVERS = ("clarabel", "osqp", "cvxpy")


def check_name(name: str) -> str:
    """Return ``name`` if it names a solver path, else raise naming the choices."""
    if name.split(":", 1)[0] not in SOLVERS:
        raise ValueError(f"solver: unknown {name!r}; use one of {SOLVERS} or 'cvxpy:NAME'")
    return name


def session(program: ConicProgram, solver: str = "clarabel", **options):
    """A solver set up for ``program``, with ``update(q=, b=)`` and ``solve()`` for re-solves.

    Clarabel keeps its setup, OSQP its factorization and warm start; cvxpy rebuilds.
    """
    base, _, sub = check_name(solver).partition(":")
    if base == "clarabel":
        return clarabel_direct.Session(program, **options)
    if base == "osqp":
        return osqp_direct.Session(program, **options)
    return cvxpy_model.Session(program, solver=sub or None, **options)


def seedable(solver: str, options: dict) -> bool:
    """Whether the solver's sessions start from a guess (``seed``); cvxpy rebuilds its model every solve."""
    return check_name(solver).split(":", 1)[0] in ("clarabel", "osqp") and options.get("polishing", True)


def solve(program: ConicProgram, solver: str = "clarabel", **options) -> ConicSolution:
    """Solve ``program`` with the named solver; ``options`` go to that adapter."""
    return session(program, solver, **options).solve()


__all__ = ["SOLVERS", "ConeNotSupported", "check_name", "cvxpy_model", "seedable", "solve"]
