"""Mechanical fields recovered from a solver's answer (scaled units)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ContactFields:
    """Free displacement DOFs and contact tractions at the contact nodes.

    ``pressure`` λ_N ≥ 0 and ``friction`` λ_T are nodal values of traction
    fields along Γ_C (force per unit length); the nodal forces on the body are
    −Nᵀ C λ_N − Tᵀ C λ_T with C the contact weights of the formulation.
    ``obstacle_advance`` is the unknown indentation under force control.
    """

    u: np.ndarray
    pressure: np.ndarray
    friction: np.ndarray | None = None
    obstacle_advance: float = 0.0
