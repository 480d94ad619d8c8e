"""The mixed multiplier saddle point, solved as its dual over the contact multipliers.

With r = (λ_N, λ_T) and B = [C N; −R] (C, R as in :mod:`.primal`), eliminating u
from the Lagrangian ½uᵀKu − fᵀu + rᵀ(B u + c) with one factorization of K gives

    min ½ rᵀ W r − rᵀ h,   W = B K⁻¹ Bᵀ,   h = B K⁻¹ f + c,
    s.t. λ_N ≥ 0,  (s_k, λ_T,k) ∈ SOC  (‖λ_T,k‖ ≤ s_k; λ_T,k ∈ R^(d−1), component-major),

and u = K⁻¹(f − Bᵀ r). With C = M and R = M T this is Hild's mixed method with
continuous P1 multipliers; with C = diag(w) its node-wise (lumped) counterpart. The
ε-regularized friction adds μ_k with cost −ε ω_k μ_k and (s_k, λ_T,k, μ_k) ∈ SOC.
Force control adds the equalities Σ (C c)ᵢ λ_N,i = P and couplingᵀ λ_T = Q; their
multipliers are minus the obstacle's advance and shift.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution, dense_matrix, nonnegative, soc, zero
from ..fem.contact import ContactTrace
from ..fem.factorization import Factorization, factorize
from ..fem.friction import FrictionPoints
from ..scene.description import SceneError
from .fields import ContactFields
from .primal import carrying


def dual(
    K: sp.spmatrix,
    f: np.ndarray,
    contact: ContactTrace,
    C: sp.spmatrix,
    friction: FrictionPoints | None = None,
    slip_bound: np.ndarray | None = None,
    epsilon: float | None = None,
    compliance: tuple[float, float] | None = None,
    factorization: Factorization | None = None,
    matrix_free: bool = False,
    coarse: Callable | None = None,
):
    """The dual program, its recovery map and ``bound_update(s) -> {"b": ...}``.

    ``matrix_free``: P is W as an operator (:meth:`~convexcontact.fem.factorization.Factorization.delassus`),
    never formed; for exact friction only; ``coarse``: functions of the body beyond the slab that preconditions it
    (:func:`~convexcontact.fem.factorization.slab`)."""
    if compliance is not None:
        raise SceneError("formulation", "normal compliance is formulated in the primal only", "use formulation='primal'")
    if matrix_free and epsilon is not None:
        raise SceneError("formulation", "the ε-regularized friction has no matrix-free dual",
                         "use formulation='dual' or 'primal'")
    factorization = factorization or factorize(K)
    m = C.shape[0]  # normal multipliers: one per node, or per Gauss point
    count = friction.count if friction is not None else 0
    tangential = count * friction.dim if friction is not None else 0  # λ_T unknowns
    extra = count if epsilon is not None else 0
    B = contact_rows(contact, C, friction)
    c = np.concatenate([C @ contact.normal_offset - contact.weighted_gap(C)] + ([-friction.offset] if count else []))
    Kf = factorization.solve(f)
    size = m + tangential + extra
    if matrix_free:
        P = factorization.delassus(B, K, coarse)
    elif extra:
        P = sp.block_diag([sp.csc_matrix(factorization.schur(B)), sp.csc_matrix((extra, extra))], format="csc")
    else:  # W alone where there is no μ block: block_diag would copy it (a pair's W at 10⁵ DOFs: 25 MB)
        P = dense_matrix(factorization.schur(B))
    q = np.concatenate([-(B @ Kf + c), -epsilon * friction.weights if extra else np.zeros(0)])

    rows, b, cones = [], [], []
    if contact.obstacle_coupling is not None:
        rows.append(sp.csr_matrix(np.concatenate([C @ contact.obstacle_coupling, np.zeros(size - m)])[None, :]))
        b.append([contact.obstacle_force])
    if contact.tangential_coupling is not None:
        rows.append(sp.csr_matrix(np.concatenate([np.zeros(m), friction.coupling, np.zeros(extra)])[None, :]))
        b.append([contact.obstacle_tangential_force])
    equalities = len(rows)
    if equalities:
        cones.append(zero(equalities))
    rows.append(-sp.eye(m, size, format="csr"))
    b.append(np.zeros(m))
    cones.append(nonnegative(m))
    dim = 1 + friction.dim + (epsilon is not None) if count else 0
    if count:
        # cone k: (s_k, λ_T,k components, [μ_k]); the unknowns after λ_N are blocks of count
        pick = [sp.csr_matrix((count, size))] + [-sp.eye(count, size, m + j * count) for j in range(dim - 1)]
        order = np.arange(dim * count).reshape(dim, count).T.ravel()
        rows.append(sp.vstack(pick).tocsr()[order])
        b.append(np.concatenate([slip_bound, np.zeros((dim - 1) * count)])[order])
        cones += [soc(dim)] * count

    last: list = [None, None]  # the load and displacement of the last gradient

    def displacement(r: np.ndarray, handed: bool = False) -> np.ndarray:
        """K⁻¹(f − Bᵀr); the last gradient's solve where its load is the same, as the recovery's load is where
        newton-cg stopped on a fresh gradient (one solve of four on the 2-D pair's Signorini at 10⁵ DOFs). ``handed``:
        the displacement leaves with the answer's fields, the cache with it."""
        load = f - B.T @ r
        u = last[1] if last[0] is not None and np.array_equal(load, last[0]) else factorization.solve(load)
        last[:] = (None, None) if handed else (load, u)
        return u

    def gradient(x: np.ndarray) -> np.ndarray:
        """W x + q as −(B u + c), u = K⁻¹(f − Bᵀx) the displacement the answer's fields recover. W x and q cancel
        where the loads bend a body its contact holds up: on a strip 400 : 1 clamped at its ends (2·10³ DOFs) the
        load alone would move it ‖K⁻¹f‖ = 9·10⁵ where it moves 2·10⁻³, and the sum's rounding (~1e-11) stood for
        the gradient where the certificate's gaps need 1e-13; f − Bᵀx (loads and contact forces on nodes of their
        own) loses nothing (docs/performance.md, "The clamped strip's certificates")."""
        return np.concatenate([-(B @ displacement(x[:m + tangential]) + c), q[m + tangential:]])  # W's μ block is 0

    program = ConicProgram(P, q, sp.vstack(rows).tocsc(), np.concatenate(b), tuple(cones), gradient=gradient)
    bound_rows = equalities + m + np.arange(count) * dim
    carries = carrying(B)

    def recover(solution: ConicSolution) -> ContactFields:
        r = np.where(carries, solution.x[: m + tangential], 0.0)
        motion = iter(-solution.z[:equalities])
        return ContactFields(
            u=displacement(r, handed=True),
            pressure=r[:m],
            friction=r[m:] if count else None,
            obstacle_advance=float(next(motion)) if contact.obstacle_coupling is not None else 0.0,
            obstacle_shift=float(next(motion)) if contact.tangential_coupling is not None else 0.0,
        )

    def bound_update(s: np.ndarray) -> dict:
        updated = program.b.copy()
        updated[bound_rows] = s
        return {"b": updated}

    return program, recover, bound_update


def contact_rows(contact: ContactTrace, C: sp.spmatrix, friction: FrictionPoints | None) -> sp.csr_matrix:
    """B: the dual's rows over the free DOFs, the weighted normal rows C N, then the friction rows −R."""
    return sp.vstack([C @ contact.N] + ([-friction.R] if friction is not None else [])).tocsr()


def normal_multipliers(program: ConicProgram, C: sp.spmatrix, contact: ContactTrace) -> sp.csr_matrix:
    """λ_N, as the recovery reports it, as a linear map of the dual's unknowns: their first m, 0 at a row that
    carries nothing."""
    m = C.shape[0]
    return sp.diags(carrying(C @ contact.N).astype(float)) @ sp.eye(m, program.n_variables, format="csr")


def stick_guess(program: ConicProgram, frictionless: ConicSolution, contact: ContactTrace) -> ConicSolution:
    """A first guess for the frictional dual ``program`` from the answer of its frictionless counterpart
    (the same trace without the tangential force): its pressures and obstacle advance, no friction
    multipliers (every point sticks). The rows of both programs begin alike: the obstacle's force
    equality, [the tangential force's], λ_N ≥ 0."""
    m, obstacle = contact.m, int(contact.obstacle_coupling is not None)
    equalities = obstacle + (contact.tangential_coupling is not None)
    x, z = np.zeros(program.n_variables), np.zeros(program.n_constraints)
    x[:m] = frictionless.x[:m]
    z[:obstacle] = frictionless.z[:obstacle]
    z[equalities: equalities + m] = frictionless.z[obstacle: obstacle + m]
    return replace(frictionless, x=x, z=z, s=program.b - program.A @ x, status="inaccurate", info={})
