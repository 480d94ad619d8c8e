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
The steps stop once one lowers J by under :data:`TOLERANCE` of J (one more step then, the last), at most
:data:`ITERATIONS`; the last step needs only the curvature along its direction, not the product.
For the same reason the steps run in single precision (:data:`WORKING`): τ and η are evaluated in float64 from the
coefficients they produce.

At the midpoint of the facet opposite vertex k of a cell, the bubbles of its three facets with coefficients c_e give
2 (Σ_e c_e − 2 c_k) curl λ_k, the hats Σ_a c_a curl λ_a (constant): the operator is a few products per cell, written
by hand and applied matrix-free (assembling the P2 matrix, with scikit-fem or by hand, costs more than the steps).
"""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

ITERATIONS = 5
"""Conjugate-gradient steps at most: on the uniform punch at 4,160 and 65,792 DOFs they reach η within 11–12 % of the
exact minimizer's (10 steps: 3–4 %, 3 steps: 21–22 %; RT0 alone: 2.1×) (docs/estimate.md, "Cost of the bound")."""

TOLERANCE = 0.045
"""After a step that lowers J by under this fraction of J, one more step and no other: the strip 100 : 1, the pair, the
Hertz block and the two cylinders at 10⁴–10⁵ DOFs then take 4 steps, η within 0.2–1.3 % of 5 steps' (within 1 % at
10⁵), the punches, whose steps lower J more slowly, all 5 (docs/estimate.md, "Fewer correction steps"). 0: always
:data:`ITERATIONS` steps."""

WORKING = np.float32
"""The floating type of the conjugate-gradient steps: they only choose φ's coefficients, and any coefficients keep
the bound (τ and η are evaluated in float64 from them); single precision halves the memory traffic of the products
(a product at 10⁵ cells: 23 ms against 40 ms in float64, both under load) and moves η by under 10⁻⁶ relative (2·10⁻⁸
measured; tests/test_flux_correction.py)."""

BLOCK = 8192
"""Cells per block of the products' cell-wise arithmetic: its temporaries then stay in the processor's caches (a
product at 10⁵ cells: 10.8 ms of CPU, against 11.6 with 4,096, 12.6 with 16,384 and 17.1 with 2,048)."""


THREADS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
"""Threads of the cell-wise arithmetic (the cores this process may run on): numpy releases the interpreter's lock in
its kernels (ufuncs, take, bincount, cumsum), so blocks of cells, and the two rows of the stress, run side by side.
The work is split the same way whatever the count (each block, each row, computed alone): η does not depend on it."""

SERIAL_BELOW = 16_384
"""Cells below which :func:`parallel` stays on the calling thread: on small meshes the hand-off to a thread costs
more than the work it shares (hertz_punch(nx=40), 3,200 cells, under load: 14 ms serial, 28 ms on two threads)."""

_worker = threading.local()


@functools.cache
def executor(workers: int) -> ThreadPoolExecutor:
    """The pool of ``workers`` threads that :func:`parallel` shares out to (made once per count)."""
    return ThreadPoolExecutor(workers, thread_name_prefix="convexcontact-cells",
                              initializer=lambda: setattr(_worker, "inside", True))


def parallel(work, items, cells: int) -> list:
    """[work(item) for item in items], the items in :data:`THREADS` contiguous runs, the first run on the calling
    thread, the others on :func:`executor`'s; serially with one thread, on meshes of fewer than
    :data:`SERIAL_BELOW` ``cells``, or when called from a worker (no nested waits on the pool)."""
    items = list(items)
    threads = min(THREADS, len(items))
    if threads <= 1 or cells < SERIAL_BELOW or getattr(_worker, "inside", False):
        return [work(item) for item in items]
    runs = np.array_split(np.arange(len(items)), threads)
    pool = executor(threads - 1)
    futures = [pool.submit(lambda run=run: [work(items[j]) for j in run]) for run in runs[1:]]
    out = [work(items[j]) for j in runs[0]]
    for future in futures:
        out.extend(future.result())
    return out


def blocks(count: int, size: int | None = None):
    """Slices of ``size`` cells (None: :data:`BLOCK`) covering ``count`` cells."""
    size = BLOCK if size is None else size
    for start in range(0, count, size):
        yield slice(start, start + size)


def for_blocks(count: int, work, size: int | None = None) -> None:
    """work(cells) for each slice of :func:`blocks` (``size`` None: :data:`BLOCK`), shared out by :func:`parallel`;
    each block writes its own cells of the outputs."""
    parallel(work, blocks(count, size), count)


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


def midpoint_values(bubbles: np.ndarray, hats: np.ndarray, curls: np.ndarray) -> np.ndarray:
    """τ = curl φ (rows, x, 3 midpoints, cells) of the coefficients of each cell's bubbles (rows, facet opposite k,
    cells) and hats (rows, vertex k, cells): at the midpoint opposite vertex k the bubbles give
    2 (Σ_e c_e − 2 c_k) curl λ_k, the hats Σ_a c_a curl λ_a (constant). ``curls`` curl λ_k (x, k, cells)."""
    scale = 2.0 * bubbles.sum(axis=1, keepdims=True) - 4.0 * bubbles  # (rows, k, cells)
    out = scale[:, None] * curls
    out += (hats[:, None] * curls).sum(axis=2, keepdims=True)
    return out


class StreamOperator:
    """J's Hessian (half of it) for the coefficients x (rows, facets + vertices) of φ, matrix-free, in the floating
    type ``dtype``.

    The gathers of the cells' coefficients and the cell-wise arithmetic run in blocks of :data:`BLOCK` cells (shared
    out between :data:`THREADS` threads), the sums back onto the facets and vertices over whole arrays, one per row
    and kind. Arrays are laid out (…, 3, cells): the small axes first, every operation over long contiguous rows.
    ``gradients`` ∇λ_k (x, 3, cells); ``weight`` |T| / 3 (the midpoint rule); ``lame`` (λ, μ) per cell."""

    def __init__(self, mesh, opposite, gradients, weight, lame, korn, dtype):
        self.nfacets, self.nvertices = mesh.nfacets, mesh.nvertices
        # (3, cells) in the platform's index type: bincount and take would convert int32 on every call
        self.facets = np.ascontiguousarray(opposite.T, dtype=np.intp)
        self.vertices = np.ascontiguousarray(mesh.t, dtype=np.intp)
        self.curls = curls(gradients, slice(None), dtype)
        lam, mu = lame
        kappa, w, gamma = lam / (2 * mu + 2 * lam), weight / (2 * mu), korn**2 - 1  # w = |T|/3 · 1/2μ
        # |T|/3 · Q per cell: diagonal (1 − κ), trace coupling −κ, shear (1 + γ)/2, skew coupling (1 − γ)/2
        normal, trace, shear, skew = w * (1 - kappa), -w * kappa, 0.5 * w * (1 + gamma), 0.5 * w * (1 - gamma)
        # (rows, x, 1, cells): the weight of X_ij itself and of X_ji' in (Q X)_ij
        self.own, self.cross = np.empty((2, 2, 2, 1, w.size), dtype)
        for (i, j), own, cross in (((0, 0), normal, trace), ((0, 1), shear, skew), ((1, 0), shear, skew),
                                   ((1, 1), normal, trace)):
            self.own[i, j, 0], self.cross[i, j, 0] = own, cross
        # the cells' loads, allocated once (a fresh array of this size costs its page faults again on every
        # product) in float64, which bincount sums without a converted copy
        self.loads = np.empty((2, 2, *gradients.shape[1:]))  # (bubbles or hats, rows, k, cells)

    def weighted_form(self, X: np.ndarray, cells) -> np.ndarray:
        """|T|/3 · Q X for the ``cells`` of a block X (rows, x, 3, block), X : Q X = C⁻¹ sym X : sym X + (C_K² − 1)/2μ
        |skew X|² pointwise (2-D: C⁻¹ τ : τ = (|τ|² − λ/(2μ + 2λ) (tr τ)²) / 2μ): Q X_ij = own_ij X_ij + cross_ij
        X_ji' with X_ji' the entry of the other row and column (X_00 with X_11, X_01 with X_10)."""
        out = X * self.own[..., cells]
        out += X[::-1, ::-1] * self.cross[..., cells]
        return out

    def adjoint(self, W: np.ndarray, cells) -> None:
        """The transpose of :func:`midpoint_values` on a block: W (rows, x, 3, block) → the loads of each cell's
        bubbles and hats (rows, k, block), into ``loads``."""
        curls = self.curls[..., cells]
        along = (W * curls).sum(axis=1)  # curl λ_k · W_k (rows, k, block)
        self.loads[0][..., cells] = 2.0 * along.sum(axis=1, keepdims=True) - 4.0 * along
        self.loads[1][..., cells] = (W.sum(axis=2, keepdims=True) * curls).sum(axis=1)

    def gather(self, x: np.ndarray, cells) -> tuple[np.ndarray, np.ndarray]:
        """The coefficients of x of the ``cells``' bubbles and hats (rows, k, block), in x's floating type."""
        facets, vertices = self.facets[:, cells], self.vertices[:, cells]
        bubbles, hats = np.empty((2, *facets.shape), x.dtype), np.empty((2, *facets.shape), x.dtype)
        for i in range(2):  # mode "clip": numpy buffers a take into ``out=`` that checks its indices (6× slower)
            on_facets, on_vertices = x[i, :self.nfacets], x[i, self.nfacets:]
            for k in range(3):
                np.take(on_facets, facets[k], out=bubbles[i, k], mode="clip")
                np.take(on_vertices, vertices[k], out=hats[i, k], mode="clip")
        return bubbles, hats

    def scatter(self, dtype, out=None) -> np.ndarray:
        """The cells' ``loads`` summed onto the facets and vertices (rows, facets + vertices; into ``out`` if given)."""
        out = np.empty((2, self.nfacets + self.nvertices), dtype) if out is None else out
        kinds = ((self.facets, slice(None, self.nfacets)), (self.vertices, slice(self.nfacets, None)))

        def add(kind_row):
            kind, i = kind_row
            at, part = kinds[kind]
            out[i, part] = np.bincount(at.ravel(), self.loads[kind, i].ravel(), out[i, part].size)

        parallel(add, [(0, 0), (0, 1), (1, 0), (1, 1)], self.loads.shape[-1])
        return out

    def gradient(self, misfit) -> tuple[np.ndarray, float]:
        """J's gradient at τ = 0 (half of it) and J at τ = 0, ``misfit(cells)`` σ̂ − σ_h at the midpoints of a block of
        cells."""
        def block(cells):
            X = misfit(cells)
            W = self.weighted_form(X, cells)
            self.adjoint(W, cells)
            return np.einsum("ijkc,ijkc", X, W, dtype=float)

        energy = self.summed(block)  # the loads first, then their sums
        return self.scatter(self.curls.dtype), energy

    def summed(self, work) -> float:
        """Σ work(cells) over the blocks, in block order whatever the threads (the same sum with 1, 2 or 3)."""
        return float(sum(parallel(work, blocks(self.loads.shape[-1]), self.loads.shape[-1])))

    def curvature(self, x: np.ndarray) -> float:
        """x · (operator x), by the cells' τ = curl φ and Q, without summing loads back onto facets and vertices."""
        def block(cells):
            tau = midpoint_values(*self.gather(x, cells), self.curls[..., cells])
            return np.einsum("ijkc,ijkc", tau, self.weighted_form(tau, cells), dtype=float)

        return self.summed(block)

    def __call__(self, x: np.ndarray, out=None) -> np.ndarray:
        def block(cells):
            tau = midpoint_values(*self.gather(x, cells), self.curls[..., cells])
            self.adjoint(self.weighted_form(tau, cells), cells)

        for_blocks(self.loads.shape[-1], block)
        return self.scatter(x.dtype, out)

    def diagonal(self) -> np.ndarray:
        """The operator's diagonal (float64): a bubble's τ is ±2 curl λ_k at the three midpoints of each of its
        cells, a hat's curl λ_a."""
        def block(cells):
            hats = self.loads[1][..., cells]
            np.multiply(3.0, (self.own[..., cells] * self.curls[..., cells] ** 2).sum(axis=1), out=hats)  # Q_ii, thrice
            self.loads[0][..., cells] = (4.0 / 3.0) * hats.sum(axis=1, keepdims=True)  # Q_ii (curl λ_k), three k

        for_blocks(self.loads.shape[-1], block)
        return self.scatter(float)


def conjugate_gradients(operator, load, diagonal, admissible, iterations: int, energy: float = 0.0,
                        tolerance: float = 0.0) -> np.ndarray:
    """At most ``iterations`` Jacobi-preconditioned CG steps on operator x = −load over the admissible coefficients
    (rows, facets + vertices), from x = 0, in the floating type of ``load`` (overwritten); J(0) = ``energy``. A step lowers J by α r·z;
    once that is under ``tolerance`` × J, the next step is the last. The last step needs only the curvature along its
    direction (:meth:`StreamOperator.curvature`: no residual follows it), not the product.

    Written out rather than scipy's ``cg``: its vectors are float64 and its dot products BLAS calls, which OpenBLAS
    spreads over threads that contend with a busy machine (a 4 ms dot product of 4·10⁵ entries, against 0.1 ms).
    The preconditioner is 0 off the admissible coefficients, so every search direction, and x, stays admissible
    without masking the products. Stops early where the preconditioned residual or the curvature along the direction
    is zero (J already minimal there: zero data, or no admissible coefficient)."""
    # six vectors, each written in place by every step: fresh ones cost their page faults on every call
    inverse = np.zeros_like(load)
    np.divide(1.0, diagonal, out=inverse, where=admissible)
    residual = np.negative(load, out=load)
    z = inverse * residual
    direction, x, product = z.copy(), np.zeros_like(load), np.empty_like(load)
    rz = np.einsum("ij,ij", residual, z)
    last = False
    for step in range(iterations):
        last = last or step + 1 == iterations
        if last:
            curvature = operator.curvature(direction)
        else:
            operator(direction, out=product)
            curvature = np.einsum("ij,ij", direction, product)
        if not (rz > 0 and curvature > 0):
            break
        alpha = rz / curvature
        x += np.multiply(alpha, direction, out=z)  # z is free until the residual's next preconditioning
        if last:
            break
        energy -= alpha * rz
        last = alpha * rz < tolerance * energy
        residual -= np.multiply(alpha, product, out=product)
        np.multiply(inverse, residual, out=z)
        rz, previous = np.einsum("ij,ij", residual, z), rz
        direction *= rz / previous
        direction += z
    return x


def corrected(vertex_stress, sigma_h, gradients, area, lame, mesh, opposite, held, korn,
              iterations: int | None = None) -> np.ndarray:
    """σ̂ + curl φ at the vertices of each cell, written over ``vertex_stress`` (as in
    :class:`convexcontact.fem.flux.Equilibrated`: (rows, x, cells, 3), a view of a (rows, x, 3, cells) array), φ from
    at most ``iterations`` CG steps on J (None: :data:`ITERATIONS`; :data:`TOLERANCE` may stop them earlier) in
    :data:`WORKING` precision, τ = curl φ then evaluated in float64. ``held`` the (rows, facets) mask of held components, ``korn`` C_K, ``gradients`` ∇λ_k (x, k, cells);
    the other arguments are ``equilibrate``'s per-cell data."""
    iterations = ITERATIONS if iterations is None else iterations
    if iterations == 0:
        return vertex_stress
    at = vertex_stress.transpose(0, 1, 3, 2)  # (rows, x, m, cells)
    operator = StreamOperator(mesh, opposite, gradients, area / 3.0, lame, korn, WORKING)
    stress = sigma_h.transpose(1, 2, 0)[:, :, None]  # (rows, x, 1, cells)

    def misfit(cells):  # σ̂ − σ_h at the midpoint opposite vertex k: (V_{k+1} + V_{k+2}) / 2 = (Σ V − V_k) / 2
        corners = at[..., cells]
        return (0.5 * (corners.sum(axis=2, keepdims=True) - corners) - stress[..., cells]).astype(WORKING)

    gradient, energy = operator.gradient(misfit)
    x = conjugate_gradients(operator, gradient, operator.diagonal(), admissible_stream_functions(mesh, held),
                            iterations, energy, TOLERANCE)
    return with_curl(vertex_stress, x.astype(float), gradients, operator, out=at)


def curls(gradients: np.ndarray, cells, dtype=float) -> np.ndarray:
    """curl λ_k = (∂_y λ_k, −∂_x λ_k) (x, k, cells) of the ``cells`` of ``gradients`` ∇λ_k (x, k, cells)."""
    out = np.empty((2, 3, *gradients[0, 0, cells].shape), dtype)
    out[0] = gradients[1][..., cells]
    np.negative(gradients[0][..., cells], out=out[1])
    return out


def with_curl(vertex_stress, x, gradients, operator: StreamOperator, out=None) -> np.ndarray:
    """σ̂ + curl φ at the vertices of each cell (rows, x, cells, 3; a view of ``out`` (rows, x, 3, cells), None: a new
    array, or ``vertex_stress``'s own to overwrite it) for the float64 coefficients x (rows, facets + vertices) of φ;
    ``gradients`` ∇λ_k (x, k, cells), ``operator`` gives the cells' facets and vertices."""
    at = vertex_stress.transpose(0, 1, 3, 2)  # (rows, x, m, cells)
    out = np.empty_like(at) if out is None else out

    def block(cells):
        tau = midpoint_values(*operator.gather(x, cells), curls(gradients, cells))
        tau *= -2.0  # a linear field's vertex values from its midpoints: V_k = Σ M − 2 M_k
        tau -= 0.5 * tau.sum(axis=2, keepdims=True)
        np.add(at[..., cells], tau, out=out[..., cells])

    for_blocks(out.shape[-1], block)
    return out.transpose(0, 1, 3, 2)
