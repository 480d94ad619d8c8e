"""Newton's method on a plastic step's optimality system, from the interior point's answer (docs/plasticity.md).

The interior point leaves the step's equilibrium at about 1e-6 of the load near a limit state (P2 punch, Clarabel
at tol 1e-10 to 1e-12). At fixed u the plastic strain is the radial return's closed form, so the step's optimality
system is, in u and the pressures z_A of the active contact rows A,

    K u − G α(u) − f + A_Aᵀ z_A = 0,    A_A u = b_A,

semismooth in u, its Jacobian K − Gᵀ-weighted consistent tangent (the Hessian of the convex step energy in u).
From the interior point's u and active set, Newton's steps end at the exact discrete answer in a few sparse
solves; the active set is corrected by the Signorini natural map (a primal-dual active set round) until it settles.
Built for Signorini and 2-D exact Tresca friction (sticking points: equalities R_S u + o_S = 0; slipping points:
their traction ±s fixed) against a rigid obstacle under displacement control (no compliance, no force control, no
3-D friction: their rows are not equalities of u alone); the answer is kept only if it is feasible and settled.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..fem.plasticity import PlasticPoints
from ..formulations.fields import ContactFields
from ..formulations.primal import carrying
from ..results.plastic_state import radial_return

ROUNDS, STEPS, LINE_SEARCH = 5, 12, 12
"""Active-set rounds, Newton steps in each, halvings of a step."""
CONVERGED = 1e-12
"""Largest equilibrium residual, relative to the largest nodal force, at which Newton stops."""


def applies(model) -> bool:
    """Signorini (or 2-D exact Tresca) against a rigid obstacle under displacement control."""
    contact, friction = model.fem.contact, model.friction
    planar = friction is None or (friction.dim == 1 and model.epsilon is None and friction.coupling is None)
    return planar and model.compliance is None and contact.obstacle_coupling is None


def tangent(points: PlasticPoints, u_full, old, radius, viscosity) -> tuple[np.ndarray, sp.spmatrix]:
    """Δα of the radial return at u (:func:`~convexcontact.results.plastic_state.radial_return`) and its derivative
    ∂Δα/∂(Πᵀε) per point, block-diagonal: 2μ/(2μ + η_p/Δt) [(1 − r/‖s*‖)(I − nnᵀ) + nnᵀ] where the point flows,
    0 elsewhere."""
    k = points.components
    trial = (np.repeat(points.shear, k) * (points.deviatoric @ u_full - old)).reshape(-1, k)
    size = np.linalg.norm(trial, axis=1)
    flowing = np.isfinite(radius) & (size > radius)
    ratio = np.divide(radius, size, out=np.ones_like(size), where=flowing)
    normal = trial / np.where(size > 0, size, 1.0)[:, None]
    scale = points.shear / (points.shear + viscosity)
    outer = normal[:, :, None] * normal[:, None, :]
    blocks = scale[:, None, None] * ((1.0 - ratio)[:, None, None] * (np.eye(k) - outer) + outer)
    blocks *= flowing[:, None, None]
    count = blocks.shape[0]
    return radial_return(points, u_full, old, radius, viscosity), sp.bsr_matrix((blocks, np.arange(count), np.arange(count + 1)),
                                            shape=(count * k, count * k)).tocsr()


def polish(model, points: PlasticPoints, coupling: sp.spmatrix, old, radius, viscosity, fields: ContactFields,
           rounds: int = ROUNDS):
    """The exact answer of the step from ``fields`` (the interior point's, scaled) and the Newton steps it took, or
    None if Newton does not settle on a feasible one within ``rounds`` active-set rounds."""
    fem, C, friction = model.fem, model.C, model.friction
    contact = fem.contact
    # the contact rows E (normal: C N; friction: −R) with E u ≤ e (normal) or E u = e (sticking), multipliers y whose
    # force is Eᵀy: y = (pressures, friction tractions λ_T)
    A = (C @ contact.N).tocsr()
    m = A.shape[0]
    E = sp.vstack([A] + ([-friction.R] if friction else []), format="csr")
    e = np.concatenate([contact.weighted_gap(C) - C @ contact.normal_offset] + ([friction.offset] if friction else []))
    weights = contact.row_weights(C)
    bound = model.slip_bound if friction else np.zeros(0)
    rows = carrying(E)
    G = coupling[fem.free]
    force = max(np.abs(fem.f).max(initial=0.0), np.abs(fem.K @ fields.u).max(), contact.weights.max())

    def sets(u, y):
        """Active rows (closed nodes, sticking points) and the multipliers fixed by the law (slipping points' ±s),
        by the natural maps of Signorini's and Tresca's laws."""
        active = rows & np.concatenate([y[:m] > (e[:m] - A @ u) / weights, np.zeros(E.shape[0] - m, bool)])
        fixed = np.zeros_like(y)
        if friction:
            trial = y[m:] + (E[m:] @ u - e[m:]) / friction.weights  # λ_T − v, v = (R u + o)/ω the slip
            stick = np.abs(trial) < bound
            active[m:] = rows[m:] & stick
            fixed[m:] = np.where(rows[m:] & ~stick, bound * np.sign(trial), 0.0)
        return active, fixed

    def residual(u, y, active):
        """The optimality system's residual (equilibrium over the force scale, then the active rows' gaps) at u, y."""
        increment, M = tangent(points, fem.full(u), old, radius, viscosity)
        equilibrium = fem.K @ u - G @ (old + increment) - fem.f + E.T @ y
        return np.concatenate([equilibrium / force, e[active] - E[active] @ u]), M

    u = fields.u.copy()
    y = np.where(rows, np.concatenate([fields.pressure] + ([fields.friction] if friction else [])), 0.0)
    (active, fixed), steps = sets(u, y), 0
    y = np.where(active, y, fixed)
    for _ in range(rounds):
        r, M = residual(u, y, active)
        for _ in range(STEPS):
            if np.abs(r).max() <= CONVERGED:
                break
            J = fem.K - G @ M @ points.deviatoric[:, fem.free]
            kkt = sp.bmat([[J, E[active].T], [E[active], None]], format="csc")
            rhs = np.concatenate([-(r[: u.size] * force - E[active].T @ y[active]), r[u.size:]])
            step = spla.splu(kkt).solve(rhs)
            direction, target = step[: u.size], fixed.copy()
            target[active] = step[u.size:]
            steps += 1
            for length in 0.5 ** np.arange(LINE_SEARCH):  # backtracking on ‖r‖: the points' flow switches on and off
                trial_u, trial_y = u + length * direction, y + length * (target - y)
                trial, trial_M = residual(trial_u, trial_y, active)
                if np.linalg.norm(trial) < (1 - 1e-4 * length) * np.linalg.norm(r):
                    break
            u, y, r, M = trial_u, trial_y, trial, trial_M
        if np.abs(r).max() > CONVERGED:
            return None  # Newton does not settle on these sets
        settled, law = sets(u, y)
        slack = (e[:m] - A @ u) / weights
        feasible = slack[rows[:m]].min(initial=0.0) >= -CONVERGED and y[:m].min(initial=0.0) >= 0 and \
            (np.abs(y[m:]) <= bound * (1 + CONVERGED)).all()
        if np.array_equal(settled, active) and np.array_equal(law, fixed) and feasible:
            return ContactFields(u=u, pressure=y[:m], friction=y[m:] if friction else None), steps
        active, fixed = settled, law
        y = np.where(active, y, fixed)
    return None
