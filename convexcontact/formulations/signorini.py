"""Signorini unilateral contact as an exact QP.

    min ½uᵀKu − fᵀu   s.t.  C(N u − g) ≤ 0

with C = diag(w) (node-wise u_N ≤ g) or C = M (Hild's continuous P1 multipliers,
weak non-penetration). The multiplier of the constraint is the nodal pressure
λ_N. Under force control the obstacle's advance δ is one more unknown with the
work −Pδ, and the gap closes by c_i δ.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution, nonnegative
from ..fem.contact import ContactTrace
from .fields import ContactFields


def contact_weights(contact: ContactTrace, non_penetration: str) -> sp.csr_matrix:
    """C: diag(w) for node-wise non-penetration, the boundary mass M for the weak form."""
    if non_penetration == "nodal":
        return sp.diags(contact.weights, format="csr")
    return contact.mass


def normal_constraint(contact: ContactTrace, C: sp.csr_matrix, n: int):
    """Rows (A, b) of C(N u + c δ + offset − g) ≤ 0 over x = (u[, δ])."""
    A = C @ contact.N
    if contact.obstacle_coupling is not None:
        A = sp.hstack([A, sp.csr_matrix(C @ contact.obstacle_coupling[:, None])])
    return sp.csc_matrix(A), C @ (contact.gap - contact.normal_offset)


def elastic_energy(K: sp.spmatrix, f: np.ndarray, contact: ContactTrace):
    """P and q of ½uᵀKu − fᵀu (− Pδ under force control)."""
    if contact.obstacle_coupling is None:
        return sp.csc_matrix(K), -f
    return sp.block_diag([K, sp.csc_matrix((1, 1))], format="csc"), np.append(-f, -contact.obstacle_force)


def split(x: np.ndarray, n: int, contact: ContactTrace):
    """Displacement and obstacle advance from the primal variable."""
    return x[:n], float(x[n]) if contact.obstacle_coupling is not None else 0.0


def signorini(K: sp.spmatrix, f: np.ndarray, contact: ContactTrace, non_penetration: str = "nodal"):
    """The Signorini QP and its recovery map (solution → :class:`ContactFields`)."""
    n = f.size
    P, q = elastic_energy(K, f, contact)
    A, b = normal_constraint(contact, contact_weights(contact, non_penetration), n)
    program = ConicProgram(P, q, A, b, (nonnegative(contact.m),))

    def recover(solution: ConicSolution) -> ContactFields:
        u, advance = split(solution.x, n, contact)
        return ContactFields(u=u, pressure=solution.z[: contact.m], obstacle_advance=advance)

    return program, recover
