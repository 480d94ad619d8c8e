"""Divergence-free corrections of the row-wise equilibrated stress: the asymmetry of σ̂ driven down, the bound kept
(docs/estimate.md, "The divergence-free correction").

Row by row, σ̂ of :func:`convexcontact.fem.flux.equilibrate` is in RT0 and not symmetric; the bound pays its skew part
with Korn's constant. Any τ with div τ = 0 in the body and τ n = 0 on the facets whose flux is prescribed keeps every
constraint σ̂ satisfies (cell divergences, Neumann and contact data), so σ̂ + τ gives a guaranteed bound as well. In
2-D, row i: τ_i = curl φ_i = (∂_y φ_i, −∂_x φ_i), and curl φ · n = ∂_t φ on a facet, so φ_i continuous and zero along
the boundary facets where row i's flux is prescribed, free on the facets where component i is held (Dirichlet) and
inside. With φ_i piecewise P2 (hierarchical: hats ψ_a, edge bubbles b_E = 4 λ_p λ_q), σ̂ + τ stays linear per cell and
the quadrature of ``cell_norms`` stays exact. The skew part of τ is −div φ / 2 (φ = (φ_1, φ_2)): linear per
cell, so the asymmetry can be driven near zero (the weak symmetry of Arnold–Falk–Winther, Bertrand–Moldenhauer–Starke,
here a post-processing). The coefficients minimize the convex quadratic

    J = ‖C^{-½}(sym(σ̂ + τ) − σ_h)‖² + (C_K² − 1) ‖(2μ)^{-½} skew(σ̂ + τ)‖²

by a few conjugate-gradient steps from τ = 0, matrix-free with a diagonal preconditioner: each step lowers J, and
every iterate keeps the bound valid (any coefficients do), so an inexact minimizer costs sharpness, never the guarantee.

At the midpoint of the facet opposite vertex k of a cell, the bubbles of its three facets with coefficients c_e give
2 (Σ_e c_e − 2 c_k) curl λ_k, the hats Σ_a c_a curl λ_a (constant): the operator is a few products per cell, written
by hand and applied matrix-free (assembling the P2 matrix, with scikit-fem or by hand, costs more than the steps).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

ITERATIONS = 5
"""Conjugate-gradient steps: on the uniform punch at 4,160 and 65,792 DOFs they reach η within 11–12 % of the exact
minimizer's (10 steps: 3–4 %, 3 steps: 21–22 %; RT0 alone: 2.1×), each step costing ≈ 10 % of the rest of the
estimator (docs/estimate.md, "Cost of the bound")."""


def admissible_stream_functions(mesh, held: np.ndarray) -> np.ndarray:
    """(rows, facets + vertices) mask of the stream functions φ_i may use: the bubbles of the interior facets and of
    the boundary facets where component i is held, the hats of the vertices on no facet where row i's flux is
    prescribed."""
    boundary = mesh.f2t[1] == -1
    bubbles = ~boundary[None] | held
    hats = np.ones((2, mesh.nvertices), dtype=bool)
    for i in range(2):
        hats[i, mesh.facets[:, boundary & ~held[i]].ravel()] = False
    return np.concatenate([bubbles, hats], axis=1)


class StreamOperator:
    """J's Hessian (half of it) and τ at the facet midpoints for the coefficients x (rows, facets + vertices) of φ.

    Arrays are laid out (…, 3, cells): the small axes first, every operation over long contiguous rows (numpy's
    reductions over a trailing axis of length 3 cost 10× more), into work arrays allocated once (a fresh array of
    this size costs its page faults again on every product: half the time). ``curls`` curl λ_k (x, 3, cells);
    ``weight`` |T| / 3 (the midpoint rule); ``lame`` (λ, μ) per cell."""

    def __init__(self, mesh, opposite, curls, weight, lame, korn):
        self.nfacets, self.nvertices = mesh.nfacets, mesh.nvertices
        # (3, cells) in the platform's index type: bincount and take would convert int32 on every call
        self.facets, self.vertices = opposite.T.astype(np.intp), mesh.t.astype(np.intp)
        self.curls = curls
        lam, mu = lame
        kappa, w, gamma = lam / (2 * mu + 2 * lam), weight / (2 * mu), korn**2 - 1  # w = |T|/3 · 1/2μ
        # |T|/3 · Q per cell: diagonal (1 − κ), trace coupling −κ, shear (1 + γ)/2, skew coupling (1 − γ)/2
        self.normal, self.trace, self.shear, self.skew = w * (1 - kappa), -w * kappa, 0.5 * w * (1 + gamma), \
            0.5 * w * (1 - gamma)
        self.field, self.weighted = np.empty((2, *curls.shape)), np.empty((2, *curls.shape))
        self.corner = tuple(np.empty((2, *curls.shape[1:])) for _ in range(3))  # (rows, k, cells)
        self.cell = tuple(np.empty((2, curls.shape[2])) for _ in range(2))  # (rows, cells)

    def midpoints(self, x: np.ndarray) -> np.ndarray:
        """τ (rows, x, 3 midpoints, cells) of the coefficients x: at the midpoint opposite vertex k the bubbles give
        2 (Σ_e c_e − 2 c_k) curl λ_k, the hats Σ_a c_a curl λ_a. Returns a work array (valid until the next call)."""
        out, (scale, hat, _), (total, term) = self.field, self.corner, self.cell
        for i in range(2):  # mode "clip": numpy buffers a take into ``out=`` that checks its indices (6× slower)
            np.take(x[i, :self.nfacets], self.facets, out=scale[i], mode="clip")
            np.take(x[i, self.nfacets:], self.vertices, out=hat[i], mode="clip")
        np.sum(scale, axis=1, out=total)
        scale *= -4.0
        total *= 2.0
        scale += total[:, None]
        for c in range(2):
            np.multiply(scale, self.curls[c], out=out[:, c])
            np.multiply(hat[:, 0], self.curls[c, 0], out=total)
            for k in (1, 2):
                np.multiply(hat[:, k], self.curls[c, k], out=term)
                total += term
            out[:, c] += total[:, None]
        return out

    def weighted_form(self, X: np.ndarray) -> np.ndarray:
        """|T|/3 · Q X, X : Q X = C⁻¹ sym X : sym X + (C_K² − 1)/2μ |skew X|² pointwise (2-D: C⁻¹ τ : τ =
        (|τ|² − λ/(2μ + 2λ) (tr τ)²) / 2μ). Returns a work array."""
        out, spare = self.weighted, self.corner[1]
        for i, j in ((0, 1), (1, 0)):
            np.multiply(X[i, i], self.normal, out=out[i, i])
            np.multiply(X[j, j], self.trace, out=spare[i])
            out[i, i] += spare[i]
            np.multiply(X[i, j], self.shear, out=out[i, j])
            np.multiply(X[j, i], self.skew, out=spare[i])
            out[i, j] += spare[i]
        return out

    def adjoint(self, Y: np.ndarray) -> np.ndarray:
        """The transpose of :meth:`midpoints`: Y (rows, x, 3, cells) → (rows, facets + vertices)."""
        (along, hat, spare), (total, term) = self.corner, self.cell
        np.multiply(Y[:, 0], self.curls[0], out=along)
        np.multiply(Y[:, 1], self.curls[1], out=hat)
        along += hat  # curl λ_k · Y_k (rows, k, cells)
        np.sum(along, axis=1, out=total)
        along *= -4.0
        total *= 2.0
        along += total[:, None]
        np.sum(Y[:, 0], axis=1, out=total)
        np.sum(Y[:, 1], axis=1, out=term)
        np.multiply(total[:, None], self.curls[0], out=hat)
        hat += np.multiply(term[:, None], self.curls[1], out=spare)
        out = np.empty((2, self.nfacets + self.nvertices))
        for i in range(2):
            out[i, :self.nfacets] = np.bincount(self.facets.ravel(), along[i].ravel(), self.nfacets)
            out[i, self.nfacets:] = np.bincount(self.vertices.ravel(), hat[i].ravel(), self.nvertices)
        return out

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.adjoint(self.weighted_form(self.midpoints(x)))

    def diagonal(self) -> np.ndarray:
        """The operator's diagonal: a bubble's τ is ±2 curl λ_k at the three midpoints of each of its cells, a hat's
        curl λ_a."""
        cx, cy = self.curls
        rows = (self.normal * cx**2 + self.shear * cy**2, self.shear * cx**2 + self.normal * cy**2)
        out = np.empty((2, self.nfacets + self.nvertices))
        for i, row in enumerate(rows):  # (3, cells): Q_ii applied to curl λ_k
            out[i, :self.nfacets] = np.bincount(self.facets.ravel(), np.tile(4.0 * row.sum(axis=0), 3),
                                                self.nfacets)
            out[i, self.nfacets:] = np.bincount(self.vertices.ravel(), 3.0 * row.ravel(), self.nvertices)
        return out


def conjugate_gradients(operator, load, diagonal, admissible, iterations: int) -> np.ndarray:
    """``iterations`` Jacobi-preconditioned CG steps (scipy's) on operator x = −load over the admissible coefficients
    (rows, facets + vertices), from x = 0; no tolerance: a fixed number of steps, each lowering J."""
    shape, keep = load.shape, admissible.ravel().astype(float)
    inverse = keep / np.where(keep > 0, diagonal.ravel(), 1.0)  # 0 off the admissible coefficients

    def masked(x):
        out = operator((x * keep).reshape(shape)).ravel()
        out *= keep
        return out

    size = load.size
    A = spla.LinearOperator((size, size), matvec=masked, dtype=float)
    M = spla.LinearOperator((size, size), matvec=lambda r: inverse * r, dtype=float)
    x, _ = spla.cg(A, -keep * load.ravel(), rtol=0.0, atol=0.0, maxiter=iterations, M=M)
    return x.reshape(shape)


def corrected(vertex_stress, sigma_h, gradients, area, lame, mesh, opposite, held, korn,
              iterations: int | None = None) -> np.ndarray:
    """σ̂ + curl φ at the vertices of each cell (rows, x, cells, 3), φ from ``iterations`` CG steps on J
    (None: :data:`ITERATIONS`). ``vertex_stress`` as in :class:`convexcontact.fem.flux.Equilibrated`, ``held`` its
    (rows, facets) mask of held components, ``korn`` C_K, ``gradients`` ∇λ_k (x, k, cells); the other arguments are
    ``equilibrate``'s per-cell data."""
    iterations = ITERATIONS if iterations is None else iterations
    curls = np.stack([gradients[1], -gradients[0]])  # curl λ_k = (∂_y λ_k, −∂_x λ_k): (x, 3, cells)
    operator = StreamOperator(mesh, opposite, curls, area / 3.0, lame, korn)
    # σ̂ − σ_h at the midpoint opposite vertex k, (V_{k+1} + V_{k+2}) / 2 = (Σ V − V_k) / 2: (rows, x, k, cells)
    misfit = 0.5 * (vertex_stress.sum(axis=3)[..., None] - vertex_stress).transpose(0, 1, 3, 2) \
        - sigma_h.transpose(1, 2, 0)[:, :, None, :]
    load = operator.adjoint(operator.weighted_form(misfit))
    x = conjugate_gradients(operator, load, operator.diagonal(), admissible_stream_functions(mesh, held), iterations)
    tau = operator.midpoints(x)  # a linear field's vertex values from its midpoints: V_k = Σ M − 2 M_k
    tau *= -2.0
    tau -= 0.5 * tau.sum(axis=2, keepdims=True)
    return vertex_stress + tau.transpose(0, 1, 3, 2)
