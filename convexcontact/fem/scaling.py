"""Internal units: lengths by the body size, stresses by E, displacements by a load scale.

In scaled units every problem has O(1) geometry, stiffness, displacements and
pressures, so solver tolerances mean the same thing for E = 2.1e11 Pa with
millimetre geometry as for E = 1. Results go back to the user's units.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Scaling:
    """User quantity = scale × scaled quantity."""

    length: float
    stress: float
    displacement: float
    dim: int = 2  # forces and energies are per unit thickness in 2-D

    @property
    def pressure(self) -> float:
        """Tractions, contact pressures and stresses of the deformed body."""
        return self.stress * self.displacement / self.length

    @property
    def force(self) -> float:
        """Forces (resultants; per unit thickness in 2-D)."""
        return self.pressure * self.length ** (self.dim - 1)

    @property
    def energy(self) -> float:
        """Energies (per unit thickness in 2-D)."""
        return self.stress * self.displacement**2 * self.length ** (self.dim - 2)
