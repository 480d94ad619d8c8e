"""Mechanical fields recovered from a solver's answer (scaled units)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ContactFields:
    """Free displacement DOFs and contact tractions.

    ``pressure`` λ_N ≥ 0 holds nodal values of the pressure along Γ_C; the normal
    nodal forces on the body are −Nᵀ C λ_N. ``friction`` λ_T holds the friction
    traction on the body along the tangent at the friction points (force Rᵀ λ_T).
    ``obstacle_advance`` and ``obstacle_shift`` are the obstacle's unknown normal
    and tangential translations under force control.
    """

    u: np.ndarray
    pressure: np.ndarray
    friction: np.ndarray | None = None
    obstacle_advance: float = 0.0
    obstacle_shift: float = 0.0
