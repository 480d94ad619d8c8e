"""Newton polish for programs whose cones bound their own variables (second-order cones too).

Bound form: every row of a nonnegative or second-order cone holds at most one variable, no
variable is in two such rows, and a second-order cone's first row holds none. With
s_r = b_r − a_r x_j, a nonnegative row is a bound on x_j and a second-order cone is a ball
‖w‖ ≤ ρ, w_r = b_r − a_r x_j, of constant radius ρ = b₀. Zero-cone rows may be general. The
dual of a frictional contact program has this form (λ_N ≥ 0, ‖λ_T,k‖ ≤ s_k).

A guess of the active bounds and of the balls whose sphere the answer lies on makes the
program a smooth one on a manifold. Newton's method there — steps in the tangent space of
the spheres, retracted onto them, the spheres' curvature ν/ρ in the reduced Hessian — ends
at that guess's exact KKT point in a few dense Cholesky solves, where an interior point needs
one factorization per iteration and cannot be warm-started. As in :mod:`.polish`, rounds of
primal-dual active-set changes follow, and the answer is kept only if it is feasible, dual
feasible and stationary.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..conic import ConicProgram, ConicSolution

FEASIBLE = 1e-10
"""Largest violation (relative to the answer's scale) a polished answer may have."""
STATIONARY = 1e-11
"""Largest reduced gradient (relative to the objective's scale) at which Newton stops."""
ROUNDS = 20
"""Active-set rounds before polishing gives up (and the interior point runs or its answer stands)."""
NEWTON_STEPS = 5
"""Newton steps per round: a wrong guess shows in the signs long before Newton would converge on it
(a sphere pulled on by ν < 0 makes the reduced Hessian wrong and Newton only linear), so the guess
is corrected every few steps, from where Newton got to."""
NEGLIGIBLE = 1e-200
"""Radii below this fraction of the program's scale are taken as 0 (see :func:`centre`)."""
DAMPING = 1e-12
"""Levenberg–Marquardt damping of the reduced Hessian, relative to P's largest diagonal entry."""


@dataclass(frozen=True)
class BoundForm:
    """Where each cone row's variable is: bounds (row, variable, coefficient), balls of
    ``size`` rows after their radius row, and the general equality rows."""

    equality: np.ndarray
    bound_rows: np.ndarray
    bound_vars: np.ndarray
    bound_coef: np.ndarray
    ball_radius_rows: np.ndarray  # (k,)
    ball_rows: np.ndarray  # (k, p)
    ball_vars: np.ndarray  # (k, p)
    ball_coef: np.ndarray  # (k, p)


def bound_form(program: ConicProgram) -> BoundForm | None:
    """The program's bound form, or None when it has none (or balls of different sizes). A program with
    bounds only (no balls) has one too."""
    A = sp.csr_matrix(program.A)
    counts = np.diff(A.indptr)
    column = np.full(A.shape[0], -1)
    coef = np.zeros(A.shape[0])
    single = counts == 1
    column[single] = A.indices[A.indptr[:-1][single]]
    coef[single] = A.data[A.indptr[:-1][single]]
    equality, bounds, balls, sizes = [], [], [], set()
    for cone, rows in program.blocks():
        index = np.arange(rows.start, rows.stop)
        if cone.kind == "zero":
            equality.append(index)
        elif cone.kind == "nonnegative":
            if (counts[index] > 1).any():
                return None
            bounds.append(index[counts[index] == 1])
        elif cone.kind == "soc" and counts[index[0]] == 0 and (counts[index[1:]] == 1).all():
            balls.append(index)
            sizes.add(cone.dim)
        else:
            return None
    if len(sizes) > 1:  # balls of two sizes: not vectorized
        return None
    bound_rows = np.concatenate(bounds) if bounds else np.zeros(0, int)
    ball = np.array(balls, dtype=int).reshape(len(balls), sizes.pop() if sizes else 1)
    used = np.concatenate([column[bound_rows], column[ball[:, 1:]].ravel()])
    if np.unique(used).size != used.size:
        return None
    return BoundForm(
        equality=np.concatenate(equality) if equality else np.zeros(0, int),
        bound_rows=bound_rows, bound_vars=column[bound_rows], bound_coef=coef[bound_rows],
        ball_radius_rows=ball[:, 0], ball_rows=ball[:, 1:], ball_vars=column[ball[:, 1:]], ball_coef=coef[ball[:, 1:]],
    )


def centre(radius: np.ndarray, scale: float) -> np.ndarray:
    """Balls of radius 0 — or so small beside the program's ``scale`` that their curvature ν/ρ would
    overflow (a slip bound of 9e-311, found by the fuzz suite): each is its centre, to any precision a
    solver has."""
    return radius <= NEGLIGIBLE * scale


def unit_rows(w: np.ndarray) -> np.ndarray:
    """The rows of w scaled to unit length, without under- or overflow (a slip bound of 1e-259 gave
    ‖w‖² = 0 and NaN directions). A zero row, which has no direction, becomes e₁."""
    largest = np.abs(w).max(axis=1, keepdims=True)
    scaled = np.where(largest > 0, w, np.eye(1, w.shape[1])) / np.where(largest > 0, largest, 1.0)
    return scaled / np.linalg.norm(scaled, axis=1, keepdims=True)


def tangent_bases(w: np.ndarray) -> np.ndarray:
    """Orthonormal bases (k, p, p − 1) of the planes orthogonal to the rows of w: the last
    p − 1 columns of the Householder reflection taking ŵ to ∓e₁ (vectorized over the balls)."""
    unit = unit_rows(w)
    v = unit.copy()
    v[:, 0] += np.where(unit[:, 0] >= 0, 1.0, -1.0)
    p = w.shape[1]
    reflection = np.eye(p) - 2.0 * v[:, :, None] * v[:, None, :] / (v * v).sum(axis=1)[:, None, None]
    return reflection[:, :, 1:]


def cone_polish(program: ConicProgram, solution: ConicSolution, form: BoundForm) -> ConicSolution:
    """The polished solution, or ``solution`` unchanged when the rounds do not end feasible."""
    P = program.P.toarray() if sp.issparse(program.P) else np.asarray(program.P)
    q, b, A = program.q, program.b, sp.csr_matrix(program.A)
    radius = b[form.ball_radius_rows]
    size = max(np.abs(b).max(initial=0.0), 1.0)
    if (radius < 0).any():
        return solution
    x, z = solution.x, solution.z
    # eigenvalue pairs of s = (ρ, w) and z = (ν, z̄): ρ − ‖w‖ pairs with ν + ‖z̄‖, and z = 0 where it is the larger
    w = b[form.ball_rows] - form.ball_coef * x[form.ball_vars]
    slack = radius - np.linalg.norm(w, axis=1)
    on_sphere = (slack < z[form.ball_radius_rows] + np.linalg.norm(z[form.ball_rows], axis=1)) & ~centre(radius, size)
    active = z[form.bound_rows] > b[form.bound_rows] - form.bound_coef * x[form.bound_vars]
    # a variable in no cost and no equality (the dual's multiplier of a roller direction): if no cone
    # holds it either, it keeps its value (it would make the reduced Hessian singular)
    unused = ~(P != 0).any(axis=0) & (q == 0) & (np.diff(sp.csc_matrix(A[form.equality]).indptr) == 0)
    scale_s = max(np.abs(b).max(initial=0.0), np.abs(x).max(initial=0.0), 1.0)
    scale_z = max(np.abs(z).max(initial=0.0), 1.0)
    for _ in range(ROUNDS):
        answer = _newton(P, q, b, A, form, x, z, active, on_sphere, unused)
        if answer is None:
            return solution
        x, z, converged = answer
        s = b - A @ x
        s[form.equality] = 0.0
        excess = np.linalg.norm(s[form.ball_rows], axis=1) - radius
        violated_bound = ~active & (s[form.bound_rows] < -FEASIBLE * scale_s)
        negative_bound = active & (z[form.bound_rows] < -FEASIBLE * scale_z)
        outside = ~on_sphere & (excess > FEASIBLE * scale_s)
        pulling = on_sphere & (z[form.ball_radius_rows] < -FEASIBLE * scale_z)
        if not (violated_bound.any() or negative_bound.any() or outside.any() or pulling.any()):
            if converged:
                s[form.bound_rows] = np.maximum(s[form.bound_rows], 0.0)
                return replace(solution, x=x, z=z, s=s, status="solved", info={**solution.info, "polished": True})
            continue  # a right guess so far: more Newton steps
        active = (active | violated_bound) & ~negative_bound
        on_sphere = (on_sphere | outside) & ~pulling
    return solution


def _newton(P, q, b, A, form: BoundForm, x0, z0, active, on_sphere, unused):
    """Newton steps towards the KKT point of the guess (active bounds held, chosen balls on their
    spheres) from (x0, z0): (x, z, converged), or None when the reduced system is singular."""
    n = q.size
    x = x0.copy()
    held = np.zeros(n, bool)
    rows = form.bound_rows[active]
    x[form.bound_vars[active]] = b[rows] / form.bound_coef[active]
    held[form.bound_vars[active]] = True
    radius = b[form.ball_radius_rows]
    point = centre(radius, max(np.abs(b).max(initial=0.0), 1.0))  # a ball of radius 0 is its centre
    centre_vars = form.ball_vars[point]
    x[centre_vars] = b[form.ball_rows[point]] / form.ball_coef[point]
    held[centre_vars] = True
    sphere = np.flatnonzero(on_sphere)
    sphere_vars, sphere_coef = form.ball_vars[sphere], form.ball_coef[sphere]
    sphere_b, rho = b[form.ball_rows[sphere]], radius[sphere]
    held[sphere_vars] = True  # moved through their tangent bases instead
    E = A[form.equality]
    free = np.flatnonzero(~held & ~unused)
    k, p = sphere_vars.shape
    t = p - 1
    damping = DAMPING * max(np.abs(np.diag(P)).max(initial=0.0), 1e-300)

    def retract(w):
        w = rho[:, None] * unit_rows(w)
        x[sphere_vars] = (sphere_b - w) / sphere_coef
        return w

    # a guess that puts the answer on a sphere while it is at the centre (a warm start from a slip bound of
    # 0, now positive) has no direction there: start it where the cost pulls, x − ∇f, i.e. w + a ⊙ ∇f
    w = sphere_b - sphere_coef * x[sphere_vars]
    at_centre = ~np.abs(w).any(axis=1)
    w[at_centre] = (sphere_coef * (P @ x + q)[sphere_vars])[at_centre]
    w = retract(w)
    scale = max(np.abs(q).max(initial=0.0), np.abs(P @ x).max(initial=0.0), 1.0)
    y = z0[form.equality]
    nu = z0[form.ball_radius_rows[sphere]]  # the guess's ν: a stationarity estimate is off after a change of radius
    converged = False
    for step in range(NEWTON_STEPS):
        gradient = P @ x + q
        if step:
            nu = _sphere_multipliers(gradient + E.T @ y, w, sphere_vars, sphere_coef)
        # Z: a column e_j per free variable, −a⁻¹ ⊙ (tangent basis vector in w) per sphere and direction
        bases = tangent_bases(w) if k else np.zeros((0, p, t))
        Z = sp.csc_matrix((
            np.concatenate([np.ones(free.size), (-bases / sphere_coef[:, :, None]).ravel()]),
            (np.concatenate([free, np.broadcast_to(sphere_vars[:, :, None], (k, p, t)).ravel()]),
             np.concatenate([np.arange(free.size),
                             np.broadcast_to(free.size + np.arange(k * t).reshape(k, 1, t), (k, p, t)).ravel()])),
        ), shape=(n, free.size + k * t))
        # the reduced Hessian Zᵀ P Z, plus each sphere's curvature ν/ρ, plus a damping far below P's scale:
        # Newton's fixed point is unchanged, but a sphere with ν = 0 along a direction P does not see
        # (a multiplier on a roller) stays solvable
        reduced = np.asarray(Z.T @ (Z.T @ P).T)
        reduced[np.diag_indices_from(reduced)] += damping + np.concatenate(
            [np.zeros(free.size), np.repeat(np.maximum(nu, 0.0) / rho, t)])
        try:
            factor = sla.cho_factor(reduced) if reduced.size else None
        except sla.LinAlgError:
            return None
        rhs = -(Z.T @ gradient)
        if E.shape[0]:  # the equalities by their Schur complement: E Z α = e − E x, Zᵀ(H Z α + Eᵀ y) = −Zᵀ g
            EZ = (E @ Z).toarray()
            along, across = _cho_solve(factor, rhs), _cho_solve(factor, EZ.T)
            try:
                y = np.linalg.solve(EZ @ across, EZ @ along - (b[form.equality] - E @ x))
            except np.linalg.LinAlgError:
                return None
            alpha = along - across @ y
        else:
            alpha = _cho_solve(factor, rhs)
        residual = np.abs(rhs - Z.T @ (E.T @ y)).max(initial=0.0)
        x[free] += alpha[: free.size]
        if k:
            w = retract(w + np.einsum("kpt,kt->kp", bases, alpha[free.size:].reshape(k, t)))
        if not np.isfinite(x).all():
            return None
        converged = residual <= STATIONARY * scale and np.abs(alpha).max(initial=0.0) <= STATIONARY * max(
            np.abs(x).max(), 1.0)
        if converged:
            break
    gradient = P @ x + q + E.T @ y
    z = np.zeros(b.size)
    z[form.equality] = y
    z[rows] = -gradient[form.bound_vars[active]] / form.bound_coef[active]
    nu = _sphere_multipliers(gradient, w, sphere_vars, sphere_coef)
    z[form.ball_radius_rows[sphere]] = nu
    z[form.ball_rows[sphere]] = -nu[:, None] * w / rho[:, None]
    z_point = -gradient[centre_vars] / form.ball_coef[point]
    z[form.ball_rows[point]] = z_point
    z[form.ball_radius_rows[point]] = np.linalg.norm(z_point, axis=1)
    # the multipliers come from stationarity, so it holds by construction up to the solves' round-off
    converged &= np.abs(P @ x + q + A.T @ z).max(initial=0.0) <= 1e3 * STATIONARY * scale
    return x, z, converged


def _cho_solve(factor, rhs):
    return sla.cho_solve(factor, rhs) if factor is not None else np.zeros_like(rhs)  # no unknowns left


def _sphere_multipliers(gradient, w, sphere_vars, sphere_coef):
    """ν of each sphere from stationarity along its normal: ∇L = g + ν ∇‖w‖ = g − ν a ⊙ ŵ."""
    if not sphere_vars.size:
        return np.zeros(0)
    normal = sphere_coef * unit_rows(w)
    return (normal * gradient[sphere_vars]).sum(axis=1) / (normal * normal).sum(axis=1)
