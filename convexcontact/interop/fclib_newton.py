"""A semismooth Newton method on Alart–Curnier's equation of an FClib local problem, W as given.

Coulomb's law at contact k, with u = W r + V λ + q and ρ > 0, is F_k(r, u) = 0 (Alart–Curnier 1991,
Siconos' ``computeAlartCurnierSTD``, radius μ max(0, r_N − ρ u_N)):

    F_N = r_N − max(0, r_N − ρ u_N),      F_T = r_T − Π_B(μ max(0, r_N − ρ u_N)) (r_T − ρ u_T),

with Π_B(R) the projection on the disc (2-D: interval) of radius R; F = 0 exactly where fclib's merit
is 0. The equation needs no symmetry of W: it is the file's problem, whatever W is (a convex program
needs W's symmetric part and loses the rest). F is piecewise smooth; a generalized Jacobian is
J = D_r + D_u W (per-contact blocks), and the step J δ = −F (with the equalities Vᵀ r + R λ + s = 0
appended) is damped by Armijo's rule on ½‖F‖². Near a solution it converges quadratically; from
far away it may stall, which the caller sees (``outcome``) and answers with another start.

Written here, not taken from a library: no Python package we found solves Coulomb's law on a given
W (Siconos is a C/C++ build with its own Python bindings, not on PyPI).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

TINY = 1e-300
ARMIJO = 1e-4
SHORTEST = 2.0**-30
"""Steps shorter than this are no progress: the method has stalled (a kink of F, or a singular J)."""
NEWTON_SHORTEST = 2.0**-4
"""A Newton step cut back further than this is not trusted: Levenberg–Marquardt's step is taken instead (on
fclib's Boxes Stack, W of rank 72/144, the LU of a nearly singular J gave steps cut to 1e-6 for 200 iterations)."""
SLOW = 6
"""Newton steps over which the measure must at least halve, else the attempt stops (a start too far)."""
DENSE = (0.5, 500)
"""W with more than this fraction of nonzeros and more unknowns is factorized dense (LAPACK), else sparse (SuperLU,
one thread). On our loaded 2 cores LAPACK's threaded LU took 0.18 s for a dense 150² matrix against SuperLU's
0.02 s (858²: 0.33 s against 0.62 s; 3204²: 3.5 s against 12.7 s), and 0.19 s a step on the LMGC PerioBox
file (W 180², 30 % nonzeros)."""


@dataclass
class Equation:
    """Alart–Curnier's equation of FC(W, q, μ) [with Vᵀ r + R λ + s = 0], every array in the same units."""

    W: sp.csr_matrix | np.ndarray
    q: np.ndarray
    mu: np.ndarray
    spacedim: int
    rho: np.ndarray  # one per contact
    V: sp.csr_matrix | None = None
    R: sp.csr_matrix | None = None
    s: np.ndarray | None = None

    @property
    def equalities(self) -> int:
        return 0 if self.V is None else self.V.shape[1]

    def velocity(self, r: np.ndarray, l: np.ndarray) -> np.ndarray:
        u = self.W @ r + self.q
        return u if self.V is None else u + self.V @ l

    def residual(self, r: np.ndarray, l: np.ndarray) -> np.ndarray:
        """F(r, λ), and the equalities' residual after it."""
        F, _, _ = self.pieces(r, self.velocity(r, l), jacobian=False)
        if self.V is None:
            return F
        rest = self.V.T @ r + self.s + (0.0 if self.R is None else self.R @ l)
        return np.concatenate([F, rest])

    def pieces(self, r: np.ndarray, u: np.ndarray, jacobian: bool = True):
        """F at (r, u) and, with ``jacobian``, the per-contact blocks ∂F/∂r and ∂F/∂u (m, d, d)."""
        d, mu = self.spacedim, self.mu
        z, v = r.reshape(-1, d), u.reshape(-1, d)
        rho = self.rho
        normal = z[:, 0] - rho * v[:, 0]
        pressed = normal > 0
        radius = mu * np.maximum(normal, 0.0)
        trial = z[:, 1:] - rho[:, None] * v[:, 1:]
        size = np.linalg.norm(trial, axis=1)
        sliding = size > radius
        ratio = np.where(sliding, radius / np.maximum(size, TINY), 1.0)
        F = np.empty_like(z)
        F[:, 0] = z[:, 0] - np.maximum(normal, 0.0)
        F[:, 1:] = z[:, 1:] - ratio[:, None] * trial
        if not jacobian:
            return F.ravel(), None, None
        m, t = z.shape[0], d - 1
        Dr, Du = np.zeros((m, d, d)), np.zeros((m, d, d))
        Dr[:, 0, 0] = np.where(pressed, 0.0, 1.0)
        Du[:, 0, 0] = np.where(pressed, rho, 0.0)
        direction = trial / np.maximum(size, TINY)[:, None]
        # outside the disc: dΠ = (R/‖t‖)(I − n nᵀ) dt + n dR, dt = dr_T − ρ du_T, dR = μ (dr_N − ρ du_N) if pressed
        Q = ratio[:, None, None] * (np.eye(t) - direction[:, :, None] * direction[:, None, :])
        Q[~sliding] = np.eye(t)
        Dr[:, 1:, 1:] = np.eye(t) - Q
        Du[:, 1:, 1:] = rho[:, None, None] * Q
        lean = np.where(sliding & pressed, mu, 0.0)[:, None] * direction
        Dr[:, 1:, 0] = -lean
        Du[:, 1:, 0] = rho[:, None] * lean
        return F.ravel(), Dr, Du

    def jacobian(self, r: np.ndarray, l: np.ndarray):
        """F and a generalized Jacobian [[D_r + D_u W, D_u V], [Vᵀ, R]] (sparse or dense like W)."""
        F, Dr, Du = self.pieces(r, self.velocity(r, l))
        Br, Bu = block_diagonal(Dr), block_diagonal(Du)
        if isinstance(self.W, np.ndarray):
            J = Br.toarray() + Bu @ self.W
            if self.V is not None:
                R = np.zeros((self.equalities,) * 2) if self.R is None else self.R.toarray()
                J = np.block([[J, (Bu @ self.V).toarray()], [self.V.T.toarray(), R]])
        else:
            J = Br + Bu @ self.W
            if self.V is not None:
                J = sp.bmat([[J, Bu @ self.V], [self.V.T, self.R]])
        if self.V is not None:
            F = np.concatenate([F, self.V.T @ r + self.s + (0.0 if self.R is None else self.R @ l)])
        return F, J


def block_diagonal(blocks: np.ndarray) -> sp.csr_matrix:
    """The block-diagonal matrix of ``blocks`` (m, d, d)."""
    count = blocks.shape[0]
    return sp.bsr_matrix((blocks, np.arange(count), np.arange(count + 1))).tocsr()


def linear_solve(A, b: np.ndarray) -> np.ndarray | None:
    """A⁻¹ b by LU (LAPACK for a dense A, SuperLU for a sparse one), or None when A is singular."""
    try:
        if isinstance(A, np.ndarray):
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", la.LinAlgWarning)  # a singular A is answered by None, not warned of
                x = la.lu_solve(la.lu_factor(A, check_finite=False), b, check_finite=False)
        else:
            x = spla.splu(sp.csc_matrix(A)).solve(b)
    except (RuntimeError, la.LinAlgError, ValueError):  # SuperLU: "Factor is exactly singular"
        return None
    return x if np.all(np.isfinite(x)) else None


def newton_step(J, F: np.ndarray) -> np.ndarray | None:
    """δ with J δ = −F, or None when J is singular."""
    return linear_solve(J, -F)


def least_squares_step(J, F: np.ndarray) -> np.ndarray | None:
    """δ minimizing ‖J δ + F‖² + ν‖δ‖² (Levenberg–Marquardt, ν tiny): a step where J is singular (W singular:
    rigid bodies; the forces are then not unique and the step picks the least change). LU, not Cholesky:
    OpenBLAS' threaded Cholesky took 1.1 s on an 858² matrix on our loaded 2 cores, its LU 0.1 s."""
    normal = J.T @ J
    damping = 1e-12 * max(normal.diagonal().sum(), TINY)
    identity = np.eye(normal.shape[0]) if isinstance(J, np.ndarray) else sp.identity(normal.shape[0])
    return linear_solve(normal + damping * identity, -J.T @ F)


def line_search(equation: Equation, x: np.ndarray, step: np.ndarray, F: np.ndarray, J, shortest: float):
    """Armijo's rule on ½‖F‖² along ``step``: (the new point, F there), or None if no step down to ``shortest``
    decreases it enough (or ``step`` is no descent direction)."""
    n, size, slope = equation.W.shape[0], 0.5 * (F @ F), F @ (J @ step)
    alpha = 1.0
    while slope < 0 and alpha >= shortest:
        trial = x + alpha * step
        G = equation.residual(trial[:n], trial[n:])
        if 0.5 * (G @ G) <= size + ARMIJO * alpha * slope:
            return trial, G, alpha
        alpha *= 0.5
    return None


def solve(equation: Equation, r: np.ndarray, l: np.ndarray, done, max_iterations: int = 100):
    """Newton's method from (r, λ) until ``done(r, λ)`` (returns (stop, measure)), it stalls or slows down.

    Each step is Newton's, cut back at most to NEWTON_SHORTEST; failing that (J singular or nearly: W of rigid
    bodies), Levenberg–Marquardt's, always a descent direction. Returns the iterate of least measure, its
    measure, the history and the outcome ("converged", "stalled", "slow" or "not converged")."""
    n = r.size
    x = np.concatenate([r, l])
    stop, value = done(r, l)
    best, history, values = (value, r, l), [], [value]
    if stop:
        return best, history, "converged"
    for k in range(1, max_iterations + 1):
        F, J = equation.jacobian(x[:n], x[n:])
        step = newton_step(J, F)
        found = None if step is None else line_search(equation, x, step, F, J, NEWTON_SHORTEST)
        if found is None:
            step = least_squares_step(J, F)
            found = None if step is None else line_search(equation, x, step, F, J, SHORTEST)
        if found is None:
            return best, history, "stalled"
        x, G, alpha = found
        stop, value = done(x[:n], x[n:])
        history.append({"newton": k, "step": alpha, "residual": float(np.linalg.norm(G)), "measure": value})
        values.append(value)
        if value < best[0]:
            best = (value, x[:n].copy(), x[n:].copy())
        if stop:
            return best, history, "converged"
        if k >= SLOW and not values[-1] < 0.5 * values[-1 - SLOW]:
            return best, history, "slow"
    return best, history, "not converged"
