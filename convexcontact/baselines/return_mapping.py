"""A classical return-mapping baseline for plastic histories: radial return, consistent tangent, penalty contact.

It shares nothing with the conic path but the FE model (the assembled body, its step scenes and its plastic
points): each step minimizes the same incremental energy with the contact replaced by the penalty energy
Σ w c/2 (u_N − g)₊² (Oden's algorithm I), over u alone — the plastic strain eliminated point by point by the radial
return, which makes the energy C¹ and convex with the stress as its gradient and the consistent tangent as its
generalized Hessian — by the damped Newton of :mod:`.penalty`. Scaled units as there; its answer differs from the
conic one by the penalty's error, O(1/c).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..fem.assembly import FEModel, assemble
from ..fem.plasticity import PlasticPoints, material_per_element, plastic_points
from ..scene.description import Scene, SceneError, Signorini, of_type
from .penalty import check_inputs, newton


@dataclass
class ReturnMappingStep:
    """One step of the step energy E(u) = Σ_q w_q [½κ(tr ε)² + ψ_q(Πᵀε − α^old)] − fᵀu + penalty (scaled units),
    ψ the point's energy minimized over its plastic strain increment: ψ(e) = min ½2μ‖e − Δα‖² + ½v‖Δα‖² + r‖Δα‖."""

    fem: FEModel
    points: PlasticPoints
    old: np.ndarray
    radius: np.ndarray
    viscosity: np.ndarray
    penalty: float

    def strains(self, u):
        """(tr ε, e = Πᵀε − α^old per point) at the free DOFs u."""
        full = self.fem.full(u)
        k = self.points.components
        return self.points.trace @ full, (self.points.deviatoric @ full - self.old).reshape(-1, k)

    def radial_return(self, e):
        """Δα, the trial deviator's size and direction at each point: Δα = ⟨2μ‖e‖ − r⟩/(2μ + v) · e/‖e‖."""
        shear = self.points.shear
        size = shear * np.linalg.norm(e, axis=1)
        direction = e / np.where(size > 0, size / shear, 1.0)[:, None]
        flow = np.maximum(size - self.radius, 0.0) / (shear + self.viscosity)
        return flow[:, None] * direction, size, direction

    def overlap(self, u):
        c = self.fem.contact
        return np.maximum(c.N @ u + c.normal_offset - c.gap, 0.0)

    def energy(self, u) -> float:
        trace, e = self.strains(u)
        increment, _, _ = self.radial_return(e)
        p = self.points
        flow = np.linalg.norm(increment, axis=1)
        point = 0.5 * (p.lame + p.shear / 3) * trace**2 + 0.5 * p.shear * np.sum((e - increment) ** 2, axis=1) \
            + 0.5 * self.viscosity * flow**2 + self.radius_cost(flow)
        contact = self.fem.contact
        return float(p.weights @ point - self.load @ u + 0.5 * self.penalty * contact.weights @ self.overlap(u) ** 2)

    def radius_cost(self, flow):
        """r‖Δα‖, 0 where Δα = 0 (elastic points have r = inf)."""
        cost = np.zeros_like(flow)
        cost[flow > 0] = self.radius[flow > 0] * flow[flow > 0]
        return cost

    @property
    def load(self) -> np.ndarray:
        return self.fem.f_full[self.fem.free]

    def gradient(self, u):
        trace, e = self.strains(u)
        increment, _, _ = self.radial_return(e)
        p, free = self.points, self.fem.free
        deviator = p.shear[:, None] * (e - increment)  # ∂ψ/∂e: the stress deviator
        internal = p.trace.T @ (p.weights * (p.lame + p.shear / 3) * trace) + p.deviatoric.T @ (
            p.weights[:, None] * deviator).ravel()
        contact = self.fem.contact
        return internal[free] - self.load + contact.N.T @ (contact.weights * self.penalty * self.overlap(u))

    def hessian(self, u):
        """The consistent tangent: ∂s/∂e = 2μ[I − β((1 − r/‖s*‖)(I − nnᵀ) + nnᵀ)] at flowing points, β = 2μ/(2μ + v)."""
        _, e = self.strains(u)
        _, size, direction = self.radial_return(e)
        p, free, k = self.points, self.fem.free, self.points.components
        flowing = size > self.radius
        ratio = np.divide(self.radius, size, out=np.ones_like(size), where=flowing)
        beta = np.where(flowing, p.shear / (p.shear + self.viscosity), 0.0)
        outer = direction[:, :, None] * direction[:, None, :]
        blocks = np.eye(k) - beta[:, None, None] * ((1 - ratio)[:, None, None] * (np.eye(k) - outer) + outer)
        blocks *= (p.weights * p.shear)[:, None, None]
        count = blocks.shape[0]
        tangent = sp.bsr_matrix((blocks, np.arange(count), np.arange(count + 1)), shape=(count * k,) * 2)
        D, T = p.deviatoric[:, free], p.trace[:, free]
        contact = self.fem.contact
        penetrating = contact.weights * self.penalty * (self.overlap(u) > 0)
        return D.T @ tangent @ D + T.T @ sp.diags(p.weights * (p.lame + p.shear / 3)) @ T + \
            contact.N.T @ sp.diags(penetrating) @ contact.N

    def force_scale(self, u) -> float:
        """The largest nodal force of the load, the elastic response or the contact, at least that of a unit (scaled)
        pressure on the largest contact weight (the certificate's f_ref)."""
        contact = self.fem.contact
        return max(np.abs(self.load).max(initial=0.0), np.abs(self.fem.K @ u).max(initial=0.0),
                   np.abs(contact.N.T @ (contact.weights * self.penalty * self.overlap(u))).max(initial=0.0),
                   contact.weights.max())

    def active(self, u):
        _, e = self.strains(u)
        _, size, _ = self.radial_return(e)
        return np.concatenate([self.overlap(u) > 0, size > self.radius])


@dataclass
class ReturnMappingResult:
    """The baseline's answer at every step (user units): displacements, contact pressures and the normal force; its
    Newton steps and seconds per step."""

    displacement: list[np.ndarray]
    pressure: list[np.ndarray]
    normal_force: np.ndarray
    newton_steps: list[int]
    seconds: list[float]


def return_mapping_history(scene: Scene, penalty: float, tol: float = 1e-10, max_iter: int = 100):
    """Run ``scene``'s history by return mapping with the penalty ``penalty`` (a scaled pressure per scaled
    displacement: relative to E/L) on its contact; rigid obstacle under displacement control, one body."""
    if of_type(scene, Scene, "scene", "build cc.Scene(...) with a history").history is None:
        raise SceneError("history", "the return-mapping baseline runs a load history", "give the scene a history")
    if not isinstance(scene.contact.law, Signorini):
        raise SceneError("contact.law", f"{type(scene.contact.law).__name__}: the return-mapping baseline's penalty "
                         "contact is frictionless", "give the scene contact law cc.Signorini()")
    fem = assemble(scene.history.envelope(scene))
    check_inputs(fem.contact, penalty, 1.0)
    points = plastic_points(fem)
    sigma, eta = (points.per_point(values) for values in material_per_element(fem))
    radius, relaxation = np.sqrt(2 / 3) * sigma / fem.scaling.pressure, eta / fem.scaling.stress
    alpha, u = np.zeros(points.count * points.components), np.zeros(fem.free.size)
    out = ReturnMappingResult([], [], np.zeros(len(scene.history)), [], [])
    times = (0.0, *scene.history.times)
    for k in range(len(scene.history)):
        start = time.perf_counter()
        step_fem = fem.at(scene.history.scene(scene, k))
        step = ReturnMappingStep(step_fem, points, alpha, radius, relaxation / (times[k + 1] - times[k]), penalty)
        u, steps, converged, _ = newton(step.energy, step.gradient, step.hessian, u, step.force_scale, tol, max_iter,
                                        step.active)
        if not converged:
            raise RuntimeError(f"return mapping: step {k + 1} did not converge in {max_iter} Newton steps")
        alpha = alpha + step.radial_return(step.strains(u)[1])[0].ravel()
        out.seconds.append(time.perf_counter() - start)
        pressure = penalty * step.overlap(u)
        scaling = step_fem.scaling
        out.displacement.append(step_fem.full(u) * scaling.displacement)
        out.pressure.append(pressure * scaling.pressure)
        contact = step_fem.contact
        mean = contact.weights @ contact.normals
        out.normal_force[k] = (contact.weights * pressure) @ (contact.normals @ mean) / np.linalg.norm(mean) * \
            scaling.force
        out.newton_steps.append(steps)
    return out
