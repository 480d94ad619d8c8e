"""Derivatives of a contact answer on its active set: the linear algebra, without scene or units.

An answer (u, λ_N, λ_T) of the discrete problem satisfies

    K u − f + Aᵀλ_N − Rᵀλ_T = 0,           A = C N,  h = C(g − o_N),
    A u ≤ h  ⟂  λ_N ≥ 0                    (per row of A),
    λ_T,k = −s_k v_k/‖v_k‖ where v_k ≠ 0,  ‖λ_T,k‖ ≤ s_k where v_k = 0,   v = R u + o,

with s = s⁰ for Tresca and s = L λ_N for Coulomb (L = F G S: the law's own equation, not the Picard map).
Where every contact row and friction point is strictly on one side of its law (:func:`normal_status`,
:func:`friction_status`), the answer is a smooth function of the data and its derivative solves one
sparse linear system (:func:`linearize`): closed rows keep A u = h, open rows keep λ_N = 0, sticking
points keep v = 0, slipping points keep λ_T = −s ê with dλ_T = −ds ê − (s/‖v‖) P⊥ dv (P⊥ = I − êêᵀ:
the projector term of 3-D; in 2-D it vanishes). Rows and points at the edge of their law (a grazing
node: gap = 0 and λ_N = 0; a point at the stick/slip boundary: v = 0 and ‖λ_T‖ = s) make the
derivative one-sided: for each direction of the parameter it solves a small linear complementarity
problem on those rows (:func:`directional`), with the system above eliminated (a Schur complement).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

ENUMERATED = 12
"""Most degenerate rows whose complementarity problem is solved by trying every branch (2¹² small solves):
every consistent branch is found, so a directional derivative that is not unique (Coulomb) is said to be so.
Beyond, Murty's principal pivoting, which finds the one solution of a P-matrix problem (Signorini, Tresca)."""

PIVOTS = 1000
"""Most principal pivots before a complementarity problem beyond :data:`ENUMERATED` is given up."""


class NotDifferentiable(ValueError):
    """The answer has no derivative of the kind asked for here (the message says why and what to do)."""


@dataclass
class Linearization:
    """The answer's active set and the linear system of its derivatives, factorized once.

    ``normal`` (rows of A): open, closed, grazing, held (an empty row: its multiplier is 0).
    ``friction`` (points): stick, slip, smooth (ε-regularized), boundary (stick/slip edge), free
    (bound 0 that no rate moves: λ_T = 0), held. ``direction`` is ê per point (slip direction; at a
    boundary point the traction's λ_T/‖λ_T‖). Unknowns x = (du, dλ_N, dλ_T), λ_T component-major like R;
    ``frames`` is what a point's row multiplies R du (and the offset rate) by, ``along`` puts ê_k on the
    rows of point k (it multiplies ds).
    """

    n: int
    normal: np.ndarray
    friction: np.ndarray | None
    direction: np.ndarray | None
    frames: sp.csr_matrix | None
    along: sp.csr_matrix | None
    flexibility: np.ndarray  # φ of the closed rows (normal compliance; 0 for Signorini)
    matrix: sp.csc_matrix
    slack: sp.csr_matrix  # E: the degenerate rows' slack columns (N × d)
    edge: sp.csr_matrix  # Ψ: the degenerate rows' complementary quantities (d × N)
    solver: spla.SuperLU

    @property
    def degenerate(self) -> int:
        return self.slack.shape[1]

    @property
    def points(self) -> int:
        return 0 if self.friction is None else self.friction.size


@dataclass
class Rates:
    """The data's derivatives along one parameter: of the residual force f − K u (u held), of h, of the slip
    offset o (component-major) and of the bound s⁰ (None: zero)."""

    force: np.ndarray
    gap: np.ndarray
    offset: np.ndarray | None = None
    bound: np.ndarray | None = None


def normal_status(gap: np.ndarray, pressure: np.ndarray, held: np.ndarray, tol: float) -> np.ndarray:
    """open / closed / grazing / held per row from the gap and the pressure, each already over its scale:
    a side is strict where its quantity exceeds ``tol``."""
    status = np.where(pressure > tol, "closed", np.where(gap > tol, "open", "grazing"))
    return np.where(held, "held", status).astype("<U8")


def friction_status(slip: np.ndarray, traction: np.ndarray, bound: np.ndarray, held: np.ndarray, fixed: np.ndarray,
                    tol: float, smooth: bool = False) -> np.ndarray:
    """stick / slip / boundary / free / zero / held / smooth per point; ``slip`` (points × c) and ``traction``,
    ``bound`` over their scales; ``fixed``: points whose bound no rate moves (a Coulomb point over open nodes).
    "zero": bound and slip 0 with a bound that may grow (its derivative is a cone: not taken)."""
    moving = np.linalg.norm(slip, axis=1) > tol
    room = bound - np.linalg.norm(traction, axis=1)
    resting = np.where(room > tol, "stick", np.where(bound > tol, "boundary", np.where(fixed, "free", "zero")))
    status = np.where(moving, "slip", resting) if not smooth else np.full(bound.size, "smooth")
    return np.where(held, "held", status).astype("<U8")


def linearize(K: sp.spmatrix, A: sp.spmatrix, normal: np.ndarray, R: sp.spmatrix | None = None,
              friction: np.ndarray | None = None, slip: np.ndarray | None = None, traction: np.ndarray | None = None,
              bound: np.ndarray | None = None, coupling: sp.spmatrix | None = None,
              epsilon: np.ndarray | None = None, flexibility: np.ndarray | None = None) -> Linearization:
    """The derivative system at the active set ``normal``, ``friction`` (see :class:`Linearization`), factorized.

    ``slip`` v and ``traction`` λ_T are (points × c) in the units of R u; ``bound`` s; ``coupling`` L of
    Coulomb's s = L λ_N; ``epsilon`` the points' ε ω_k of the regularized law |v|_ε = sqrt(‖v‖² + ε²ω²)
    (None: exact); ``flexibility`` φ_i of normal compliance, whose closed rows keep A_i du − φ_i dλ_i = dh_i
    (φ = w/(c p e^(p−1)) for λ = c e^p; None: 0, Signorini).
    """
    if friction is not None and (friction == "zero").any():
        raise NotDifferentiable(f"{(friction == 'zero').sum()} friction points have zero bound and zero slip, "
                                "and their bound may grow: the derivative there is a cone, not implemented")
    n, r = K.shape[0], A.shape[0]
    closed = np.isin(normal, ("closed", "grazing"))
    grazing = np.flatnonzero(normal == "grazing")
    yielding = np.zeros(r) if flexibility is None else np.where(closed, flexibility, 0.0)
    blocks = [[sp.csr_matrix(K), sp.csr_matrix(A.T)],
              [sp.diags(closed.astype(float)) @ A, sp.diags((~closed).astype(float) - yielding)]]
    slack_rows = list(n + grazing)
    edge_columns, edge_values, edge_rows = list(n + grazing), [1.0] * grazing.size, list(range(grazing.size))
    direction = frames = along = None
    coupled = None
    if R is not None:
        p, c = slip.shape
        frame, direction, curvature = point_frames(friction, slip, traction, bound, epsilon)
        frames = point_matrix(frame + curvature)  # what R du (and the offset rate) is multiplied by, per point
        slipping = np.isin(friction, ("slip", "smooth"))
        along = point_columns(np.where(slipping[:, None], direction, 0.0))  # ê_k at the rows of point k (q × p)
        lam = along @ coupling if coupling is not None else None
        keeps = np.tile(~np.isin(friction, ("stick", "boundary")), c).astype(float)
        blocks[0].append(-sp.csr_matrix(R).T)
        blocks[1].append(None)
        blocks.append([frames @ R, lam, sp.diags(keeps)])
        boundary = np.flatnonzero(friction == "boundary")
        slack_rows += list(n + r + boundary)  # the first row of a boundary point's frame is ê (its traction)
        for j in range(c):  # ψ = ds − ê·dλ_T
            edge_rows += list(grazing.size + np.arange(boundary.size))
            edge_columns += list(n + r + j * p + boundary)
            edge_values += list(-direction[boundary, j])
        if coupling is not None:
            coupled = sp.csr_matrix(coupling)[boundary]
    size = n + r + (0 if R is None else R.shape[0])
    degenerate = len(slack_rows)
    edge = sp.csr_matrix((edge_values, (edge_rows, edge_columns)), shape=(degenerate, size))
    if coupled is not None and coupled.shape[0]:
        edge = edge + sp.vstack([sp.csr_matrix((grazing.size, size)),
                                 sp.hstack([sp.csr_matrix((coupled.shape[0], n)), coupled,
                                            sp.csr_matrix((coupled.shape[0], size - n - r))])])
    slack = sp.csr_matrix((-np.ones(degenerate), (slack_rows, np.arange(degenerate))), shape=(size, degenerate))
    matrix = sp.bmat(blocks, format="csc")
    try:
        solver = spla.splu(matrix)
    except RuntimeError as error:  # "Factor is exactly singular"
        raise NotDifferentiable(f"the active set's linear system is singular ({error}): its multipliers are not "
                                "unique (more active rows than they can hold apart)") from None
    return Linearization(n, normal, friction, direction, frames, along, yielding, matrix, slack, sp.csr_matrix(edge),
                         solver)


def point_frames(friction: np.ndarray, slip: np.ndarray, traction: np.ndarray, bound: np.ndarray,
                 epsilon: np.ndarray | None):
    """Per point (p × c × c): the frame whose rows a sticking or boundary point keeps (identity; at a boundary
    point ê = λ_T/‖λ_T‖ first, then its orthogonal complement), the direction ê (slip, or traction at a
    boundary), and the curvature s ∂(v/‖v‖)/∂v of a slipping point (s/|v|_ε (I − v vᵀ/|v|_ε²) regularized)."""
    p, c = slip.shape
    size = np.linalg.norm(slip, axis=1)
    strength = np.linalg.norm(traction, axis=1)
    direction = np.zeros((p, c))
    moving = size > 0
    direction[moving] = slip[moving] / size[moving, None]
    edge = friction == "boundary"
    direction[edge] = traction[edge] / strength[edge, None]
    frame = np.zeros((p, c, c))
    frame[friction == "stick"] = np.eye(c)
    frame[edge, 0] = direction[edge]
    if c == 2:
        frame[edge, 1] = np.column_stack([-direction[edge, 1], direction[edge, 0]])
    curvature = np.zeros((p, c, c))
    if epsilon is not None:
        smooth = np.sqrt(size**2 + epsilon**2)
        curvature = (bound / smooth)[:, None, None] * (np.eye(c) - slip[:, :, None] * slip[:, None, :]
                                                       / smooth[:, None, None] ** 2)
        direction = slip / smooth[:, None]  # dλ_T = −ds v/|v|_ε − s J dv
    elif c == 2:
        sliding = friction == "slip"
        outer = direction[:, :, None] * direction[:, None, :]
        scale = np.divide(bound, size, out=np.zeros(p), where=sliding)
        curvature = scale[:, None, None] * (np.eye(2) - outer) * sliding[:, None, None]
    return frame, direction, curvature


def point_matrix(blocks: np.ndarray) -> sp.csr_matrix:
    """The (p·c × p·c) matrix, component-major, acting on each point's c components by its (c × c) block."""
    p, c, _ = blocks.shape
    a, b = np.meshgrid(np.arange(c), np.arange(c), indexing="ij")
    rows = (a[None] * p + np.arange(p)[:, None, None]).ravel()
    columns = (b[None] * p + np.arange(p)[:, None, None]).ravel()
    return sp.csr_matrix((blocks.ravel(), (rows, columns)), shape=(p * c, p * c))


def point_columns(vectors: np.ndarray) -> sp.csr_matrix:
    """The (p·c × p) matrix putting point k's vector (c components) at its rows, component-major."""
    p, c = vectors.shape
    rows = (np.arange(c)[None] * p + np.arange(p)[:, None]).ravel()
    return sp.csr_matrix((vectors.ravel(), (rows, np.repeat(np.arange(p), c))), shape=(p * c, p))


def right_side(linear: Linearization, rates: Rates) -> np.ndarray:
    """The right-hand side of :func:`linearize`'s system for the data rates ``rates``."""
    closed = np.isin(linear.normal, ("closed", "grazing"))
    parts = [rates.force, np.where(closed, rates.gap, 0.0)]
    if linear.friction is not None:
        p, c = linear.direction.shape
        offset = np.zeros(p * c) if rates.offset is None else rates.offset
        bound = np.zeros(p) if rates.bound is None else rates.bound
        if (bound[linear.friction == "free"] != 0).any():
            raise NotDifferentiable("a friction point with zero bound and zero slip has a bound that moves with this "
                                    "parameter: its derivative is a cone, not implemented")
        parts.append(-(linear.frames @ offset) - linear.along @ bound)
    return np.concatenate(parts)


def bound_rate(linear: Linearization, rates: Rates) -> np.ndarray:
    """ψ⁰: the degenerate rows' complementary quantities' data part (ds⁰ at boundary points)."""
    grazing = int((linear.normal == "grazing").sum())
    if linear.friction is None:
        return np.zeros(grazing)
    bound = np.zeros(linear.points) if rates.bound is None else rates.bound
    return np.concatenate([np.zeros(grazing), bound[linear.friction == "boundary"]])


def directional(linear: Linearization, rates: Rates, sign: float) -> np.ndarray | None:
    """The derivative x of the answer as the parameter moves by ``sign`` (±1): one solve where nothing is
    degenerate, else with the complementarity problem of the degenerate rows; None where that problem has no
    solution or several (Coulomb: the answer may branch)."""
    base = linear.solver.solve(right_side(linear, rates))
    if linear.degenerate == 0:
        return sign * base
    lifts = linear.solver.solve(linear.slack.toarray())
    Q = linear.edge @ lifts
    q = sign * (linear.edge @ base + bound_rate(linear, rates))
    slack = complementary(Q, q)
    return None if slack is None else sign * base + lifts @ slack


def complementary(Q: np.ndarray, q: np.ndarray) -> np.ndarray | None:
    """The w ≥ 0 with z = q + Q w ≥ 0, wᵀz = 0, if there is exactly one (None: none or several)."""
    if q.size > ENUMERATED:
        return pivoting(Q, q)
    found = []
    for size in range(q.size + 1):
        for branch in itertools.combinations(range(q.size), size):
            w = branch_slack(Q, q, np.isin(np.arange(q.size), branch))
            if w is None or not solves(Q, q, w):
                continue
            if not any(np.abs(w - other).max() <= ROUNDOFF * slack_scale(Q, q, w, other) for other in found):
                found.append(np.maximum(w, 0.0))
    return found[0] if len(found) == 1 else None


ROUNDOFF = 1e-9
"""Relative round-off of the degenerate rows' small dense systems: what a sign or a difference is judged against."""


def branch_slack(Q: np.ndarray, q: np.ndarray, basis: np.ndarray) -> np.ndarray | None:
    """w with z_basis = 0 (w positive there) and w = 0 elsewhere; None where that block is singular."""
    w = np.zeros(q.size)
    if basis.any():
        try:
            w[basis] = np.linalg.solve(Q[np.ix_(basis, basis)], -q[basis])
        except np.linalg.LinAlgError:
            return None
    return w


def slack_scale(Q: np.ndarray, q: np.ndarray, *slacks: np.ndarray) -> float:
    """The size of a slack: its own, or what q asks of Q."""
    return max(*(np.abs(w).max(initial=0.0) for w in slacks), np.abs(q).max(initial=0.0)
               / max(np.abs(Q).max(initial=0.0), 1e-300), 1e-300)


def solves(Q: np.ndarray, q: np.ndarray, w: np.ndarray) -> bool:
    """Whether w ≥ 0 and z = q + Q w ≥ 0 within round-off (complementarity holds by construction)."""
    z_scale = max(np.abs(q).max(initial=0.0), np.abs(Q).max(initial=0.0) * np.abs(w).max(initial=0.0), 1e-300)
    return (w.min(initial=0.0) >= -ROUNDOFF * slack_scale(Q, q, w)
            and (q + Q @ w).min(initial=0.0) >= -ROUNDOFF * z_scale)


def pivoting(Q: np.ndarray, q: np.ndarray) -> np.ndarray | None:
    """Murty's least-index principal pivoting: finite for a P-matrix Q; None if it does not end.

    Written by hand: scipy has no complementarity solver, and Q (edges times lifts) need not be symmetric, so the
    project's conic solvers (symmetric P) cannot pose it as a QP."""
    basis = np.zeros(q.size, bool)  # w_i basic (z_i = 0)
    for _ in range(PIVOTS):
        w = branch_slack(Q, q, basis)
        if w is None:
            return None
        if solves(Q, q, w):
            return np.maximum(w, 0.0)
        z, tol = q + Q @ w, ROUNDOFF * slack_scale(Q, q, w)
        bad = np.flatnonzero(np.where(basis, w < -tol, z < -tol * np.abs(Q).max(initial=1.0)))
        basis[bad[0]] = ~basis[bad[0]]
    return None
