"""Solver-independent certificate: residuals of the discrete contact conditions.

Computed from the recovered fields (u, λ_N, λ_T), never from the solver's own
report. Each residual is scaled to the problem, so 1e-8 means the same on any
mesh and in any units. Complementarity is measured by **natural maps**, not products:
a residual r bounds the error of every quantity by about κ·r of its scale (κ the
conditioning of the contact problem), where a product λ_N (u_N − g) would turn an
error δ in both factors into δ² and pass a 1e-5 error as 1e-10.

- ``non_penetration``   max (u_N − g)_+ / u_ref         (weighted by C for the weak form)
- ``pressure_sign``     max (−λ_N)_+ / p_ref
- ``complementarity``   max |min(λ_N / p_ref, (g − u_N) / u_ref)|   (the Signorini natural map)
- ``equilibrium``       ‖Ku − f + NᵀCλ_N − Rᵀλ_T‖∞ / f_ref
- ``obstacle_balance``  |Σ contact force − P| / max(P, Q, 1), likewise Q  (force control only)
- ``pair_balance``      max over pairs of ‖R_slave + R_master‖ / max(‖R_slave‖, Σw): the contact forces on the
                        two bodies of a pair, summed over each body's nodes, are equal and opposite (pairs only)
- ``friction_bound``    max (‖λ_T‖ − s)_+ / p_ref     (friction only)
- ``friction_law``      max ‖λ_T − Π_{B(s)}(λ_T − ρ v)‖ / p_ref with ρ = p_ref / u_ref (friction
                        only): the projection (De Saxcé / Alart–Curnier) form of "‖λ_T‖ ≤ s, and
                        λ_T = −s v/|v| where the point slips", v the slip at the friction point
                        relative to the obstacle. For the ε-regularized law λ_T = −s v/|v|_ε,
                        |v|_ε = sqrt(‖v‖² + ε²), it is ‖λ_T + s v/|v|_ε‖ / p_ref.

For Coulomb friction s = F λ_N of the same solution: the residuals then measure how far
the answer is from a fixed point of the Picard map, i.e. from the discrete Coulomb law.

With normal compliance, ``non_penetration`` and ``complementarity`` give way to
- ``compliance_law``    max |λ_N − c_N (u_N − g)_+^p| / p_ref

u_ref and p_ref are the largest displacement (or obstacle motion) and pressure of
the solution, but at least the displacement and pressure scales of the data — both 1
in the scaled units of :mod:`convexcontact.fem.scaling` — so that a solution that
should be zero (stick, no contact) is not judged against its own round-off. f_ref is
the largest nodal force of the data or the solution, at least that of a unit pressure on
the largest contact weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..fem.contact import ContactTrace
from ..fem.friction import FrictionPoints
from ..fem.mortar import PairTrace
from ..formulations.fields import ContactFields


@dataclass(frozen=True)
class Certificate:
    """Scaled residuals of the discrete contact conditions."""

    residuals: dict[str, float]

    @property
    def worst(self) -> float:
        return max(self.residuals.values())

    def passes(self, tol: float = 1e-6) -> bool:
        return self.worst <= tol

    def as_dict(self) -> dict[str, float]:
        return {**self.residuals, "worst": self.worst}


def normal_displacement(contact: ContactTrace, fields: ContactFields) -> np.ndarray:
    """u_N at the contact nodes, the obstacle's advance included."""
    advance = 0.0 if contact.obstacle_coupling is None else contact.obstacle_coupling * fields.obstacle_advance
    return contact.N @ fields.u + contact.normal_offset + advance


def normal_gap(contact: ContactTrace, fields: ContactFields) -> np.ndarray:
    """u_N − g at the contact nodes, the obstacle's advance included (≤ 0 is admissible)."""
    return normal_displacement(contact, fields) - contact.gap


def certify(
    K: sp.spmatrix,
    f: np.ndarray,
    contact: ContactTrace,
    C: sp.spmatrix,
    fields: ContactFields,
    friction: FrictionPoints | None = None,
    slip_bound: np.ndarray | None = None,
    epsilon: float | None = None,
    compliance: tuple[float, float] | None = None,
) -> Certificate:
    """Residuals of the Signorini or normal compliance (and, with ``friction``, Tresca) conditions."""
    lam_N = fields.pressure
    # u_N − g for nodal contact, its projection for weak, its value at each Gauss point
    weighted_gap = (C @ normal_displacement(contact, fields) - contact.weighted_gap(C)) / contact.row_weights(C)
    contact_force = contact.N.T @ (C.T @ lam_N)
    if friction is not None:
        contact_force = contact_force - friction.R.T @ fields.friction
    elastic_force = K @ fields.u

    u_ref = max(np.abs(fields.u).max(initial=0.0), abs(fields.obstacle_advance), abs(fields.obstacle_shift), 1.0)
    p_ref = max(np.abs(lam_N).max(initial=0.0), 1.0)
    # at least the nodal force of a unit (data-scale) pressure, for unloaded bodies
    f_ref = max(np.abs(f).max(initial=0.0), np.abs(elastic_force).max(initial=0.0), contact.weights.max())
    if compliance is None:
        residuals = {
            "non_penetration": np.maximum(weighted_gap, 0.0).max(initial=0.0) / u_ref,
            "complementarity": np.abs(np.minimum(lam_N / p_ref, -weighted_gap / u_ref)).max(initial=0.0),
        }
    else:
        stiffness, exponent = compliance
        law = stiffness * np.maximum(weighted_gap, 0.0) ** exponent  # per node, or per Gauss point
        residuals = {"compliance_law": np.abs(lam_N - law).max(initial=0.0) / p_ref}
    residuals["pressure_sign"] = np.maximum(-lam_N, 0.0).max(initial=0.0) / p_ref
    residuals["equilibrium"] = np.abs(elastic_force - f + contact_force).max(initial=0.0) / f_ref
    balance = []
    force_ref = max(contact.obstacle_force, abs(contact.obstacle_tangential_force), 1.0)  # 1: the data's force scale
    if contact.obstacle_coupling is not None:
        resultant = contact.obstacle_coupling @ (C.T @ lam_N)
        balance.append(abs(resultant - contact.obstacle_force) / force_ref)
    if contact.tangential_coupling is not None:
        resultant = friction.coupling @ fields.friction
        balance.append(abs(resultant - contact.obstacle_tangential_force) / force_ref)
    if balance:
        residuals["obstacle_balance"] = max(balance)
    if friction is not None:
        residuals.update(friction_residuals(friction, fields, slip_bound, p_ref, u_ref, epsilon))
    if isinstance(contact, PairTrace):
        residuals["pair_balance"] = contact.imbalance(*pair_multipliers(C, fields, friction))
    return Certificate({k: float(v) for k, v in residuals.items()})


def pair_multipliers(C: sp.spmatrix, fields: ContactFields, friction: FrictionPoints | None):
    """The weighted multipliers (Cᵀλ_N, w·λ_T) whose forces a pair's rows apply (scaled), at the contact nodes
    (a frictionless pair's nodes have no friction points: w·λ_T = 0 there)."""
    if friction is None:
        return C.T @ fields.pressure, None
    to_nodes = sp.block_diag([friction.interpolation.T] * friction.dim, format="csr")
    return C.T @ fields.pressure, to_nodes @ (np.tile(friction.weights, friction.dim) * fields.friction)


def weighted_slip(friction: FrictionPoints, fields: ContactFields) -> np.ndarray:
    """v = R u + offset − coupling δ_T: slip relative to the obstacle, weighted, at the friction points."""
    shift = 0.0 if friction.coupling is None else friction.coupling * fields.obstacle_shift
    return friction.slip(fields.u) - shift


def friction_residuals(friction, fields, slip_bound, p_ref, u_ref, epsilon=None) -> dict[str, float]:
    """‖λ_T‖ ≤ s, and the natural map of the friction law at each point (vectors of d − 1
    components per point in 3-D; slips as lengths, the weights divided out)."""
    lam_T = friction.components(fields.friction)
    slip = friction.components(weighted_slip(friction, fields)) / friction.weights[:, None]
    if epsilon is None:  # λ_T = Π_{B(s)}(λ_T − ρ v)
        trial = lam_T - (p_ref / u_ref) * slip
        size = np.linalg.norm(trial, axis=1)
        # the projection's factor min(1, s/‖trial‖), divided only where it is below 1 (s/‖trial‖ overflowed for a
        # bound far beyond a tiny trial: the fuzz suite's unloaded scenes)
        shrink = np.divide(slip_bound, size, out=np.ones_like(size), where=size > slip_bound)
        law = lam_T - shrink[:, None] * trial
    else:  # λ_T = −s v / sqrt(‖v‖² + ε²)
        magnitude = np.sqrt((slip**2).sum(axis=1) + epsilon**2)
        law = lam_T + (slip_bound / magnitude)[:, None] * slip
    return {
        "friction_bound": np.maximum(np.linalg.norm(lam_T, axis=1) - slip_bound, 0.0).max(initial=0.0) / p_ref,
        "friction_law": np.linalg.norm(law, axis=1).max(initial=0.0) / p_ref,
    }
