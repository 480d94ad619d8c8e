"""The plastic state of a step, the material law's residuals and the step's result (docs/plasticity.md).

Residuals of the flow rule at every plastic point q, beside the contact residuals and scaled like them: with
τ_q = s_q − (η_p/Δt) Δα_q (the stress deviator less its viscous overstress) and r_q = √(2/3) σ_Y,

- ``yield_condition``  max (‖τ_q‖ − r_q)_+ / p_ref
- ``flow_rule``        max ‖τ_q − Π_{B(r_q)}(τ_q + ρ Δα_q)‖ / p_ref,  ρ = p_ref / e_ref

the natural map of "‖τ‖ ≤ r, and τ = r Δα/‖Δα‖ where Δα ≠ 0" (Perzyna's law: Δα = Δt/η_p ⟨‖s‖ − r⟩ s/‖s‖),
as the friction law's. p_ref is the largest ‖s_q‖ and e_ref the largest ‖α_q‖ or deviatoric strain, both at least
the data's scales (1, scaled).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..fem.plasticity import DEVIATORS, PlasticPoints
from .result import ContactResult


@dataclass
class PlasticState:
    """Scaled fields at the plastic points: deviatoric plastic strain ``alpha`` and this step's ``increment``
    (k coordinates per point), the stress deviator ``deviator`` and mean stress ``mean``, the accumulated
    equivalent plastic strain ``accumulated`` (Σ √(2/3)‖Δα‖); ``radius`` √(2/3)σ_Y (inf: elastic) and
    ``viscosity`` η_p/Δt per point."""

    points: PlasticPoints
    alpha: np.ndarray
    increment: np.ndarray
    deviator: np.ndarray
    mean: np.ndarray
    accumulated: np.ndarray
    radius: np.ndarray
    viscosity: np.ndarray

    @classmethod
    def of(cls, points, u_full, old, accumulated, radius, viscosity) -> PlasticState:
        """The state after a step that moved the body to ``u_full`` (scaled), its increment the exact minimizer of
        the step's energy at that u (:func:`radial_return`): the material law then holds to round-off, and what
        the solver left is the equilibrium residual's."""
        increment = radial_return(points, u_full, old, radius, viscosity)
        alpha = old + increment
        deviator = np.repeat(points.shear, points.components) * (points.deviatoric @ u_full - alpha)
        mean = (points.lame + points.shear / 3.0) * (points.trace @ u_full)
        step = np.sqrt(2.0 / 3.0) * np.linalg.norm(increment.reshape(-1, points.components), axis=1)
        return cls(points, alpha, increment, deviator, mean, accumulated + step, radius, viscosity)

    def per_point(self, values: np.ndarray) -> np.ndarray:
        return values.reshape(-1, self.points.components)

    @property
    def von_mises(self) -> np.ndarray:
        return np.sqrt(1.5) * np.linalg.norm(self.per_point(self.deviator), axis=1)

    def residuals(self, u_full: np.ndarray) -> dict[str, float]:
        """The material law's residuals (module docstring) at the plastic points."""
        plastic = np.isfinite(self.radius)
        if not plastic.any():
            return {}
        deviator, increment = self.per_point(self.deviator)[plastic], self.per_point(self.increment)[plastic]
        radius = self.radius[plastic]
        strain = np.linalg.norm(self.per_point(self.points.deviatoric @ u_full), axis=1)
        p_ref = max(np.linalg.norm(deviator, axis=1).max(), 1.0)
        e_ref = max(np.linalg.norm(self.per_point(self.alpha), axis=1).max(), strain.max(), 1.0)
        tau = deviator - self.viscosity[plastic, None] * increment
        trial = tau + (p_ref / e_ref) * increment
        size = np.linalg.norm(trial, axis=1)
        shrink = np.divide(radius, size, out=np.ones_like(size), where=size > radius)
        return {"yield_condition": float(np.maximum(np.linalg.norm(tau, axis=1) - radius, 0.0).max() / p_ref),
                "flow_rule": float(np.linalg.norm(tau - shrink[:, None] * trial, axis=1).max() / p_ref)}

    def energy(self, u_full: np.ndarray) -> float:
        """½ Σ_q w_q (ε − ε_p):C:(ε − ε_p), scaled."""
        points = self.points
        volumetric = (points.lame + points.shear / 3.0) * (points.trace @ u_full) ** 2
        deviatoric = np.sum(self.per_point(self.deviator) ** 2, axis=1) / points.shear
        return float(0.5 * points.weights @ (volumetric + deviatoric))


def radial_return(points: PlasticPoints, u_full: np.ndarray, old: np.ndarray, radius: np.ndarray,
                  viscosity: np.ndarray) -> np.ndarray:
    """Δα minimizing ½ 2μ‖Πᵀε(u) − α^old − Δα‖² + ½ (η_p/Δt)‖Δα‖² + r‖Δα‖ at each point (u fixed): with the trial
    deviator s* = 2μ(Πᵀε − α^old), Δα = ⟨‖s*‖ − r⟩ / (2μ + η_p/Δt) · s*/‖s*‖ (0 where r = inf, at elastic points)."""
    k = points.components
    trial = (np.repeat(points.shear, k) * (points.deviatoric @ u_full - old)).reshape(-1, k)
    size = np.linalg.norm(trial, axis=1)
    excess = np.where(np.isfinite(radius), np.maximum(size - radius, 0.0), 0.0)
    flow = np.divide(excess, (points.shear + viscosity) * size, out=np.zeros_like(size), where=excess > 0)
    return (flow[:, None] * trial).ravel()


@dataclass
class PlasticResult(ContactResult):
    """A step of an elasto-viscoplastic body: the contact result with the plastic state (scaled) beside it."""

    plastic: PlasticState | None = None

    @classmethod
    def of(cls, result: ContactResult, plastic: PlasticState) -> PlasticResult:
        kept = {f.name: getattr(result, f.name) for f in fields(ContactResult)}
        return cls(**{**kept, "estimate_error": False}, plastic=plastic)  # the residual estimate is elastic

    @property
    def elastic_energy(self) -> float:
        """The stored energy ½ (ε − ε_p):C:(ε − ε_p), user units."""
        u = self.displacement / self.fem.scaling.displacement
        return self.plastic.energy(u) * self.fem.scaling.energy

    @property
    def max_equivalent_plastic_strain(self) -> float:
        scaling = self.fem.scaling
        return float(self.plastic.accumulated.max(initial=0.0) * scaling.displacement / scaling.length)

    @property
    def max_von_mises(self) -> float:
        return float(self.plastic.von_mises.max(initial=0.0) * self.fem.scaling.pressure)

    def cell_fields(self) -> dict[str, np.ndarray]:
        """Cell averages (user units) of the stress (plane strain: σ_zz too), von Mises, the plastic strain and the
        equivalent plastic strain."""
        state, points, scaling = self.plastic, self.plastic.points, self.fem.scaling
        strain_scale = scaling.displacement / scaling.length
        names = ("xx", "yy", "zz", "yz", "xz", "xy") if self.fem.dim == 3 else ("xx", "yy", "zz", "xy")
        to_tensor = np.array([1.0 if n[0] == n[1] else np.sqrt(0.5) for n in names]) * DEVIATORS[self.fem.dim].T
        deviator, plastic = state.per_point(state.deviator) @ to_tensor, state.per_point(state.alpha) @ to_tensor
        per_point = {f"sigma_{n}": (deviator[:, i] + (state.mean if i < 3 else 0.0)) * scaling.pressure
                     for i, n in enumerate(names)}
        per_point.update({f"plastic_strain_{n}": plastic[:, i] * strain_scale for i, n in enumerate(names)})
        per_point["von_mises"] = state.von_mises * scaling.pressure
        per_point["equivalent_plastic_strain"] = state.accumulated * strain_scale
        cells = self.fem.mesh.t.shape[1]
        volume = np.bincount(points.element, points.weights, minlength=cells)
        return {name: np.bincount(points.element, points.weights * values, minlength=cells) / volume
                for name, values in per_point.items()}

    def summary(self) -> dict:
        out = super().summary()
        if self.solved:
            out["plastic"] = {"max_equivalent_plastic_strain": self.max_equivalent_plastic_strain,
                              "max_von_mises": self.max_von_mises,
                              "n_flowing": int((np.linalg.norm(self.plastic.per_point(self.plastic.increment), axis=1)
                                                > FLOWING * max(self.plastic.accumulated.max(initial=0.0), 1.0)).sum())}
        return out


FLOWING = 1e-7
"""A point flows in a step when its plastic strain increment exceeds this fraction of the largest accumulated plastic
strain (at least the data's strain scale)."""
