"""Newton's method on a plastic step's optimality system, from the interior point's answer (docs/plasticity.md).

The interior point leaves the step's equilibrium at about 1e-6 of the load near a limit state (P2 punch, Clarabel
at tol 1e-10 to 1e-12). At fixed u the plastic strain is the radial return's closed form, so the step's optimality
system is, in u and the pressures z_A of the active contact rows A,

    K u − G α(u) − f + A_Aᵀ z_A = 0,    A_A u = b_A,

semismooth in u, its Jacobian K − Gᵀ-weighted consistent tangent (the Hessian of the convex step energy in u).
From the interior point's u and active set, Newton's steps end at the exact discrete answer in a few sparse
solves; the active set is corrected by the Signorini natural map (a primal-dual active set round) until it settles.
Built for Signorini against a rigid obstacle under displacement control (no friction, no compliance, no force
control: their rows are not equalities of u alone); the answer is kept only if it is feasible and its residual
smaller.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..fem.plasticity import PlasticPoints
from ..formulations.fields import ContactFields
from ..formulations.primal import carrying

ROUNDS, STEPS, LINE_SEARCH = 5, 12, 12
"""Active-set rounds, Newton steps in each, halvings of a step."""
CONVERGED = 1e-12
"""Largest equilibrium residual, relative to the largest nodal force, at which Newton stops."""


def applies(model) -> bool:
    contact = model.fem.contact
    return model.friction is None and model.compliance is None and contact.obstacle_coupling is None


def tangent(points: PlasticPoints, u_full, old, radius, viscosity) -> tuple[np.ndarray, sp.spmatrix]:
    """Δα of the radial return at u and its derivative ∂Δα/∂(Πᵀε) per point, block-diagonal:
    2μ/(2μ + η_p/Δt) [(1 − r/‖s*‖)(I − nnᵀ) + nnᵀ] where the point flows, 0 elsewhere."""
    k = points.components
    trial = (np.repeat(points.shear, k) * (points.deviatoric @ u_full - old)).reshape(-1, k)
    size = np.linalg.norm(trial, axis=1)
    flowing = np.isfinite(radius) & (size > radius)
    ratio = np.divide(radius, size, out=np.ones_like(size), where=flowing)
    normal = trial / np.where(size > 0, size, 1.0)[:, None]
    scale = points.shear / (points.shear + viscosity)
    increment = ((scale * (1.0 - ratio) / points.shear)[:, None] * trial) * flowing[:, None]
    outer = normal[:, :, None] * normal[:, None, :]
    blocks = scale[:, None, None] * ((1.0 - ratio)[:, None, None] * (np.eye(k) - outer) + outer)
    blocks *= flowing[:, None, None]
    count = blocks.shape[0]
    return increment.ravel(), sp.bsr_matrix((blocks, np.arange(count), np.arange(count + 1)),
                                            shape=(count * k, count * k)).tocsr()


def polish(model, points: PlasticPoints, coupling: sp.spmatrix, old, radius, viscosity, fields: ContactFields,
           rounds: int = ROUNDS):
    """The exact answer of the step from ``fields`` (the interior point's, scaled) and the Newton steps it took, or
    None if Newton does not settle on a feasible one within ``rounds`` active-set rounds."""
    fem, C = model.fem, model.C
    contact = fem.contact
    A = (C @ contact.N).tocsr()
    b = contact.weighted_gap(C) - C @ contact.normal_offset
    weights, rows = contact.row_weights(C), carrying(A)
    G = coupling[fem.free]
    force = max(np.abs(fem.f).max(initial=0.0), np.abs(fem.K @ fields.u).max(), contact.weights.max())

    def residual(u, z, active):
        """The optimality system's residual (equilibrium over the force scale, then the active rows' gaps) at u, z."""
        increment, M = tangent(points, fem.full(u), old, radius, viscosity)
        equilibrium = fem.K @ u - G @ (old + increment) - fem.f + A.T @ z
        return np.concatenate([equilibrium / force, b[active] - A[active] @ u]), M

    u, z = fields.u.copy(), np.where(rows, fields.pressure, 0.0)
    active, steps = rows & (z > (b - A @ u) / weights), 0
    for _ in range(rounds):
        r, M = residual(u, z, active)
        for _ in range(STEPS):
            if np.abs(r).max() <= CONVERGED:
                break
            J = fem.K - G @ M @ points.deviatoric[:, fem.free]
            kkt = sp.bmat([[J, A[active].T], [A[active], None]], format="csc")
            rhs = np.concatenate([-(r[: u.size] * force - A.T @ z), r[u.size:]])
            step = spla.splu(kkt).solve(rhs)
            direction, target = step[: u.size], np.zeros_like(z)
            target[active] = step[u.size:]
            steps += 1
            for length in 0.5 ** np.arange(LINE_SEARCH):  # backtracking on ‖r‖: the points' flow switches on and off
                trial_u, trial_z = u + length * direction, z + length * (target - z)
                trial, trial_M = residual(trial_u, trial_z, active)
                if np.linalg.norm(trial) < (1 - 1e-4 * length) * np.linalg.norm(r):
                    break
            u, z, r, M = trial_u, trial_z, trial, trial_M
        slack = (b - A @ u) / weights
        settled = rows & (z > slack)
        if np.abs(r).max() > CONVERGED:
            return None  # Newton does not settle on this active set
        if np.array_equal(settled, active) and slack[rows].min(initial=0.0) >= -CONVERGED and z.min(initial=0) >= 0:
            return ContactFields(u=u, pressure=z), steps
        active = settled
    return None
