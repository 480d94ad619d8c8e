"""Active-set polish of an interior-point answer, for programs with polyhedral cones.

An interior-point solver stops at a tolerance relative to the whole problem, so rows
whose forces are small beside the largest (soft subdomains, tiny elements, zero load)
can stay inaccurate. Guessing the active set from the answer (z_i > s_i) and solving
the equality-constrained KKT system gives the exact answer of that guess — the idea of
OSQP's polishing. Rows the interior point left unresolved (z and s both tiny) can make
the first guess wrong, so a few primal-dual active-set rounds follow: violated rows
join, rows with negative multipliers leave. The answer is kept only if it is primal and
dual feasible.

A 2-D second-order cone |s₁| ≤ s₀ (2-D friction) is the pair of half-planes s₀ − s₁ ≥ 0,
s₀ + s₁ ≥ 0, so such programs are polished as the equivalent linear program. Larger
second-order cones (3-D friction) are polished by Newton's method (:mod:`.cone_polish`)
when each cone bounds its own variables, as in the dual contact programs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..conic import ConicProgram, ConicSolution, nonnegative
from .cone_polish import FEASIBLE, bound_form, cone_polish

ROUNDS = 30
"""Active-set rounds before polishing gives up (and the interior-point answer stands). Each is one KKT solve, about
an interior-point iteration: 30 cost at most about one more interior point. The Cattaneo–Mindlin dual at ν = 0.4999
(W's condition 1e11) needed 22 from an AlmostSolved iterate (non-penetration 5e-4); at 10 the Picard map's every
other Tresca step stayed there and the map failed. The second pass (signs on the iterate's scale, the former rule)
keeps the former 10 (:data:`LOOSE_ROUNDS`): a singular W (friction at Gauss points) takes its KKT solves by least
squares, 0.1–0.2 s each, and its strict pass already polishes in 17–28 rounds where it polishes at all."""

LOOSE_ROUNDS = 10
"""Active-set rounds of the polish's second pass (see :data:`ROUNDS`)."""


def kkt_solve(P: sp.spmatrix, q: np.ndarray, A: sp.csr_matrix, b: np.ndarray):
    """(x, z) of P x + Aᵀ z = −q, A x = b, or None when singular or solved too inaccurately.

    When every row of A fixes one variable (bounds: the dual's multipliers), the variables
    left free solve P_FF x_F = −q_F − P_FX x_X alone: on a dense P (a condensed program) a
    Cholesky factorization of P_FF is far cheaper than a sparse LU of the whole KKT matrix.
    """
    n = P.shape[0]
    fixed = A.indices
    if (np.diff(A.indptr) == 1).all() and np.unique(fixed).size == fixed.size and dense(P):
        x = np.zeros(n)
        x[fixed] = b / A.data
        free = np.setdiff1d(np.arange(n), fixed)
        P_dense = P.toarray()
        reduced, rhs = P_dense[np.ix_(free, free)], -q[free] - P_dense[np.ix_(free, fixed)] @ x[fixed]
        try:
            x[free] = sla.cho_solve(sla.cho_factor(reduced), rhs)
        except sla.LinAlgError:
            # singular: multipliers that are not unique (more friction points than nodal DOFs they act
            # on). The system is still consistent at the optimum: take its least-norm solution
            x[free] = sla.lstsq(reduced, rhs)[0]
            if np.abs(reduced @ x[free] - rhs).max(initial=0.0) > FEASIBLE * max(np.abs(rhs).max(initial=0.0), 1.0):
                return None
        z = -(P_dense[fixed] @ x + q[fixed]) / A.data
        return (x, z) if np.isfinite(x).all() and np.isfinite(z).all() else None
    kkt = sp.bmat([[P, A.T], [A, None]], format="csc")
    rhs = np.concatenate([-q, b])
    try:
        lu = spla.splu(kkt)
    except RuntimeError:  # singular: dependent active rows or an unheld rigid motion
        return None
    answer = lu.solve(rhs)
    answer += lu.solve(rhs - kkt @ answer)  # one step of refinement for ill-conditioned K (ν → ½)
    residual = np.abs(rhs - kkt @ answer).max(initial=0.0)
    if not np.isfinite(answer).all() or residual > FEASIBLE * max(np.abs(rhs).max(initial=0.0), 1.0):
        return None  # the KKT system is solved too inaccurately to trust
    return answer[:n], answer[n:]


def dense(P: sp.spmatrix) -> bool:
    """Whether P is a dense block (a condensed program) rather than a sparse FE matrix."""
    n = P.shape[0]
    return n >= 100 and P.nnz >= 0.25 * n * n


def half_planes(program: ConicProgram) -> sp.csr_matrix | None:
    """Row map H taking the slacks of a program with zero, nonnegative and 2-D SOC cones to
    those of its linear equivalent (each SOC pair (s₀, s₁) ↦ (s₀ − s₁, s₀ + s₁)); None if
    a cone is not polyhedral. H Hᵀ = 2 on SOC rows, so H⁻¹ = ½Hᵀ there."""
    diagonal = np.ones(program.n_constraints)
    pairs = []
    for cone, rows in program.blocks():
        if cone.kind == "soc" and cone.dim == 2:
            pairs.append(rows.start)
        elif cone.kind not in ("zero", "nonnegative"):
            return None
    first = np.array(pairs, dtype=int)
    H = sp.lil_matrix(sp.diags(diagonal))
    H[first, first + 1] = -1.0
    H[first + 1, first] = 1.0
    return H.tocsr()


def polishable(program: ConicProgram) -> bool:
    """Whether :func:`polish` applies to the program (it may still fail on a given answer)."""
    return half_planes(program) is not None or (not program.is_linear and bound_form(program) is not None)


def polish(program: ConicProgram, solution: ConicSolution) -> ConicSolution:
    """The polished solution, or ``solution`` itself (the same object) when polishing does not apply or fails."""
    # an "almost solved" answer is polished too: a polished answer is primal and dual feasible with
    # complementarity by construction, i.e. the program's exact optimum, whatever the solver said
    if solution.status not in ("solved", "inaccurate") or not np.isfinite(solution.z).all():
        return solution
    H = half_planes(program)
    if H is None:  # a cone that is not polyhedral: Newton's method if the cones bound their own variables
        form = None if program.is_linear else bound_form(program)
        return solution if form is None else cone_polish(program, solution, form)
    if program.is_linear:
        return _polish_linear(program, solution)
    # the linear equivalent: slacks H s, multipliers H⁻ᵀ z (= ½ H z on pairs, z elsewhere)
    soc_rows = np.asarray(abs(H).sum(axis=1)).ravel() > 1
    half = np.where(soc_rows, 0.5, 1.0)
    cones = tuple(nonnegative(c.dim) if c.kind == "soc" else c for c in program.cones)
    linear = replace(program, A=sp.csr_matrix(H @ program.A), b=H @ program.b, cones=cones)
    # first rows (s₀ − s₁) of the pairs where s₀ or s₁ holds no variable (the dual's balls of radius
    # b₀; the epigraph of a point whose slip is all prescribed): both half-planes active there pin the
    # same variable twice. Elsewhere (t ≥ |R u|) both active is a sticking point, t = R u = 0
    empty = np.diff(sp.csr_matrix(program.A).indptr) == 0
    first = soc_rows & (np.asarray(H.sum(axis=1)).ravel() == 0)
    pairs = np.flatnonzero(first & (empty | np.roll(empty, -1)))
    transformed = replace(solution, z=half * (H @ solution.z), s=H @ solution.s)
    polished = _polish_linear(linear, transformed, pairs)
    if polished is transformed:  # failed (a guess may carry an earlier answer's "polished" flag: not a test)
        return solution
    return replace(polished, z=H.T @ polished.z, s=half * (H.T @ polished.s))


def free_variables(P: sp.spmatrix, q: np.ndarray, A: sp.csr_matrix, equality: np.ndarray) -> np.ndarray:
    """Mask of the variables that have no cost (zero column of P, q_j = 0), appear in no equality,
    and either with one sign in all their rows or only in rows of their own (bounds): any value that
    satisfies their rows is optimal and those rows carry no multiplier (the dual's multipliers of a
    contact node with no free DOF; the friction epigraph t_k ≥ |v_k| of a point with zero slip
    bound). Left in, they make the KKT system singular and the polish fail; they are placed after
    the others are solved for instead."""
    columns = sp.csc_matrix(A)
    P = sp.csc_matrix(P)
    nonzeros = np.concatenate([[0], np.cumsum(P.data != 0)])  # by value: a dense W (formulations/dual.py) stores
    # its exact zeros, which a column's stored entries would count
    costless = (nonzeros[P.indptr[1:]] == nonzeros[P.indptr[:-1]]) & (q == 0)
    in_equality = np.diff(sp.csc_matrix(columns[equality]).indptr) > 0
    signs = sp.csc_matrix(columns.sign())
    one_sign = np.abs(np.asarray(signs.sum(axis=0)).ravel()) == np.diff(signs.indptr)
    own_rows = np.diff(sp.csr_matrix(A).indptr) == 1
    alone = np.asarray(abs(signs[~own_rows]).sum(axis=0)).ravel() == 0
    return costless & ~in_equality & (one_sign | alone) & (np.diff(columns.indptr) > 0)


def place_free(x: np.ndarray, guess: np.ndarray, A: sp.csr_matrix, b: np.ndarray, free: np.ndarray) -> np.ndarray:
    """x with each free variable at its ``guess`` value moved into what its rows A x ≤ b allow, given the others."""
    others = x.copy()
    others[free] = 0.0
    room = b - A @ others  # A_rj x_j ≤ room_r
    block = sp.csc_matrix(A)[:, free]
    for k, j in enumerate(np.flatnonzero(free)):
        rows = block.indices[block.indptr[k]:block.indptr[k + 1]]
        coefficients = block.data[block.indptr[k]:block.indptr[k + 1]]
        limits = room[rows] / coefficients
        lower = limits[coefficients < 0].max(initial=-np.inf)
        upper = limits[coefficients > 0].min(initial=np.inf)
        x[j] = np.clip(guess[j], lower, upper)
    return x


def sign_scale(program: ConicProgram) -> Callable[[np.ndarray], np.ndarray]:
    """x ↦ the rounding in each row's multiplier z = −(P x + q) through A (|A|, |P| and the rows' norms taken once,
    not in every round: a condensed program's P is a dense n × n block): FEASIBLE times it is the most negative a
    multiplier may be in the polish's first, strict rounds. Not the largest multiplier: an inaccurate (AlmostSolved)
    iterate's reach 1.9e5 where a ball's radius is 0, and even the KKT answer's open-node gaps (228) passed a slip of
    −4.4e-9 against its force beside slips of 1e-6 (the Cattaneo–Mindlin dual at ν = 0.4999: the Tresca step's
    friction law at 1e-5). Where W is so ill-conditioned that the KKT solve's own error exceeds it (the same at
    ν = 0.49999, condition 1e11: slips' noise 1e5 times this), the rounds run again judged on the interior point's
    largest multiplier, as before, and the certificate judges their answer (there 9e-8)."""
    A, P, q = abs(sp.csr_matrix(program.A)), abs(program.P), np.abs(program.q)
    norms = np.maximum(np.asarray(A.multiply(A).sum(axis=1)).ravel(), 1e-300)
    return lambda x: (A @ (P @ np.abs(x) + q)) / norms


def _polish_linear(program: ConicProgram, solution: ConicSolution, pairs: np.ndarray = ()) -> ConicSolution:
    """Polish a linear program; ``pairs``: first rows of half-plane pairs b₀ ∓ a x ≥ 0 of which at
    most one is active (both active pin the same variable twice: a singular KKT system)."""
    equality = np.zeros(program.n_constraints, bool)
    for cone, rows in program.blocks():
        equality[rows] = cone.kind == "zero"
    A = sp.csr_matrix(program.A)
    free = free_variables(program.P, program.q, A, equality)
    kept = np.flatnonzero(~free)
    A_kept = A[:, kept]
    touches = np.diff(A_kept.indptr) > 0  # an empty row has no say in the determined variables
    touches &= np.diff(A[:, np.flatnonzero(free)].tocsr().indptr) == 0  # a free variable's rows carry no force
    P_kept, q_kept = sp.csc_matrix(program.P)[kept][:, kept], program.q[kept]
    scale_s = max(np.abs(program.b).max(initial=0.0), np.abs(solution.x).max(initial=0.0), 1.0)
    pairs = np.asarray(pairs, dtype=int)
    loose, rounding = max(np.abs(solution.z).max(initial=0.0), 1.0), sign_scale(program)
    # signs judged against the KKT solve's rounding first, then on the interior point's largest multiplier
    for strict, rounds in ((True, ROUNDS), (False, LOOSE_ROUNDS)):
        active, z = touches & (equality | (solution.z > solution.s)), solution.z
        for _ in range(rounds):
            both = pairs[active[pairs] & active[pairs + 1]]
            active[np.where(z[both] < z[both + 1], both, both + 1)] = False
            answer = kkt_solve(P_kept, q_kept, A_kept[active], program.b[active])
            if answer is None:
                return solution
            x, z = np.zeros(program.n_variables), np.zeros(program.n_constraints)
            x[kept], z[active] = answer
            x = place_free(x, solution.x, A, program.b, free)
            s = np.where(equality, 0.0, program.b - A @ x)
            scale_z = rounding(x) if strict else loose
            violated = touches & ~equality & (s < -FEASIBLE * scale_s)
            negative = active & ~equality & (z < -FEASIBLE * scale_z)
            if not violated.any() and not negative.any():
                return replace(solution, x=x, z=z, s=np.maximum(s, 0.0), status="solved",
                               info={**solution.info, "polished": True})
            active = (active | violated) & ~negative
    return solution
