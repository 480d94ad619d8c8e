"""Closed-form reference solutions the tests check the toolkit against.

- Hertz contact in plane strain (DESIGN.md, verification case 2) and of a sphere in 3-D;
- Hild's one-triangle Coulomb example (seed 001, section 4; verification case 3).
"""

from __future__ import annotations

import numpy as np


def lame_plane_strain(E: float, nu: float) -> tuple[float, float]:
    """Lamé parameters (λ, μ) of an isotropic material."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def hertz_plane_strain(force: float, radius: float, E: float, nu: float) -> tuple[float, float]:
    """Half-width ``a`` and peak pressure ``p0`` of a 2-D Hertz contact.

    A rigid cylinder (or parabolic punch) of radius R pressed with force P per unit
    thickness on an elastic half-plane: E* = E/(1 − ν²), a = sqrt(4PR/(πE*)),
    p0 = 2P/(πa).
    """
    effective_modulus = E / (1 - nu**2)
    a = np.sqrt(4 * force * radius / (np.pi * effective_modulus))
    return float(a), float(2 * force / (np.pi * a))


def hertz_sphere(force: float, radius: float, E: float, nu: float) -> tuple[float, float]:
    """Contact radius ``a`` and peak pressure ``p0`` of 3-D Hertz contact.

    A rigid sphere (or paraboloid) of radius R pressed with force P on an elastic
    half-space: E* = E/(1 − ν²), a = (3PR/(4E*))^(1/3), p0 = 3P/(2πa²); the pressure
    is p0 sqrt(1 − r²/a²) (:func:`hertz_pressure` of the radial distance r).
    """
    effective_modulus = E / (1 - nu**2)
    a = (3 * force * radius / (4 * effective_modulus)) ** (1 / 3)
    return float(a), float(3 * force / (2 * np.pi * a**2))


def hertz_pressure(x: np.ndarray, a: float, p0: float) -> np.ndarray:
    """Hertz pressure p0 sqrt(1 − x²/a²) for |x| < a, 0 outside (x: 2-D coordinate or 3-D radius)."""
    x = np.asarray(x, dtype=float)
    return p0 * np.sqrt(np.clip(1 - (x / a) ** 2, 0.0, None))


def hild_critical_friction(nu: float) -> float:
    """Friction coefficient (λ+3μ)/(λ+μ) = 3 − 4ν above which Hild's example loses uniqueness."""
    return 3 - 4 * nu


def hild_one_triangle_solutions(
    F1: float, F2: float, friction: float, E: float, nu: float, length: float = 1.0
) -> list[dict]:
    """All solutions of Hild's one-triangle Coulomb contact problem (seed 001, Prop. 4.1).

    Triangle A(0,0), B(ℓ,0), C(0,ℓ), one P1 element in plane strain; B and C are
    fixed (Γ_D = [B,C]), a constant traction (F1, F2) acts on Γ_N = [A,C] and
    Γ_C = [A,B] rests on the rigid foundation y = 0 with zero initial gap. The only
    unknown is the displacement (u_x, u_y) of node A.

    Sign conventions (Hild's). On Γ_C the outward normal is n = (0, −1) and the
    tangent t = (n2, −n1) = (−1, 0), so

    - ``U_N`` = u·n = −u_y(A): U_N ≤ 0 is non-penetration, U_N < 0 separation;
    - ``U_T`` = u·t = −u_x(A): U_T > 0 is *left* slip (A moves to −x),
      U_T < 0 *right* slip (A moves to +x).

    Contact forces act on the body at A, nodal values in force per unit thickness:

    - ``lambda_N`` = R_N ≥ 0, the compressive normal force (the foundation pushes
      A along −n = +y); ``lambda_T`` = friction force along t.
      Coulomb: |lambda_T| ≤ F lambda_N, and in slip lambda_T = −F lambda_N sign(U_T).
      With f = (F1, F2) ℓ/2 the nodal load and K the 2×2 stiffness of A:
      K u = f + r, r = ``contact_force`` = (−lambda_T, lambda_N) in x, y.
    - ``Lambda`` = 2 lambda_N / ℓ is the paper's Λ: the nodal force divided by the
      lumped weight ℓ/2 of A (a lumped pressure). Hild's P1 multiplier, which is
      linear on [A,B] and vanishes at B, has the value λ_h(A) = 3Λ/2 = 3 lambda_N/ℓ.

    With a = λ+3μ, b = λ+μ (a/b = 3 − 4ν = F_c) the regimes are

    - separation: Λ = 0, U_T = ℓ(b F2 − a F1)/(4μ(λ+2μ)), U_N = ℓ(b F1 − a F2)/(4μ(λ+2μ));
    - stick: U_T = U_N = 0, Λ = −F2;
    - right slip: U_N = 0, U_T = −ℓ(F F2 + F1)/(a + F b), Λ = (b F1 − a F2)/(a + F b);
    - left slip: U_N = 0, U_T = ℓ(F F2 − F1)/(a − F b), Λ = (b F1 − a F2)/(a − F b);

    each kept when its signs hold (U_N ≤ 0; Λ ≥ 0 and |F1| ≤ FΛ; U_T < 0 and Λ ≥ 0;
    U_T > 0 and Λ ≥ 0). A solution on the border of two regimes (e.g. Λ = 0 and
    U_N = 0) is listed once, under the first of stick, right slip, left slip,
    separation. At F = F_c on the half-line F1 = F F2 < 0 the solutions form the
    segment Λ ∈ [0, −F2], U_T = −ℓ(F2 + Λ)/b, U_N = 0: its two endpoints are
    returned (stick and left slip with Λ = 0), both with ``continuum`` True.

    Returns
    -------
    list of dict
        Keys ``regime``, ``U_T``, ``U_N``, ``lambda_N``, ``lambda_T``, ``Lambda``,
        ``displacement`` (u_x, u_y), ``contact_force`` (r_x, r_y), ``continuum``.
    """
    lam, mu = lame_plane_strain(E, nu)
    a, b = lam + 3 * mu, lam + mu
    scale = max(abs(F1), abs(F2))
    if scale == 0:
        return [_hild_solution("stick", 0.0, 0.0, 0.0, a, b, F1, length)]
    force_tol, disp_tol = 1e-10 * scale, 1e-10 * scale * length / mu
    critical = abs(a - friction * b) <= 1e-12 * a

    candidates = []
    if -F2 >= -force_tol and abs(F1) <= -friction * F2 + force_tol:
        candidates.append(("stick", 0.0, 0.0, -F2))
    U_T = -length * (friction * F2 + F1) / (a + friction * b)
    Lambda = (b * F1 - a * F2) / (a + friction * b)
    if U_T <= disp_tol and Lambda >= -force_tol:
        candidates.append(("right slip", U_T, 0.0, Lambda))
    continuum = critical and abs(F1 - friction * F2) <= force_tol and F2 < -force_tol
    if continuum:
        candidates.append(("left slip", -length * F2 / b, 0.0, 0.0))
    elif not critical:
        U_T = length * (friction * F2 - F1) / (a - friction * b)
        Lambda = (b * F1 - a * F2) / (a - friction * b)
        if U_T >= -disp_tol and Lambda >= -force_tol:
            candidates.append(("left slip", U_T, 0.0, Lambda))
    U_N = length * (b * F1 - a * F2) / (4 * mu * (lam + 2 * mu))
    if U_N <= disp_tol:
        candidates.append(("separation", length * (b * F2 - a * F1) / (4 * mu * (lam + 2 * mu)), U_N, 0.0))

    distinct = []
    for candidate in candidates:
        if not any(_same(candidate, kept, disp_tol, force_tol) for kept in distinct):
            distinct.append(candidate)
    return [_hild_solution(*c, a, b, F1, length, continuum) for c in distinct]


def _same(first: tuple, second: tuple, disp_tol: float, force_tol: float) -> bool:
    """Whether two (regime, U_T, U_N, Λ) candidates are the same solution."""
    return (
        abs(first[1] - second[1]) <= 10 * disp_tol
        and abs(first[2] - second[2]) <= 10 * disp_tol
        and abs(first[3] - second[3]) <= 10 * force_tol
    )


def _hild_solution(
    regime: str,
    U_T: float,
    U_N: float,
    Lambda: float,
    a: float,
    b: float,
    F1: float,
    length: float,
    continuum: bool = False,
) -> dict:
    """One solution as a dict; the friction force comes from the tangential equilibrium of A."""
    lambda_N = Lambda * length / 2
    lambda_T = (a * U_T + b * U_N + length * F1) / 2
    return {
        "regime": regime,
        "U_T": U_T,
        "U_N": U_N,
        "lambda_N": lambda_N,
        "lambda_T": lambda_T,
        "Lambda": Lambda,
        "displacement": (-U_T, -U_N),
        "contact_force": (-lambda_T, lambda_N),
        "continuum": continuum,
    }
