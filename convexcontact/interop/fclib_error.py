"""The field's measures of an answer to an FClib problem, on the matrices as read (never a symmetrized copy).

- :func:`merit`: fclib's ``fclib_merit_local`` (MERIT_1), ‖r − Π_C(r − û)‖ / (1 + √‖q‖);
- :func:`siconos_error`: Siconos' ``fc3d_compute_error`` / ``fc2d_compute_error``, the same natural map
  divided by max(‖q‖, ‖r‖, ‖u‖): unit-free, the measure of the Acary–Brémond–Huber campaign;
- :func:`siconos_error_global`: ``gfc3d_compute_error``, the relative equilibrium residual
  ‖M v − H r − f‖ / max(‖f‖, ‖M v‖, ‖H r‖) plus the natural map on u = Hᵀ v + w over max(‖u‖, ‖r‖);
- :func:`natural_residuals`: our certificate (DESIGN.md), each condition's largest violation.

û = u + [μ‖u_T‖, 0(, 0)] per contact (De Saxcé's modified velocity); Π_C the projection on the
friction cone C_μ = {‖r_T‖ ≤ μ r_N}. Everything here is a pure function of the problem and the answer.
"""

from __future__ import annotations

import numpy as np

from .fclib import GlobalProblem, LocalProblem

TINY = 1e-300
EPSILON = np.finfo(float).eps
"""Siconos divides by its scaling only above DBL_EPSILON (local) or √DBL_EPSILON (global), as here."""


def per_contact(x: np.ndarray, spacedim: int) -> np.ndarray:
    return np.asarray(x, dtype=float).reshape(-1, spacedim)


def project_on_cone(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Euclidean projection of each row [x_N, x_T] onto C_μ = {‖x_T‖ ≤ μ x_N}."""
    normal, tangent = x[:, 0], x[:, 1:]
    size = np.linalg.norm(tangent, axis=1)
    inside = size <= mu * normal
    polar = mu * size <= -normal  # in the polar cone: projects to 0
    on_axis = (mu * size + normal) / (mu * mu + 1.0)  # the projection's normal component on the boundary
    out = np.zeros_like(x)
    out[inside] = x[inside]
    edge = ~inside & ~polar
    out[edge, 0] = on_axis[edge]
    out[edge, 1:] = (mu * on_axis / np.maximum(size, TINY))[edge, None] * tangent[edge]
    return out


def check_size(value, size: int, name: str) -> np.ndarray:
    """``value`` as a float vector of ``size`` entries, or a ValueError naming it (a wrong size would otherwise
    surface as numpy's broadcasting message)."""
    if np.shape(value) != (size,):
        raise ValueError(f"{name}: must hold {size} numbers (FClib's order, [N, T…] per contact for forces), "
                         f"got shape {np.shape(value)}")
    return np.asarray(value, dtype=float)


def velocity(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> np.ndarray:
    """u = W r + q (+ V λ for a mixed problem)."""
    r = check_size(r, problem.q.size, "r")
    u = problem.W @ r + problem.q
    if problem.V is None:
        return u
    if l is None:
        raise ValueError("fclib_local/V: a problem with equalities needs their multipliers l (λ) as well as r")
    return u + problem.V @ check_size(l, problem.V.shape[1], "l")


def equality_residual(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None) -> np.ndarray:
    """Vᵀ r + R λ + s (empty without equalities)."""
    if problem.V is None:
        return np.zeros(0)
    residual = problem.V.T @ r + problem.s
    return residual if problem.R is None else residual + problem.R @ l


def natural_map(u: np.ndarray, r: np.ndarray, mu: np.ndarray, spacedim: int) -> float:
    """‖r − Π_C(r − û)‖ over all contacts: zero exactly at Coulomb's law (Siconos' and fclib's numerator)."""
    u, z = per_contact(u, spacedim), per_contact(r, spacedim)
    shifted = u.copy()
    shifted[:, 0] += mu * np.linalg.norm(u[:, 1:], axis=1)
    return float(np.linalg.norm(z - project_on_cone(z - shifted, mu)))


def equality_term(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None) -> float:
    """fclib's second term for a mixed problem, ‖Vᵀ r + R λ + s‖ / (1 + ‖s‖); 0 without equalities."""
    if problem.V is None:
        return 0.0
    return float(np.linalg.norm(equality_residual(problem, r, l)) / (1.0 + np.linalg.norm(problem.s)))


def merit(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> float:
    """FClib's merit function MERIT_1 (``fclib_merit_local``), for spacedim 2 and 3.

    ‖r − Π_C_μ(r − û)‖ / (1 + √‖q‖), û = W r + V λ + q + [μ‖u_T‖, 0, 0] per contact, plus, with
    equalities, ‖Vᵀ r + R λ + s‖ / (1 + ‖s‖). The normalization is fclib's as coded,
    ``sqrt(error)/(1.0 + sqrt(dnrm2(q)))``: 1 + the square root of ‖q‖ (not 1 + ‖q‖). fclib itself
    computes it for spacedim 3 only; the formula is the same in 2-D.
    """
    value = natural_map(velocity(problem, r, l), r, problem.mu, problem.spacedim)
    return value / (1.0 + np.sqrt(np.linalg.norm(problem.q))) + equality_term(problem, r, l)


def siconos_error(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> float:
    """Siconos' unit-free error (``fc3d_compute_error``; ``fc2d_compute_error`` in 2-D, the same formula).

    ‖r − Π_C(r − û)‖ / max(‖q‖, ‖r‖, ‖u‖) with u = W r + q recomputed from r (the divisor only where it
    exceeds DBL_EPSILON). Siconos has no mixed local problem; with equalities u includes V λ and the
    relative residual ‖Vᵀ r + R λ + s‖ / max(‖s‖, ‖Vᵀ r‖) is added (our extension, gfc3d's pattern).
    """
    u = velocity(problem, r, l)
    value = natural_map(u, r, problem.mu, problem.spacedim)
    value /= relative(np.linalg.norm(problem.q), np.linalg.norm(r), np.linalg.norm(u), floor=EPSILON)
    if problem.V is not None:
        size = relative(np.linalg.norm(problem.s), np.linalg.norm(problem.V.T @ r), floor=EPSILON)
        value += float(np.linalg.norm(equality_residual(problem, r, l))) / size
    return float(value)


def siconos_error_global(problem: GlobalProblem, r: np.ndarray, v: np.ndarray) -> float:
    """Siconos' ``gfc3d_compute_error`` (Siconos' q is FClib's f, its b FClib's w).

    ‖M v − H r − f‖ / max(‖f‖, ‖M v‖, ‖H r‖) + ‖r − Π_C(r − û)‖ / max(‖u‖, ‖r‖), u = Hᵀ v + w, each divisor
    used only above √DBL_EPSILON, as Siconos does. M and H as read from the file.
    """
    r, v = check_size(r, problem.H.shape[1], "r"), check_size(v, problem.M.shape[0], "v")
    forces, reactions = problem.M @ v, problem.H @ r
    balance = np.linalg.norm(forces - reactions - problem.f)
    balance /= relative(np.linalg.norm(problem.f), np.linalg.norm(forces), np.linalg.norm(reactions),
                        floor=np.sqrt(EPSILON))
    u = problem.H.T @ v + problem.w
    law = natural_map(u, r, problem.mu, problem.spacedim)
    law /= relative(np.linalg.norm(u), np.linalg.norm(r), floor=np.sqrt(EPSILON))
    return float(balance + law)


def relative(*norms: float, floor: float) -> float:
    """Siconos' divisor: the largest of ``norms`` where it exceeds ``floor``, else 1 (an absolute error)."""
    largest = max(norms)
    return largest if abs(largest) > floor else 1.0


def natural_residuals(problem: LocalProblem, r: np.ndarray, l: np.ndarray | None = None) -> dict[str, float]:
    """Our certificate of the answer: the largest violation of each condition, by natural maps.

    Forces are measured against p_ref = max(‖r‖∞, ‖q‖∞/max|W|), velocities against u_ref = max(‖u‖∞,
    ‖q‖∞); friction by ‖r_T − Π_B(μ r_N)(r_T − ρ u_T)‖ with ρ = p_ref/u_ref (DESIGN.md, discrete certificate);
    equalities against max(‖s‖∞, ‖Vᵀ r‖∞).
    """
    d, mu = problem.spacedim, problem.mu
    u = per_contact(velocity(problem, r, l), d)
    z = per_contact(r, d)
    scale_W = abs(problem.W).max() if problem.W.nnz else 0.0
    q_max = np.abs(problem.q).max(initial=0.0)
    p_ref = max(np.abs(z).max(initial=0.0), q_max / scale_W if scale_W > 0 else 0.0, TINY)
    u_ref = max(np.abs(u).max(initial=0.0), q_max, TINY)
    bound = mu * np.maximum(z[:, 0], 0.0)
    trial = z[:, 1:] - (p_ref / u_ref) * u[:, 1:]
    shrink = np.minimum(1.0, bound / np.maximum(np.linalg.norm(trial, axis=1), TINY))
    values = {
        "pressure_sign": np.maximum(-z[:, 0], 0.0).max(initial=0.0) / p_ref,
        "non_penetration": np.maximum(-u[:, 0], 0.0).max(initial=0.0) / u_ref,
        "complementarity": np.abs(np.minimum(z[:, 0] / p_ref, u[:, 0] / u_ref)).max(initial=0.0),
        "friction_bound": np.maximum(np.linalg.norm(z[:, 1:], axis=1) - bound, 0.0).max(initial=0.0) / p_ref,
        "friction_law": np.linalg.norm(z[:, 1:] - shrink[:, None] * trial, axis=1).max(initial=0.0) / p_ref,
    }
    if problem.V is not None:
        size = max(np.abs(problem.s).max(initial=0.0), np.abs(problem.V.T @ r).max(initial=0.0), TINY)
        values["equalities"] = np.abs(equality_residual(problem, r, l)).max(initial=0.0) / size
    return {k: float(v) for k, v in values.items()}
