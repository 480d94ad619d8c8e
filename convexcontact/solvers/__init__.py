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


def check_options(options: dict) -> dict:
    """The options every adapter takes, checked where they enter: ``tol`` a positive finite number,
    ``max_iter`` a positive integer, ``verbose`` and ``polishing`` booleans. Native settings are checked
    by the adapter that knows them."""
    tol = options.get("tol")
    if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < float("inf")):
        raise ValueError(f"tol: expected a positive finite number, got {tol!r} — e.g. tol=1e-10")
    max_iter = options.get("max_iter")
    if max_iter is not None and (isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1):
        raise ValueError(f"max_iter: expected a positive integer, got {max_iter!r} — e.g. max_iter=500")
    for flag in ("verbose", "polishing"):
        if flag in options and not isinstance(options[flag], bool):
            raise ValueError(f"{flag}: expected True or False, got {options[flag]!r}")
    return options


def session(program: ConicProgram, solver: str = "clarabel", **options):
    """A solver set up for ``program``, with ``update(q=, b=)`` and ``solve()`` for re-solves.

    Clarabel keeps its setup, OSQP its factorization and warm start; cvxpy rebuilds.
    """
    base, _, sub = check_name(solver).partition(":")
    check_options(options)
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


__all__ = ["SOLVERS", "ConeNotSupported", "check_name", "check_options", "cvxpy_model", "seedable", "solve"]
