"""Signorini contact as an exact QP, Tresca friction as an exact SOCP, normal compliance.

    min ½uᵀKu − fᵀu + Σ_k s_k |(R u)_k|   s.t.  C(N u − g) ≤ 0

C = diag(w) (node-wise u_N ≤ g) or the boundary mass M (Hild's weak form); R the
friction rows of :mod:`convexcontact.fem.friction`. The friction term enters through
epigraph variables, (t_k, (R u)_k) ∈ SOC with cost s_k t_k — no smoothing; in 3-D
(R u)_k has two components and the cone is the exact isotropic SOC(3). With
``epsilon`` the cone is (t_k, (R u)_k, ε ω_k): the regularized sqrt(u_T² + ε²).
Under force control the obstacle's normal advance δ_N (work −P δ_N) and tangential
shift δ_T (work −Q δ_T) are unknowns too. A frictionless scene has no t, no R.

Normal compliance (``compliance`` = (c_N, p), scaled) replaces non-penetration by the
energy Σ w_i c_N/(p+1) e_i^(p+1) over the excess e ≥ u_N − g, e ≥ 0: a quadratic
cost for p = 1, epigraphs (r_i, κ, e_i) ∈ power cone(1/(p+1)) with cost
Σ w_i/(p+1) r_i for p > 1, where κ = c_N^(−1/p) (the excess at unit pressure) keeps r
of the size of e (with (r, 1, e), r = e^(p+1) underflows the solver's tolerances).
The multiplier of w(u_N − g − e) ≤ 0 is again the pressure, now c_N e^p.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution, nonnegative, power, soc
from ..fem.contact import ContactTrace
from ..fem.friction import FrictionPoints
from ..scene.description import SceneError
from .fields import ContactFields


def contact_weights(contact: ContactTrace, non_penetration: str) -> sp.csr_matrix:
    """C: diag(w) for node-wise non-penetration, the boundary mass M for the weak form, diag(ω) G at the
    Gauss points (points × nodes: the only C that is not square)."""
    if non_penetration == "gauss":
        if contact.points is None:
            raise SceneError("contact.non_penetration", "this contact's trace has no Gauss points (they are "
                             "built for a body against a rigid obstacle, when the scene is prepared with that law)",
                             "use 'nodal' or 'weak' for a pair of bodies; prepare the scene with the Gauss-point "
                             "law (cc.prepare), not with Model.with_law")
        return contact.points.C
    if non_penetration == "nodal":
        if contact.multiplier_transform is not None:
            # P2 tetrahedra: the vertex shape functions of a P2 triangle integrate to 0
            raise SceneError("contact.non_penetration", "node-wise contact cannot weigh the nodes whose shape "
                             "functions integrate to zero on Γ_C (vertices of P2 tetrahedra)",
                             "use non_penetration = 'weak' (the boundary mass), or P1 / Q1 / Q2 elements")
        return sp.diags(contact.weights, format="csr")
    return contact.mass


def carrying(rows: sp.spmatrix) -> np.ndarray:
    """Mask of the rows that touch an unknown; the multiplier of an empty row (a contact node
    whose displacement is all prescribed) carries no force, is arbitrary, and is reported as 0."""
    return np.diff(sp.csr_matrix(rows).indptr) > 0


class Layout:
    """Where each unknown sits in x = (u, [δ_N], [δ_T], [t], [e], [r])."""

    def __init__(self, n: int, contact: ContactTrace, friction: FrictionPoints | None, compliance=None,
                 normal_rows: int = 0):
        self.n = n
        self.advance = n if contact.obstacle_coupling is not None else None
        self.shift = n + (self.advance is not None) if contact.tangential_coupling is not None else None
        start = n + (self.advance is not None) + (self.shift is not None)
        self.epigraph = slice(start, start + (friction.count if friction is not None else 0))
        self.excess = slice(self.epigraph.stop, self.epigraph.stop + (normal_rows if compliance else 0))
        powered = compliance is not None and compliance[1] > 1
        self.power = slice(self.excess.stop, self.excess.stop + (normal_rows if powered else 0))
        self.size = self.power.stop

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
    """Rows (A, b) of C(N u + c δ_N + offset [− e]) − C g ≤ 0 (C g: :meth:`ContactTrace.weighted_gap`)."""
    A = sp.hstack([C @ contact.N, sp.csr_matrix((C.shape[0], layout.size - layout.n))]).tocsr()
    if layout.advance is not None:
        A = A + layout.column(layout.advance, C @ contact.obstacle_coupling)
    if layout.excess.stop > layout.excess.start:
        A = A - selector(layout.excess, layout.size, sp.diags(contact.row_weights(C)))
    return A, contact.weighted_gap(C) - C @ contact.normal_offset


def selector(block: slice, size: int, scale: sp.spmatrix | None = None) -> sp.csr_matrix:
    """Rows picking the unknowns of ``block`` (times ``scale``)."""
    count = block.stop - block.start
    pick = sp.csr_matrix((np.ones(count), (np.arange(count), np.arange(block.start, block.stop))), shape=(count, size))
    return pick if scale is None else sp.csr_matrix(scale @ pick)


def compliance_energy(layout: Layout, weights: np.ndarray, compliance):
    """Cost (P diagonal, q) and cone rows (A, b, cones) of Σ w c/(p+1) e^(p+1), e ≥ 0."""
    stiffness, exponent = compliance
    P_diag, q = np.zeros(layout.size), np.zeros(layout.size)
    rows, b, cones = [-selector(layout.excess, layout.size)], [np.zeros(weights.size)], [nonnegative(weights.size)]
    if exponent == 1:
        P_diag[layout.excess] = stiffness * weights
    else:
        q[layout.power] = weights / (exponent + 1)
        count, kappa = weights.size, stiffness ** (-1.0 / exponent)
        epigraph, excess = -selector(layout.power, layout.size), -selector(layout.excess, layout.size)
        order = np.arange(3 * count).reshape(3, count).T.ravel()  # cone i = rows (r_i, κ, e_i)
        rows.append(sp.vstack([epigraph, sp.csr_matrix((count, layout.size)), excess]).tocsr()[order])
        b.append(np.concatenate([np.zeros(count), np.full(count, kappa), np.zeros(count)])[order])
        cones += [power(1.0 / (exponent + 1))] * count
    return P_diag, q, rows, b, cones


def cone_dim(friction: FrictionPoints, epsilon: float | None) -> int:
    """Dimension of a friction cone: (t_k, the d − 1 slip components [, ε ω_k])."""
    return 1 + friction.dim + (epsilon is not None)


def friction_rows(friction: FrictionPoints, layout: Layout, epsilon: float | None):
    """Rows (A, b) of the cones (t_k, (R u + offset − coupling δ_T)_k [, ε ω_k]), interleaved."""
    count, dim = friction.count, cone_dim(friction, epsilon)
    epigraph = sp.csr_matrix(
        (-np.ones(count), (np.arange(count), layout.epigraph.start + np.arange(count))), shape=(count, layout.size)
    )
    slip = sp.hstack([friction.R, sp.csr_matrix((friction.R.shape[0], layout.size - layout.n))]).tocsr()
    if layout.shift is not None:
        slip = slip - layout.column(layout.shift, friction.coupling)
    blocks, offsets = [epigraph, -slip], [np.zeros(count), friction.offset]
    if epsilon is not None:
        blocks.append(sp.csr_matrix((count, layout.size)))
        offsets.append(epsilon * friction.weights)
    # R is component-major, so the stacked rows are dim blocks of count: cone k = rows k, count + k, ...
    order = np.arange(dim * count).reshape(dim, count).T.ravel()
    return sp.vstack(blocks).tocsr()[order], np.concatenate(offsets)[order], [soc(dim)] * count


def primal(
    K: sp.spmatrix,
    f: np.ndarray,
    contact: ContactTrace,
    C: sp.spmatrix,
    friction: FrictionPoints | None = None,
    slip_bound: np.ndarray | None = None,
    epsilon: float | None = None,
    compliance: tuple[float, float] | None = None,
):
    """The primal program, its recovery map and ``bound_update(s) -> {"q": ...}`` for new slip bounds.

    ``compliance`` = (c_N, p) in scaled units switches non-penetration to normal compliance.
    """
    layout = Layout(f.size, contact, friction, compliance, C.shape[0])
    extra_diag = np.zeros(layout.size - layout.n)
    q = np.zeros(layout.size)
    q[: layout.n] = -f
    if layout.advance is not None:
        q[layout.advance] = -contact.obstacle_force
    if layout.shift is not None:
        q[layout.shift] = -contact.obstacle_tangential_force
    A, b = normal_rows(contact, C, layout)
    rows, offsets, cones = [A], [b], [nonnegative(C.shape[0])]
    if compliance is not None:
        P_diag, q_e, rows_e, b_e, cones_e = compliance_energy(layout, contact.row_weights(C), compliance)
        extra_diag, q = P_diag[layout.n :], q + q_e
        rows, offsets, cones = rows + rows_e, offsets + b_e, cones + cones_e
    if friction is not None:
        q[layout.epigraph] = slip_bound
        A_T, b_T, cones_T = friction_rows(friction, layout, epsilon)
        rows, offsets, cones = rows + [A_T], offsets + [b_T], cones + cones_T
    P = sp.block_diag([K, sp.diags(extra_diag)], format="csc")
    program = ConicProgram(P, q, sp.vstack(rows).tocsc(), np.concatenate(offsets), tuple(cones))
    dim = cone_dim(friction, epsilon) if friction is not None else 0
    friction_start = program.n_constraints - (friction.count * dim if friction is not None else 0)  # the last rows
    normal_carries = carrying(C @ contact.N)
    friction_carries = carrying(friction.R) if friction is not None else None

    def recover(solution: ConicSolution) -> ContactFields:
        z = solution.z
        pressure = np.where(normal_carries, z[: C.shape[0]], 0.0)
        traction = None
        if friction is not None:  # the slip components of each cone, back to component-major order
            cones_z = z[friction_start:].reshape(friction.count, dim)[:, 1 : 1 + friction.dim]
            traction = np.where(friction_carries, cones_z.T.ravel(), 0.0)
        return ContactFields(pressure=pressure, friction=traction, **layout.unpack(solution.x))

    def bound_update(s: np.ndarray) -> dict:
        updated = program.q.copy()
        updated[layout.epigraph] = s
        return {"q": updated}

    return program, recover, bound_update
