"""Newton's method on a plastic step's optimality system: the fast path from the last step, and the finish of the
interior point's answer (docs/plasticity.md).

At fixed u the plastic strain is the radial return's closed form, so the step is the minimization over u alone of the
reduced energy

    Φ(u) = ½uᵀKu − fᵀu + Σ_q w_q [ψ_q(Πᵀε_q − α_q^old) − μ‖Πᵀε_q‖²],
    ψ(e) = min over Δα of μ‖e − Δα‖² + (η_p/2Δt)‖Δα‖² + r‖Δα‖,

convex and C¹ with the semismooth gradient ∇Φ = Ku − G(α^old + Δα(u)) − f and the consistent tangent as generalized
Hessian, under the contact rows. On a guess of the active contact rows A (closed nodes; sticking friction points,
R_S u + o_S = 0; the slipping ones' tractions held at ±s, a linear term of Φ) Newton's step solves

    [J  E_Aᵀ] [d]   [−∇Φ − E_fixedᵀ y_fixed]
    [E_A  0 ] [z] = [e_A − E_A u           ]

on one sparse Cholesky of J (its ordering kept from step to step): by eliminating the active rows' DOFs where each
row moves one DOF of its own (nodes against a flat obstacle), else by the Schur complement E_A J⁻¹ E_Aᵀ. After the
step that meets the rows, the iterates stay on them, and an Armijo line search on Φ — the merit a residual norm is
not: a semismooth residual's norm need not decrease along Newton's direction where points start or stop flowing —
makes the iteration globally convergent for a fixed A (a convex function on an affine set); primal-dual active-set
rounds (the natural maps of Signorini's and Tresca's laws) correct A until it settles feasible.

In 3-D a slipping point's traction −s v/‖v‖ turns with its slip: it is not held fixed but its dissipation s‖R_k u + o_k‖
joins Φ (convex, smooth where the point slips), with the curvature s/‖v‖ (I − nnᵀ) of the disc's projection in J; the
sticking points are rows as in 2-D, and the natural map λ_T − v/ω against the disc sorts them each round.

Normal compliance's energy Σ w c/(p+1) ((C N u − C g)/w)₊^(p+1) joins Φ likewise (its rows never active).

Built for Signorini, normal compliance and exact Tresca friction (2-D intervals, 3-D discs) against a rigid obstacle or
between bodies, under displacement control (no ε-regularized friction, no force control: not built). :func:`newton`
returns the answer or the reason it gave up; the caller falls back to the conic program.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..fem.factorization import factorize
from ..fem.plasticity import PlasticPoints
from ..formulations.fields import ContactFields
from ..formulations.primal import carrying
from ..results.plastic_state import radial_return

ROUNDS, STEPS, LINE_SEARCH = 8, 30, 30
"""Active-set rounds, Newton steps in all of them, halvings of a step: a bounded cost before the conic fallback."""
CONVERGED = 1e-12
"""Largest equilibrium residual, relative to the largest nodal force, at which Newton stops."""
SECANT = 10.0
"""Largest multiple of the last increment the secant predictor takes."""
ROUNDING = 1e-10
"""Residual below which Newton also stops when a step no longer halves it (the Schur complement's rounding)."""
NOISE = 1e-12
"""Entries of the contact rows below NOISE × the largest are round-off (dropped)."""
ARMIJO = 1e-4
"""Sufficient decrease of Φ along a step, in units of the directional derivative."""
ROUNDOFF = 1e-13
"""Changes of Φ below ROUNDOFF · |Φ| are rounding: near the answer the full step is taken."""
PATTERN_FILL = 1e-300
"""Weight of the structural entries added to J so that its first factorization holds every later J's pattern
(the entries are below the floats' resolution of any J entry, so they change no value)."""


def applies(model) -> bool:
    """Signorini or normal compliance, with or without exact Tresca friction (2-D intervals, 3-D discs), against a rigid
    obstacle or between bodies, under displacement control."""
    contact, friction = model.fem.contact, model.friction
    exact = friction is None or (model.epsilon is None and friction.coupling is None)
    return exact and contact.obstacle_coupling is None  # compliance's p ≥ 1 (the law's own check): finite curvature


def compliance(excess_rows: np.ndarray, weights: np.ndarray, law: tuple[float, float]):
    """Normal compliance's energy Σ w c/(p+1) x^(p+1), x = ((E_N u − e_N)/w)₊ the excess of each row (``excess_rows``
    = E_N u − e_N), as in the primal program: its value, the pressures c x^p (their force is E_Nᵀ·) and the diagonal of
    its Hessian on the rows, c p x^(p−1)/w where x > 0."""
    stiffness, exponent = law
    excess = np.maximum(excess_rows / weights, 0.0)
    pressure = stiffness * excess**exponent
    curvature = np.where(excess > 0, stiffness * exponent * excess ** (exponent - 1) / weights, 0.0)
    return float(weights @ (stiffness / (exponent + 1) * excess ** (exponent + 1))), pressure, curvature


def dissipation(w: np.ndarray, dim: int, bound: np.ndarray, slipping: np.ndarray, floor, heading: np.ndarray):
    """The 3-D slipping points' dissipation Σ_k s_k‖w_k‖ — w = E_T u − e_T the friction rows' values (the weighted
    slip, negated; component-major, ``dim`` components per point), summed over the points ``slipping`` — its value,
    the tractions s w/‖w‖ at those points (0 elsewhere; their force is E_Tᵀ·) and its Hessian, per point
    s/‖w‖ (I − nnᵀ), n = w/‖w‖: the disc's counterpart of the interval's fixed ±s, with the curvature of the elastic
    newton-cg's ball projection. Below ``floor`` a point has no direction of its own: n is its ``heading`` (the
    natural map's, points × d − 1), and ‖w‖ is floored there (a finite, stiff curvature across it)."""
    count = bound.size
    points = w.reshape(dim, count).T * slipping[:, None]
    size = np.linalg.norm(points, axis=1)
    moving = size > floor
    size = np.maximum(size, floor)
    normal = np.where(moving[:, None], points / size[:, None], heading)
    traction = (bound * slipping)[:, None] * normal
    blocks = (bound * slipping / size)[:, None, None] * (np.eye(dim) - normal[:, :, None] * normal[:, None, :])
    index = np.arange(dim * count).reshape(dim, count).T  # each point's rows
    rows, columns = np.repeat(index, dim, axis=1), np.tile(index, (1, dim))
    hessian = sp.csr_matrix((blocks.ravel(), (rows.ravel(), columns.ravel())), shape=(dim * count, dim * count))
    return float(bound[slipping] @ size[slipping]), traction.T.ravel(), hessian


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
    derivative = sp.bsr_matrix((blocks, np.arange(count), np.arange(count + 1)), shape=(count * k, count * k))
    return radial_return(points, u_full, old, radius, viscosity), derivative.tocsr()


@dataclass
class Plastic:
    """The plastic data of a step (scaled): points, coupling G (full DOFs × k·points), α^old, r and η_p/Δt per point,
    and a factorization of the tangent kept from step to step (its ordering)."""

    points: PlasticPoints
    coupling: sp.spmatrix
    old: np.ndarray
    radius: np.ndarray
    viscosity: np.ndarray
    factors: dict

    def energy(self, u_full, increment) -> float:
        """Σ_q w_q [ψ_q(e_q) − μ‖Πᵀε_q‖²] at the yielding points (elsewhere ψ_q(e) = μ‖Πᵀε‖²), Δα = ``increment``."""
        p, k = self.points, self.points.components
        yielding = np.isfinite(self.radius)
        strain = (p.deviatoric @ u_full).reshape(-1, k)[yielding]
        e = strain - self.old.reshape(-1, k)[yielding]
        flow = increment.reshape(-1, k)[yielding]
        size = np.linalg.norm(flow, axis=1)
        shear = p.shear[yielding]
        point = 0.5 * shear * (np.sum((e - flow) ** 2, axis=1) - np.sum(strain**2, axis=1)) \
            + 0.5 * self.viscosity[yielding] * size**2 + self.radius[yielding] * size
        return float(p.weights[yielding] @ point)


def secant(model, u: np.ndarray, y: np.ndarray, increment: np.ndarray | None) -> np.ndarray:
    """The secant predictor: s × the last step's ``increment``, s the least-squares fit of the gaps of the rows that
    carried a pressure (y > 0) in the new step, within [0, SECANT]; 0 without such rows. The tangent predictor from
    the last state (Newton's first step) pushed the punch's nodes in alone and made most points flow, then took
    10–20 damped steps to recover (docs/plasticity.md)."""
    contact = model.fem.contact
    closed = y[: contact.m] > 0
    if increment is None or not closed.any():
        return np.zeros_like(u)
    A = (model.C @ contact.N).tocsr()[closed]
    gap = (contact.weighted_gap(model.C) - model.C @ contact.normal_offset)[closed] - A @ u
    move = A @ increment
    return float(np.clip(move @ gap / max(move @ move, np.finfo(float).tiny), 0.0, SECANT)) * increment


def unit_rows(B: sp.spmatrix) -> tuple[np.ndarray, np.ndarray] | None:
    """The DOF and the coefficient of each row of ``B`` where every row has one nonzero, on a DOF of its own; else
    None. Such rows are eliminated from the Newton system like Dirichlet conditions: one solve per step instead of
    the Schur complement's one per row."""
    B = sp.csr_matrix(B, copy=True)
    B.eliminate_zeros()
    if B.shape[0] == 0 or (np.diff(B.indptr) != 1).any() or np.unique(B.indices).size != B.shape[0]:
        return None
    return B.indices, B.data


def cholesky(plastic: Plastic, J: sp.spmatrix, G: sp.spmatrix, D: sp.spmatrix, dim: int,
             curved: sp.spmatrix | None = None):
    """A Cholesky factorization of the tangent J (free DOFs), refactorizing the step's earlier one on its pattern (J's
    pattern is K's with the points' k × k blocks coupled through G and D, and the rows ``curved`` of the 3-D slipping
    points' dissipation and of normal compliance); None where J is singular."""
    factors = plastic.factors
    if "pattern" not in factors:
        k, count = plastic.points.components, plastic.points.count
        blocks = sp.kron(sp.eye(count), np.ones((k, k)))  # the tangent's blocks, full
        pattern = (abs(J) + abs(G) @ blocks @ abs(D)).tocsr()
        if curved is not None:
            pattern = pattern + abs(curved).T @ abs(curved)
        pattern.data[:] = 1.0
        factors["pattern"] = pattern
    J = J + PATTERN_FILL * factors["pattern"]
    try:
        if "J" in factors and factors["J"].size == J.shape[0]:
            factors["J"].refactorize(J)
        else:
            factors["J"] = factorize(J, dim=dim)
            factors["J"].size = J.shape[0]
    except (ValueError, RuntimeError):  # SceneError (singular) is a ValueError; PARDISO's zero pivot a RuntimeError
        factors.pop("J", None)
        return None
    return factors["J"]


@dataclass
class Outcome:
    """Newton's answer (None if it gave up), the Newton steps taken and, if it gave up, why."""

    fields: ContactFields | None
    steps: int
    reason: str = ""


def newton(model, plastic: Plastic, u: np.ndarray, y: np.ndarray, rounds: int = ROUNDS) -> Outcome:
    """The step's exact answer from the guess ``u`` (free DOFs) and contact multipliers ``y`` (pressures, then friction
    tractions; scaled), by the globalized semismooth Newton of the module docstring."""
    fem, friction = model.fem, model.friction
    contact = fem.contact
    # the contact rows E (normal: C N; friction: −R) with E u ≤ e (normal) or E u = e (sticking), multipliers y whose
    # force is Eᵀy: y = (pressures, friction tractions λ_T)
    A = (model.C @ contact.N).tocsr()
    m = A.shape[0]
    E = sp.vstack([A] + ([-friction.R] if friction else []), format="csr")
    # entries at round-off (a mortar row's component along a DOF the rollers hold, 1e-16 of the others) carry nothing:
    # kept, such a row is a constraint of noise (a singular Schur complement, a 3-D point slipping by 1e-17 forever)
    E.data[np.abs(E.data) <= NOISE * np.abs(E.data).max(initial=0.0)] = 0.0
    E.eliminate_zeros()
    e = np.concatenate([contact.weighted_gap(model.C) - model.C @ contact.normal_offset]
                       + ([friction.offset] if friction else []))
    weights = contact.row_weights(model.C)
    bound = model.slip_bound if friction else np.zeros(0)
    dim = friction.dim if friction else 1
    rows = carrying(E)
    compliant = model.compliance  # normal compliance: its rows are an energy of u, never active
    # the rows with a curvature in J: compliance's, the 3-D discs'
    with_curvature = [E[:m]] * (compliant is not None) + [E[m:]] * (dim > 1)
    curved = sp.vstack(with_curvature) if with_curvature else None
    # a 3-D slipping point's slip below which it has no direction of its own (its curvature s/‖w‖ floored there)
    floor = CONVERGED * max(1.0, np.abs(u).max()) * (friction.weights if friction else 1.0)
    G, D = plastic.coupling[fem.free], plastic.points.deviatoric[:, fem.free].tocsr()
    force = max(np.abs(fem.f).max(initial=0.0), np.abs(fem.K @ u).max(), contact.weights.max())

    def sets(u, y):
        """Active rows (closed nodes, sticking points), the multipliers fixed by the law (2-D slipping points' ±s)
        and the 3-D slipping points with their natural maps' directions, by the natural maps of Signorini's and
        Tresca's laws."""
        active = rows & np.concatenate([y[:m] > (e[:m] - A @ u) / weights, np.zeros(E.shape[0] - m, bool)])
        active[:m] &= compliant is None
        fixed, slipping, heading = np.zeros_like(y), np.zeros(bound.size, bool), None
        if friction:
            trial = y[m:] + (E[m:] @ u - e[m:]) / np.tile(friction.weights, dim)  # λ_T − v, v = (R u + o)/ω the slip
            stick = np.linalg.norm(trial.reshape(dim, -1), axis=0) < bound
            active[m:] = rows[m:] & np.tile(stick, dim)
            if dim == 1:
                fixed[m:] = np.where(rows[m:] & ~stick, bound * np.sign(trial), 0.0)
            else:
                slipping = rows[m:].reshape(dim, -1).any(axis=0) & ~stick
                points = trial.reshape(dim, -1).T
                heading = points / np.maximum(np.linalg.norm(points, axis=1), np.finfo(float).tiny)[:, None]
        return active, fixed, slipping, heading

    def state(u, fixed, slipping, heading):
        """Φ (with the slipping tractions' work, the 3-D slipping points' dissipation, normal compliance's energy), its
        gradient, the tangent's blocks at u, the multipliers these terms give (all rows; 0 at the others) and their
        Hessian on the rows (None without 3-D slipping points or compliance)."""
        u_full = fem.full(u)
        increment, M = tangent(plastic.points, u_full, plastic.old, plastic.radius, plastic.viscosity)
        Eu = E @ u
        gradient = fem.K @ u - G @ (plastic.old + increment) - fem.f + E.T @ fixed
        merit = 0.5 * u @ (fem.K @ u) - fem.f @ u + plastic.energy(u_full, increment) + fixed @ Eu
        traction, curvature = fixed.copy(), [sp.csr_matrix((m, m)), sp.csr_matrix((E.shape[0] - m,) * 2)]
        if slipping.any():
            value, traction[m:], curvature[1] = dissipation(Eu[m:] - e[m:], dim, bound, slipping, floor, heading)
            gradient, merit = gradient + E[m:].T @ traction[m:], merit + value
        if compliant is not None:
            value, traction[:m], diagonal = compliance(Eu[:m] - e[:m], weights, compliant)
            gradient, merit, curvature[0] = gradient + E[:m].T @ traction[:m], merit + value, sp.diags(diagonal)
        hessian = sp.block_diag(curvature, format="csr") if slipping.any() or compliant is not None else None
        return merit, gradient, M, traction, hessian

    def direction(M, hessian, gradient, active, u):
        """Newton's step d and the active rows' multipliers z (None, None if the system is singular)."""
        J, B, rhs = fem.K - G @ (M @ D), E[active], e[active] - E[active] @ u
        if hessian is not None:
            J = J + E.T @ hessian @ E
        unit = unit_rows(B)
        if unit is not None:  # each active row moves one DOF (nodes against a flat obstacle): eliminated in J
            dofs, values = unit
            prescribed = np.zeros(u.size)
            prescribed[dofs] = rhs / values
            keep = np.ones(u.size)
            keep[dofs] = 0.0
            eliminated = sp.diags(keep) @ J @ sp.diags(keep) + sp.diags(1.0 - keep)
            factors = cholesky(plastic, eliminated, G, D, fem.dim, curved)
            if factors is not None:
                b = -gradient - J @ prescribed
                b[dofs] = prescribed[dofs]
                d = factors.solve(b)
                return d, (-gradient - J @ d)[dofs] / values
        factors = None if plastic.factors.get("saddle") else cholesky(plastic, J, G, D, fem.dim, curved)
        if factors is None:  # J singular (a body held by its contact alone): the saddle-point matrix is not
            plastic.factors["saddle"] = True
            try:
                step = spla.splu(sp.bmat([[J, B.T], [B, None]], format="csc")).solve(np.concatenate([-gradient, rhs]))
            except RuntimeError:  # "Factor is exactly singular"
                return None, None
            return step[: u.size], step[u.size:]
        free = factors.solve(-gradient)
        if not active.any():
            return free, np.zeros(0)
        try:
            z = np.linalg.solve(factors.schur(B), B @ free - rhs)
        except np.linalg.LinAlgError:
            return None, None
        return free - factors.solve(B.T @ z), z

    (active, fixed, slipping, heading), steps, weight = sets(u, y), 0, 0.0
    for _ in range(rounds):
        merit, gradient, M, traction, hessian = state(u, fixed, slipping, heading)
        y = np.where(active, y, traction)
        previous = np.inf
        while True:
            residual = np.abs(gradient + E[active].T @ y[active]).max() / force
            violation = e[active] - E[active] @ u
            met = np.abs(violation).max(initial=0.0) <= CONVERGED * max(1.0, np.abs(u).max())
            if met and (residual <= CONVERGED or ROUNDING >= residual > previous / 2):
                break  # converged, or stalled at the solves' rounding
            if steps == STEPS:
                return Outcome(None, steps, f"Newton did not converge in {STEPS} steps ({rounds} active-set rounds)")
            d, z = direction(M, hessian, gradient, active, u)
            if d is None:
                return Outcome(None, steps, "the tangent (or its Schur complement on the active rows) is singular")
            steps, previous = steps + 1, residual
            # Armijo on Φ + ρ‖e_A − E_A u‖₁, exact for ρ > max |z|: the steps meeting the active rows are damped too
            weight = max(weight, 2.0 * np.abs(z).max(initial=0.0))
            slope = gradient @ d - weight * np.abs(violation).sum()
            penalized = merit + weight * np.abs(violation).sum()
            for length in 0.5 ** np.arange(LINE_SEARCH):
                trial = state(u + length * d, fixed, slipping, heading)
                missed = (1 - length) * np.abs(violation).sum()  # the rows are linear: the violation shrinks so
                if trial[0] + weight * missed <= penalized + ARMIJO * length * slope \
                        + ROUNDOFF * max(abs(merit), abs(trial[0])):
                    break
            else:
                return Outcome(None, steps, f"the line search on the step energy found no decrease in {LINE_SEARCH} "
                               "halvings")
            u = u + length * d
            merit, gradient, M, traction, hessian = trial
            y[active] = z
            y = np.where(active, y, traction)
        settled, law, slips, heading = sets(u, y)
        slack = e[:m] - A @ u  # in the units of the rows' violation that stopped Newton
        tolerance = CONVERGED * max(1.0, np.abs(y).max(initial=0.0))
        closed = slack[rows[:m]].min(initial=0.0) >= -CONVERGED * max(1.0, np.abs(u).max())
        feasible = (compliant is not None or closed) \
            and y[:m].min(initial=0.0) >= -tolerance \
            and (np.linalg.norm(y[m:].reshape(dim, -1), axis=0) <= bound + tolerance).all()
        if np.array_equal(settled, active) and np.array_equal(law, fixed) and np.array_equal(slips, slipping) \
                and feasible:
            pressure = np.maximum(y[:m], 0.0)  # a closed row's pressure may end at −1e-12 of the largest: rounding
            return Outcome(ContactFields(u=u, pressure=pressure, friction=y[m:] if friction else None), steps)
        active, fixed, slipping = settled, law, slips
    return Outcome(None, steps, f"the contact's active set did not settle in {rounds} rounds")
