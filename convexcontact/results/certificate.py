"""Solver-independent certificate: residuals of the discrete contact conditions.

Computed from the recovered fields (u, λ_N, λ_T), never from the solver's own
report. Each residual is scaled to the problem, so 1e-8 means the same on any
mesh and in any units:

- ``non_penetration``   max (u_N − g)_+ / u_ref         (weighted by C for the weak form)
- ``pressure_sign``     max (−λ_N)_+ / p_ref
- ``complementarity``   max |λ_N (u_N − g)| / (p_ref u_ref)
- ``equilibrium``       ‖Ku − f + NᵀCλ_N + TᵀCλ_T‖∞ / f_ref
- ``obstacle_balance``  |Σ contact force − P| / P    (force control only)
- ``friction_bound``    max (|λ_T| − s)_+ / p_ref     (friction only)
- ``slip_direction``    max |λ_T + s u_T/|u_T|| / p_ref over slipping nodes (friction only)

u_ref, p_ref and f_ref are the largest displacement (or obstacle advance), pressure
and nodal force of the problem (data or solution).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..fem.contact import ContactTrace
from ..formulations.fields import ContactFields

TINY = 1e-300


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


def normal_gap(contact: ContactTrace, fields: ContactFields) -> np.ndarray:
    """u_N − g at the contact nodes, the obstacle's advance included (≤ 0 is admissible)."""
    advance = 0.0 if contact.obstacle_coupling is None else contact.obstacle_coupling * fields.obstacle_advance
    return contact.N @ fields.u + contact.normal_offset + advance - contact.gap


def certify(
    K: sp.spmatrix,
    f: np.ndarray,
    contact: ContactTrace,
    C: sp.spmatrix,
    fields: ContactFields,
    slip_bound: np.ndarray | None = None,
) -> Certificate:
    """Residuals of the Signorini (and, with ``slip_bound``, Tresca) conditions."""
    lam_N = fields.pressure
    lam_T = fields.friction
    gap = normal_gap(contact, fields)
    weighted_gap = (C @ gap) / contact.weights  # u_N − g for nodal contact, its P1 projection for weak
    contact_force = contact.N.T @ (C @ lam_N)
    if lam_T is not None:
        contact_force = contact_force + contact.T.T @ (C @ lam_T)
    elastic_force = K @ fields.u

    u_ref = max(np.abs(fields.u).max(initial=0.0), abs(fields.obstacle_advance), TINY)
    p_ref = max(np.abs(lam_N).max(initial=0.0), TINY)
    f_ref = max(np.abs(f).max(initial=0.0), np.abs(elastic_force).max(initial=0.0), TINY)
    residuals = {
        "non_penetration": np.maximum(weighted_gap, 0.0).max(initial=0.0) / u_ref,
        "pressure_sign": np.maximum(-lam_N, 0.0).max(initial=0.0) / p_ref,
        "complementarity": np.abs(lam_N * weighted_gap).max(initial=0.0) / (p_ref * u_ref),
        "equilibrium": np.abs(elastic_force - f + contact_force).max(initial=0.0) / f_ref,
    }
    if contact.obstacle_coupling is not None:
        resultant = contact.obstacle_coupling @ (C @ lam_N)
        residuals["obstacle_balance"] = abs(resultant - contact.obstacle_force) / max(contact.obstacle_force, TINY)
    if slip_bound is not None:
        residuals.update(friction_residuals(contact, fields, slip_bound, p_ref, u_ref))
    return Certificate({k: float(v) for k, v in residuals.items()})


def friction_residuals(contact, fields, slip_bound, p_ref, u_ref) -> dict[str, float]:
    """|λ_T| ≤ s, and λ_T = −s u_T/|u_T| where the node slips (|u_T| above round-off)."""
    lam_T = fields.friction
    u_T = contact.T @ fields.u + contact.tangent_offset
    slipping = np.abs(u_T) > 1e-9 * u_ref
    direction_error = np.abs(lam_T + slip_bound * np.sign(u_T))[slipping]
    return {
        "friction_bound": np.maximum(np.abs(lam_T) - slip_bound, 0.0).max(initial=0.0) / p_ref,
        "slip_direction": direction_error.max(initial=0.0) / p_ref,
    }
