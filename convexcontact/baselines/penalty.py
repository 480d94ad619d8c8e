"""Penalty and regularized reference solvers: plain sparse Newton, no conic solver.

The methods production codes use, kept independent of the convex programs so that
each can check the other (and the penalty error can be measured against the exact
answer):

- Oden's algorithm I / normal compliance: u_N ≤ g replaced by the exterior penalty
  Σ w_i c/(p+1) (u_N,i − g_i)_+^{p+1}; the pressure is λ_N = c (u_N − g)_+^p. For
  p = 1 this is the classical penalty method, solved by semismooth Newton on the
  active set of penetrating nodes.
- Oden's algorithm II: Tresca friction with |u_T| regularized as sqrt(u_T² + ε²),
  with the penalty normal contact above — the usual penalty + regularized method.
- Coulomb: the fixed point s = F λ_N over it (the Picard map over normal pressures
  of DESIGN.md, close to Oden's algorithm III).

All three minimize one convex C¹ energy with :func:`newton` (damped by backtracking
on the energy); for friction the Newton curvature is the primal–dual one of
:class:`PenaltyFunctional`. Everything is in scaled units (``FEModel.K``, ``.f``,
``.contact``); the penalty c is a scaled pressure per scaled displacement, i.e.
relative to the stiffness scale E / L. Sign convention (DESIGN.md): λ_N ≥ 0 is the
pressure, λ_T the tangential traction on the body along the tangent, so λ_T =
−s u_T/|u_T| in slip and here λ_T = −s u_T / sqrt(u_T² + ε²); equilibrium reads
K u − f + Nᵀ W λ_N − Tᵀ W λ_T = 0 with W = diag(w).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..fem.contact import ContactTrace

ARMIJO = 1e-4
"""Sufficient decrease asked of a damped step: E(u + t d) ≤ E(u) + ARMIJO t ∇E·d."""
ROUNDOFF = 1e-12
"""Energy changes below this fraction of |E| are round-off: a full step near the solution is accepted."""
SMALLEST_STEP = 2.0**-40


@dataclass
class PenaltyResult:
    """Answer of a baseline solver, in scaled units.

    ``u`` are the free DOFs, ``pressure`` λ_N and ``friction`` λ_T (None without
    friction) the nodal tractions at the contact nodes (see the module docstring
    for signs). ``iterations`` counts Newton steps (fixed-point steps for Coulomb).
    ``history`` holds one array per monitored quantity: ``energy`` and
    ``residual`` (‖∇E‖∞ over the force scale) at every Newton iterate, the start
    included, and the ``step_length`` of every step; for Coulomb ``slip_bound_change`` (relative change of s per step)
    and ``newton_iterations`` of each inner solve.
    """

    u: np.ndarray
    pressure: np.ndarray
    friction: np.ndarray | None
    iterations: int
    converged: bool
    history: dict[str, np.ndarray]


def newton(
    energy: Callable[[np.ndarray], float],
    gradient: Callable[[np.ndarray], np.ndarray],
    hessian: Callable[[np.ndarray], sp.spmatrix],
    x0: np.ndarray,
    force_scale: Callable[[np.ndarray], float],
    tol: float = 1e-10,
    max_iter: int = 50,
    pattern: Callable[[np.ndarray], np.ndarray] | None = None,
    after_step: Callable[[np.ndarray, np.ndarray], None] | None = None,
):
    """Damped (semismooth) Newton on a convex C¹ energy, backtracking on the energy.

    ``hessian`` may be any SPD model of the curvature (a generalized Hessian); the
    step is then a descent direction and the energy decreases at every step.
    Converged when ‖∇E(x)‖∞ ≤ tol · force_scale(x) and, if ``pattern`` is given
    (e.g. the active set), it is the same as at the previous iterate.
    ``after_step(x, step)`` is told every accepted step. Returns ``(x, steps,
    converged, history)`` with ``energy``, ``residual`` (start included) and
    ``step_length`` histories; a line search that cannot decrease the energy ends
    the loop unconverged.
    """
    x = np.array(x0, dtype=float)
    value, grad = energy(x), gradient(x)
    energies, residuals, step_lengths = [value], [], []
    previous = None
    converged = False
    while True:
        residuals.append(np.abs(grad).max(initial=0.0) / force_scale(x))
        current = None if pattern is None else pattern(x)
        if residuals[-1] <= tol and (pattern is None or np.array_equal(current, previous)):
            converged = True
            break
        if len(step_lengths) == max_iter:
            break
        direction = spsolve(sp.csc_matrix(hessian(x)), -grad)
        slope = grad @ direction
        t = 1.0
        while (trial_value := energy(x + t * direction)) > value + ARMIJO * t * slope + ROUNDOFF * abs(value):
            t /= 2.0
            if t < SMALLEST_STEP:
                break
        if t < SMALLEST_STEP:  # no decrease along a descent direction: round-off or a wrong derivative
            break
        if after_step is not None:
            after_step(x, t * direction)
        x, value, previous = x + t * direction, trial_value, current
        grad = gradient(x)
        energies.append(value)
        step_lengths.append(t)
    history = {"energy": np.array(energies), "residual": np.array(residuals), "step_length": np.array(step_lengths)}
    return x, len(step_lengths), converged, history


def check_inputs(contact: ContactTrace, penalty: float, power: float, slip_bound=None, epsilon=None):
    if contact.obstacle_coupling is not None or getattr(contact, "tangential_coupling", None) is not None:
        raise ValueError(
            "contact.obstacle_coupling: the baselines are for displacement control only; "
            "give the obstacle a depth (and no tangential force) instead of a force"
        )
    if not penalty > 0:
        raise ValueError(f"penalty: must be > 0, got {penalty}")
    if not power >= 1:
        raise ValueError(f"power: the normal compliance exponent must be ≥ 1, got {power}")
    if slip_bound is not None:
        s = np.broadcast_to(np.asarray(slip_bound, dtype=float), (contact.m,))
        if not np.all(s >= 0):
            raise ValueError("slip_bound: must be ≥ 0 at every contact node")
        if not epsilon > 0:
            raise ValueError(f"epsilon: the regularization must be > 0, got {epsilon}")
        return np.array(s)
    return None


@dataclass
class PenaltyFunctional:
    """E(u) = ½uᵀKu − fᵀu + Σ w c/(p+1) (u_N − g)_+^{p+1} [+ Σ w s sqrt(u_T² + ε²)] and its derivatives.

    The curvature of the friction term is the exact s ε²/r³ (r = sqrt(u_T² + ε²))
    unless ``primal_dual``: then λ_T is carried as its own iterate and the curvature
    is (s + λ_T u_T/r)/r, λ_T ← −s u_T/r − curvature·Δu_T after each step, clipped
    to |λ_T| ≤ s (Chan, Golub, Mulet 1999). It equals the exact one at the
    solution, so convergence stays quadratic, but a slipping start no longer sends
    the step far past the kink (s ε²/r³ ≈ 0 there).
    """

    K: sp.spmatrix
    f: np.ndarray
    contact: ContactTrace
    penalty: float
    power: float = 1.0
    slip_bound: np.ndarray | None = None
    epsilon: float | None = None
    primal_dual: bool = True

    def __post_init__(self):
        self.dual_friction = np.zeros(self.contact.m)

    def overlap(self, u):
        c = self.contact
        return np.maximum(c.N @ u + c.normal_offset - c.gap, 0.0)

    def slip(self, u):
        return self.contact.T @ u + self.contact.tangent_offset

    def tractions(self, u):
        """λ_N = c (u_N − g)_+^p and λ_T = −s u_T / sqrt(u_T² + ε²) (None without friction)."""
        pressure = self.penalty * self.overlap(u) ** self.power
        if self.slip_bound is None:
            return pressure, None
        u_T = self.slip(u)
        return pressure, -self.slip_bound * u_T / np.sqrt(u_T**2 + self.epsilon**2)

    def energy(self, u) -> float:
        w, c, p = self.contact.weights, self.penalty, self.power
        value = 0.5 * u @ (self.K @ u) - self.f @ u + w @ (c / (p + 1.0) * self.overlap(u) ** (p + 1.0))
        if self.slip_bound is not None:
            value += w @ (self.slip_bound * np.sqrt(self.slip(u) ** 2 + self.epsilon**2))
        return float(value)

    def gradient(self, u):
        w = self.contact.weights
        pressure, friction = self.tractions(u)
        grad = self.K @ u - self.f + self.contact.N.T @ (w * pressure)
        if friction is not None:
            grad -= self.contact.T.T @ (w * friction)
        return grad

    def friction_curvature(self, u):
        s, u_T = self.slip_bound, self.slip(u)
        r = np.sqrt(u_T**2 + self.epsilon**2)
        if self.primal_dual:
            return (s + self.dual_friction * u_T / r) / r
        return s * self.epsilon**2 / r**3

    def hessian(self, u):
        w, c, p = self.contact.weights, self.penalty, self.power
        gap = self.overlap(u)
        normal = np.where(gap > 0, c * p * gap ** (p - 1.0), 0.0)
        H = self.K + self.contact.N.T @ sp.diags(w * normal) @ self.contact.N
        if self.slip_bound is not None:
            H = H + self.contact.T.T @ sp.diags(w * self.friction_curvature(u)) @ self.contact.T
        return H

    def active(self, u):
        return self.overlap(u) > 0

    def after_step(self, u, step):
        if self.slip_bound is None or not self.primal_dual:
            return
        u_T = self.slip(u)
        linearized = -self.slip_bound * u_T / np.sqrt(u_T**2 + self.epsilon**2)
        linearized -= self.friction_curvature(u) * (self.contact.T @ step)
        self.dual_friction = np.clip(linearized, -self.slip_bound, self.slip_bound)


def _solve(functional: PenaltyFunctional, tol: float, max_iter: int, u0) -> PenaltyResult:
    K, contact = functional.K, functional.contact
    load = np.abs(functional.f).max(initial=0.0)

    def force_scale(u):
        """The largest nodal force of the load, the elastic response or the normal contact."""
        contact_force = contact.N.T @ (contact.weights * functional.tractions(u)[0])
        return max(load, np.abs(K @ u).max(initial=0.0), np.abs(contact_force).max(initial=0.0), 1e-300)

    x0 = np.zeros(functional.f.size) if u0 is None else u0
    # the energy is piecewise quadratic in the normal part for p = 1: finished when the active set repeats
    pattern = functional.active if functional.power == 1 else None
    u, steps, converged, history = newton(
        functional.energy,
        functional.gradient,
        functional.hessian,
        x0,
        force_scale,
        tol,
        max_iter,
        pattern,
        functional.after_step,
    )
    pressure, friction = functional.tractions(u)
    return PenaltyResult(u, pressure, friction, steps, converged, history)


def penalty_signorini(
    K, f, contact: ContactTrace, penalty: float, power: float = 1.0, tol: float = 1e-10, max_iter: int = 50, u0=None
) -> PenaltyResult:
    """Signorini by exterior penalty / normal compliance (Oden's algorithm I): λ_N = c (u_N − g)_+^p.

    p = 1: semismooth Newton on the active set of penetrating nodes, finished when
    the active set repeats and ‖∇E‖∞ ≤ tol × force scale. p > 1: damped Newton
    (the energy is C²-smooth enough). The error against Signorini is O(c^(−1/p)).
    """
    check_inputs(contact, penalty, power)
    return _solve(PenaltyFunctional(K, f, contact, penalty, power), tol, max_iter, u0)


def regularized_tresca(
    K,
    f,
    contact: ContactTrace,
    slip_bound,
    epsilon: float,
    penalty: float,
    power: float = 1.0,
    tol: float = 1e-10,
    max_iter: int = 100,
    u0=None,
    primal_dual: bool = True,
) -> PenaltyResult:
    """Tresca friction regularized by ε with penalty normal contact (Oden's algorithm II).

    Minimizes E(u) + Σ w s sqrt(u_T² + ε²) by damped Newton; ``slip_bound`` s is a
    scalar or one value per contact node. λ_T = −s u_T / sqrt(u_T² + ε²), |λ_T| < s.
    ``primal_dual=False`` is plain Newton with the exact Hessian (Oden's "standard
    Newton–Raphson"): fine from u = 0, slow from a slipping start when ε is small;
    see :class:`PenaltyFunctional`.
    """
    s = check_inputs(contact, penalty, power, slip_bound, epsilon)
    return _solve(PenaltyFunctional(K, f, contact, penalty, power, s, epsilon, primal_dual), tol, max_iter, u0)


def penalty_coulomb(
    K,
    f,
    contact: ContactTrace,
    friction: float,
    epsilon: float,
    penalty: float,
    power: float = 1.0,
    relaxation: float = 1.0,
    tol: float = 1e-8,
    max_iter: int = 50,
    newton_tol: float = 1e-10,
    newton_max_iter: int = 100,
) -> PenaltyResult:
    """Coulomb friction as the fixed point s = F λ_N over the regularized penalty Tresca problem.

    s⁰ = 0 (the frictionless solve), then s ← (1 − ω) s + ω F λ_N(s) until
    ‖Δs‖∞ ≤ tol ‖s‖∞. Each inner solve (primal–dual Newton) starts from the previous
    displacement. ``iterations`` counts fixed-point steps. The
    map need not be contractive: an unconverged history is an answer, not an error.
    The fields returned are those of the last inner solve, whose bound s is within
    ``tol`` of F λ_N when converged.
    """
    check_inputs(contact, penalty, power, 0.0, epsilon)
    if not friction >= 0:
        raise ValueError(f"friction: the coefficient must be ≥ 0, got {friction}")
    if not 0 < relaxation <= 1:
        raise ValueError(f"relaxation: ω must be in (0, 1], got {relaxation}")
    if max_iter < 1:
        raise ValueError(f"max_iter: at least one fixed-point step, got {max_iter}")
    slip_bound = np.zeros(contact.m)
    changes, inner_steps = [], []
    u, converged = None, False
    while len(changes) < max_iter:
        functional = PenaltyFunctional(K, f, contact, penalty, power, slip_bound, epsilon)
        inner = _solve(functional, newton_tol, newton_max_iter, u)
        inner_steps.append(inner.iterations)
        u = inner.u
        if not inner.converged:
            break
        updated = (1.0 - relaxation) * slip_bound + relaxation * friction * inner.pressure
        changes.append(np.abs(updated - slip_bound).max() / max(np.abs(updated).max(), 1e-300))
        slip_bound = updated
        if changes[-1] <= tol:
            converged = True
            break
    history = {"slip_bound_change": np.array(changes), "newton_iterations": np.array(inner_steps)}
    return PenaltyResult(u, inner.pressure, inner.friction, len(changes), converged, history)
