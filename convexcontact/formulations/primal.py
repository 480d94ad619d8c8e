"""Signorini contact as an exact QP, and Tresca friction as an exact SOCP.

    min ½uᵀKu − fᵀu + Σ_k s_k |(R u)_k|   s.t.  C(N u − g) ≤ 0

C = diag(w) (node-wise u_N ≤ g) or the boundary mass M (Hild's weak form); R the
friction rows of :mod:`convexcontact.fem.friction`. The friction term enters through
epigraph variables, (t_k, (R u)_k) ∈ SOC with cost s_k t_k — no smoothing. With
``epsilon`` the cone is (t_k, (R u)_k, ε ω_k): the regularized sqrt(u_T² + ε²).
Under force control the obstacle's normal advance δ_N (work −P δ_N) and tangential
shift δ_T (work −Q δ_T) are unknowns too. A frictionless scene has no t, no R.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution, nonnegative, soc
from ..fem.contact import ContactTrace
from ..fem.friction import FrictionPoints
from .fields import ContactFields


def contact_weights(contact: ContactTrace, non_penetration: str) -> sp.csr_matrix:
    """C: diag(w) for node-wise non-penetration, the boundary mass M for the weak form."""
    if non_penetration == "nodal":
        return sp.diags(contact.weights, format="csr")
    return contact.mass


def carrying(rows: sp.spmatrix) -> np.ndarray:
    """Mask of the rows that touch an unknown; the multiplier of an empty row (a contact node
    whose displacement is all prescribed) carries no force, is arbitrary, and is reported as 0."""
    return np.diff(sp.csr_matrix(rows).indptr) > 0


class Layout:
    """Where each unknown sits in x = (u, [δ_N], [δ_T], [t])."""

    def __init__(self, n: int, contact: ContactTrace, friction: FrictionPoints | None):
        self.n = n
        self.advance = n if contact.obstacle_coupling is not None else None
        self.shift = n + (self.advance is not None) if contact.tangential_coupling is not None else None
        start = n + (self.advance is not None) + (self.shift is not None)
        self.epigraph = slice(start, start + (friction.count if friction is not None else 0))
        self.size = self.epigraph.stop

    def column(self, index: int | None, values: np.ndarray) -> sp.csr_matrix:
        """A sparse block holding ``values`` in column ``index`` (empty when index is None)."""
        column = sp.lil_matrix((values.size, self.size))
        if index is not None:
            column[:, index] = values[:, None]
        return column.tocsr()

    def unpack(self, x: np.ndarray) -> dict:
        return {
            "u": x[: self.n],
            "obstacle_advance": float(x[self.advance]) if self.advance is not None else 0.0,
            "obstacle_shift": float(x[self.shift]) if self.shift is not None else 0.0,
        }


def normal_rows(contact: ContactTrace, C: sp.spmatrix, layout: Layout):
    """Rows (A, b) of C(N u + c δ_N + offset − g) ≤ 0."""
    A = sp.hstack([C @ contact.N, sp.csr_matrix((contact.m, layout.size - layout.n))]).tocsr()
    if layout.advance is not None:
        A = A + layout.column(layout.advance, C @ contact.obstacle_coupling)
    return A, C @ (contact.gap - contact.normal_offset)


def friction_rows(friction: FrictionPoints, layout: Layout, epsilon: float | None):
    """Rows (A, b) of the cones (t_k, (R u + offset − coupling δ_T)_k [, ε ω_k]), interleaved."""
    count, dim = friction.count, 2 if epsilon is None else 3
    epigraph = sp.csr_matrix(
        (-np.ones(count), (np.arange(count), layout.epigraph.start + np.arange(count))), shape=(count, layout.size)
    )
    slip = sp.hstack([friction.R, sp.csr_matrix((count, layout.size - layout.n))]).tocsr()
    if layout.shift is not None:
        slip = slip - layout.column(layout.shift, friction.coupling)
    blocks, offsets = [epigraph, -slip], [np.zeros(count), friction.offset]
    if epsilon is not None:
        blocks.append(sp.csr_matrix((count, layout.size)))
        offsets.append(epsilon * friction.weights)
    order = np.arange(dim * count).reshape(dim, count).T.ravel()  # block k = rows k, count + k, ...
    return sp.vstack(blocks).tocsr()[order], np.concatenate(offsets)[order], [soc(dim)] * count


def primal(
    K: sp.spmatrix,
    f: np.ndarray,
    contact: ContactTrace,
    C: sp.spmatrix,
    friction: FrictionPoints | None = None,
    slip_bound: np.ndarray | None = None,
    epsilon: float | None = None,
):
    """The primal program, its recovery map and ``bound_update(s) -> {"q": ...}`` for new slip bounds."""
    layout = Layout(f.size, contact, friction)
    P = sp.block_diag([K, sp.csc_matrix((layout.size - layout.n,) * 2)], format="csc")
    q = np.zeros(layout.size)
    q[: layout.n] = -f
    if layout.advance is not None:
        q[layout.advance] = -contact.obstacle_force
    if layout.shift is not None:
        q[layout.shift] = -contact.obstacle_tangential_force
    A, b = normal_rows(contact, C, layout)
    cones = [nonnegative(contact.m)]
    if friction is not None:
        q[layout.epigraph] = slip_bound
        A_T, b_T, cones_T = friction_rows(friction, layout, epsilon)
        A, b, cones = sp.vstack([A, A_T]), np.concatenate([b, b_T]), cones + cones_T
    program = ConicProgram(P, q, sp.csc_matrix(A), b, tuple(cones))
    dim = 2 if epsilon is None else 3
    normal_carries = carrying(C @ contact.N)
    friction_carries = carrying(friction.R) if friction is not None else None

    def recover(solution: ConicSolution) -> ContactFields:
        z = solution.z
        pressure = np.where(normal_carries, z[: contact.m], 0.0)
        traction = np.where(friction_carries, z[contact.m + 1 :: dim], 0.0) if friction is not None else None
        return ContactFields(pressure=pressure, friction=traction, **layout.unpack(solution.x))

    def bound_update(s: np.ndarray) -> dict:
        updated = program.q.copy()
        updated[layout.epigraph] = s
        return {"q": updated}

    return program, recover, bound_update
