"""The one interface between formulations and solvers: Clarabel's standard form.

    minimize   ½ xᵀPx + qᵀx
    subject to Ax + s = b,   s ∈ K = K₁ × K₂ × …

with cones (in this order of rows) from :data:`CONES`. Dual variables z ∈ K*
satisfy Px + q + Aᵀz = 0 at optimality. The 3-D power cone of exponent α is
{(x, y, w): x^α y^(1−α) ≥ |w|, x, y ≥ 0}, as in Clarabel.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass(frozen=True)
class Cone:
    """One block of rows of the constraint: ``kind`` is zero, nonnegative, soc or power."""

    kind: str
    dim: int
    alpha: float | None = None  # exponent of a power cone

    def __post_init__(self):
        if self.kind not in CONES:
            raise ValueError(f"Cone.kind: must be one of {CONES}, got {self.kind!r}")
        integer = isinstance(self.dim, (int, np.integer)) and not isinstance(self.dim, bool)
        if not integer:  # a ValueError, as every bad input of the package (the CLI's exit code 2)
            raise ValueError(f"Cone.dim: expected an integer, got {self.dim!r}")
        if self.dim < 1 or (self.kind == "soc" and self.dim < 2):
            raise ValueError(f"Cone.dim: a {self.kind} cone has dimension ≥ {2 if self.kind == 'soc' else 1}, "
                             f"got {self.dim}")
        if self.kind == "power" and (self.dim != 3 or not 0 < (self.alpha or 0) < 1):
            raise ValueError(f"a power cone has dimension 3 and 0 < alpha < 1, got {self.dim}, {self.alpha}")


CONES = ("zero", "nonnegative", "soc", "power")


def zero(dim: int) -> Cone:
    return Cone("zero", dim)


def nonnegative(dim: int) -> Cone:
    return Cone("nonnegative", dim)


def soc(dim: int) -> Cone:
    """(t, x) with t ≥ ‖x‖₂; dimension 1 + len(x)."""
    return Cone("soc", dim)


def power(alpha: float) -> Cone:
    """(x, y, w) with x^α y^(1−α) ≥ |w|, x, y ≥ 0."""
    return Cone("power", 3, alpha)


@dataclass(frozen=True)
class ConicProgram:
    """Data of a convex conic program in Clarabel's standard form.

    ``P`` is stored as the full symmetric matrix (sparse, or dense as :func:`dense_matrix` holds it, or an operator);
    adapters take the upper triangle where the solver wants it. ``gradient``, where the formulation has one, is its
    own formula of x ↦ Px + q for this q, exact where Px and q cancel (the contact dual's, formulations/dual.py);
    solvers that read it take it from :meth:`updated`, which drops it with a new q.
    """

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csc_matrix
    b: np.ndarray
    cones: tuple[Cone, ...]
    gradient: Callable[[np.ndarray], np.ndarray] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        for name in ("q", "b"):
            vector = getattr(self, name)
            if not isinstance(vector, np.ndarray) or vector.ndim != 1 or vector.dtype.kind not in "fiu":
                raise ValueError(f"ConicProgram.{name}: expected a 1-D numpy array of numbers, got "
                                 f"{type(vector).__name__} {getattr(vector, 'shape', '')}; pass np.ravel(…)")
        if not (sp.issparse(self.P) or isinstance(self.P, spla.LinearOperator)):
            raise ValueError(f"ConicProgram.P: expected a scipy.sparse matrix or a scipy LinearOperator, got "
                             f"{type(self.P).__name__}; pass scipy.sparse.csc_matrix(P), or "
                             "convexcontact.conic.dense_matrix(P) to keep a dense P's memory")
        if not sp.issparse(self.A):
            raise ValueError(f"ConicProgram.A: expected a scipy.sparse matrix, got {type(self.A).__name__}; pass "
                             "scipy.sparse.csc_matrix(A)")
        n, m = self.q.size, self.b.size
        if self.P.shape != (n, n) or self.A.shape != (m, n):
            raise ValueError(f"ConicProgram: shapes P {self.P.shape}, A {self.A.shape} do not fit q ({n}) and b ({m})")
        if self.gradient is not None and not callable(self.gradient):
            raise ValueError(f"ConicProgram.gradient: expected a function x ↦ Px + q or None, got "
                             f"{type(self.gradient).__name__}; leave it None to let solvers form Px + q")
        if not isinstance(self.cones, tuple) or not all(isinstance(c, Cone) for c in self.cones):
            raise ValueError("ConicProgram.cones: expected a tuple of Cone (zero(m), nonnegative(m), soc(d), power(α))")
        if sum(c.dim for c in self.cones) != m:
            raise ValueError(f"ConicProgram.cones: dimensions add up to {sum(c.dim for c in self.cones)}, "
                             f"not to the {m} rows of A")
        for name, values in (("q", self.q), ("b", self.b), ("A", self.A.data)) + (
                (("P", self.P.data),) if sp.issparse(self.P) else ()):
            if not np.all(np.isfinite(values)):
                raise ValueError(f"ConicProgram.{name}: holds NaN or inf; a convex program needs finite data")
        if sp.issparse(self.P) and not symmetric(self.P):
            raise ValueError("ConicProgram.P: not symmetric; the program is ½ xᵀPx with P symmetric (pass ½(P + Pᵀ), "
                             "which has the same objective) — solvers read one triangle and would solve another")

    @property
    def n_variables(self) -> int:
        return self.q.size

    @property
    def n_constraints(self) -> int:
        return self.b.size

    @property
    def is_linear(self) -> bool:
        """True when every cone is polyhedral (zero or nonnegative)."""
        return all(c.kind in ("zero", "nonnegative") for c in self.cones)

    def updated(self, q: np.ndarray | None = None, b: np.ndarray | None = None) -> ConicProgram:
        """The program with new data q and/or b (None: kept); the formulation's ``gradient`` holds for its own q
        only, so a new q drops it."""
        same_q = q is None or q is self.q or np.array_equal(q, self.q)
        return replace(self, q=self.q if q is None else q, b=self.b if b is None else b,
                       gradient=self.gradient if same_q else None)

    def blocks(self):
        """Yield (cone, row slice) for every cone block."""
        start = 0
        for cone in self.cones:
            yield cone, slice(start, start + cone.dim)
            start += cone.dim


def dense_matrix(W: np.ndarray) -> sp.spmatrix:
    """The dense symmetric W as a scipy matrix on W's own memory (a view stays a view): one block of scipy's BSR
    format, two indices, where CSC holds an int32 row index per entry that no solver of a dense P reads (m² · 4 B: 61
    MB beside the 122 MB of the 2-D pair's friction W at 2.8·10⁵ DOFs, alive through its Newton solves). Solvers read
    the values back with :func:`dense_values`; scipy's operations (triu, tocsc, products) take it as any sparse P."""
    if not isinstance(W, np.ndarray) or W.ndim != 2 or W.shape[0] != W.shape[1] or W.dtype.kind not in "fiu":
        raise ValueError(f"dense_matrix: expected a square 2-D numpy array of numbers, got {type(W).__name__} "
                         f"{getattr(W, 'shape', '')}; pass np.asarray(W, dtype=float)")
    if not W.size:  # BSR has no block of size 0
        return sp.csc_matrix(W.shape)
    return sp.bsr_matrix((W[None], np.zeros(1, np.int32), np.array([0, 1], np.int32)), shape=W.shape)


def dense_values(P) -> np.ndarray | None:
    """P's values as an (n, n) array without a copy where P is one dense block (:func:`dense_matrix`), else None."""
    if sp.issparse(P) and P.format == "bsr" and P.blocksize == P.shape:
        return P.data[0]
    return None


def symmetric(P, rtol: float = 1e-10) -> bool:
    """Whether xᵀPy = yᵀPx for random x, y (two products, no transpose formed: cheap beside any solve)."""
    rng = np.random.default_rng(0)
    values = dense_values(P)
    P = P if values is None else values  # scipy's product on a dense block takes 2.6 times numpy's
    x, y = rng.standard_normal((2, P.shape[0]))
    Px = P @ x
    return abs(y @ Px - x @ (P @ y)) <= rtol * np.linalg.norm(Px) * np.linalg.norm(y)


@dataclass
class ConicSolution:
    """What a solver returns, before anything is known of mechanics.

    ``status`` is ours (solved, infeasible, unbounded, inaccurate, failed);
    ``solver_status`` is the solver's own word, untouched.
    """

    x: np.ndarray
    z: np.ndarray
    s: np.ndarray
    status: str
    solver_status: str
    iterations: int
    solve_time: float
    solver: str
    info: dict = field(default_factory=dict)

    @property
    def solved(self) -> bool:
        return self.status in ("solved", "inaccurate")


Recovery = Callable[[ConicSolution], dict]
"""Maps a solver's (x, z, s) back to mechanical fields; returned by every formulation."""
