"""Sparse factorizations of the stiffness K, and its condensation onto the contact DOFs.

:func:`factorize` gives K⁻¹ b and W = B K⁻¹ Bᵀ, dense or as an operator. :func:`condense` gives the dense Schur
complement S of K onto the contact DOFs C (|C| ≪ n) with the condensed load and the
lift back to all free DOFs; W = B_C S⁻¹ B_Cᵀ then costs no sparse solve at all. :func:`saddle` gives W itself from
one factorization of K with B's rows appended, where |C| is large (:data:`SADDLE_COLUMNS`).

Backends: ``"pardiso"`` (MKL PARDISO, SPD mode; symmetric indefinite for :func:`saddle`; through pypardiso's ``mkl_rt``; imported
only when used) and ``"superlu"`` (scipy). ``"auto"`` takes PARDISO when it loads.
Measurements behind the choices: docs/factorizations.md.
"""

from __future__ import annotations

import functools
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..scene.description import SceneError
from .coarse import independent

BLOCK = 64
"""Right-hand sides per SuperLU solve: one 300-column block was 5–10× slower than blocks of ≤ 64."""

RCOND = 1e-13
"""K is numerically singular when (yᵀKy)/(yᵀy) < RCOND · max Kᵢᵢ for y = K⁻¹b, b random."""


def singular_stiffness(detail: str) -> SceneError:
    """The error for a singular K (field "dirichlet"), ``detail`` saying how it showed."""
    return SceneError(
        "dirichlet",
        f"the stiffness is singular ({detail}): the body can move rigidly",
        "the dual (Delassus) formulation needs Dirichlet conditions that hold every rigid motion; "
        "use formulation='primal' or fix more components",
    )


def _pardiso():
    """The PARDISO module if MKL loads, else None (imports pypardiso and MKL on first use only)."""
    try:
        from . import pardiso

        pardiso._library()
        return pardiso
    except (ImportError, OSError):
        return None


def _backend(name: str) -> str:
    if name == "auto":
        return "pardiso" if _pardiso() is not None else "superlu"
    if name not in ("pardiso", "superlu"):
        raise ValueError(f"unknown backend {name!r}: use 'auto', 'pardiso' or 'superlu'")
    if name == "pardiso" and _pardiso() is None:
        raise ImportError("backend 'pardiso' needs pypardiso (pip install pypardiso)")
    return name


def _check_definite(K: sp.spmatrix, solve) -> None:
    """Raise if K is numerically singular.

    Pivots do not tell: an elasticity K with a free rotation gave PARDISO pivots of
    1e-10 × Kᵢᵢ, above those of nonsingular slender beams. One step of inverse iteration
    does: the Rayleigh quotient of y = K⁻¹b is ≥ λ_min, and for a singular K it is
    rounding-sized (≈ 1e-17 · max Kᵢᵢ measured, against ≥ 8e-12 for a 100:1 cantilever).
    """
    b = np.random.default_rng(0).standard_normal(K.shape[0])
    y = solve(b)
    scale = K.diagonal().max()
    if not (np.all(np.isfinite(y)) and scale > 0 and y @ (K @ y) > RCOND * scale * (y @ y)):
        raise singular_stiffness("a rigid motion costs no energy")


def _superlu(K: sp.spmatrix, dim: int):
    """SuperLU of an SPD K: symmetric mode with MMD on AᵀA in 2-D (1.6–2.8× faster), COLAMD in 3-D."""
    if dim == 2:
        options = {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}
    else:
        options = {"permc_spec": "COLAMD"}
    try:
        lu = spla.splu(sp.csc_matrix(K), **options)
    except RuntimeError as error:  # "Factor is exactly singular"
        raise singular_stiffness(str(error)) from None

    def solve(b: np.ndarray) -> np.ndarray:
        b = np.asarray(b, dtype=float)
        if b.ndim == 1 or b.shape[1] <= BLOCK:
            return lu.solve(b)
        return np.hstack([lu.solve(b[:, j:j + BLOCK]) for j in range(0, b.shape[1], BLOCK)])

    return solve


def _pardiso_factors(K: sp.spmatrix, schur: np.ndarray | None = None, mtype: int = 2, upper: bool = False):
    try:
        return _pardiso().Pardiso(K, schur, mtype, upper)
    except RuntimeError as error:
        if getattr(error, "singular", False):
            raise singular_stiffness("PARDISO found a zero pivot") from None
        raise


class Factorization(ABC):
    """K⁻¹ b and W = B K⁻¹ Bᵀ from one factorization of an SPD K (see :func:`factorize`).

    Attributes
    ----------
    backend : "pardiso" or "superlu".
    timings : seconds per stage ("factorization", ...).
    """

    backend: str
    timings: dict[str, float]
    fill: int | None = None  # nonzeros of the factors, where the backend reports them (PARDISO)
    flops: float | None = None  # of a numeric factorization, where the backend reports them (PARDISO)
    _block = BLOCK

    @abstractmethod
    def solve(self, b: np.ndarray) -> np.ndarray:
        """K⁻¹ b for b of shape (n,) or (n, k)."""

    def schur(self, B: sp.spmatrix) -> np.ndarray:
        """W = B K⁻¹ Bᵀ (dense, symmetrized), solving for a block of Bᵀ's columns at a time."""
        Bt = sp.csc_matrix(B.T)
        W = np.empty((B.shape[0], B.shape[0]))
        for start in range(0, B.shape[0], self._block):
            W[:, start:start + self._block] = B @ self.solve(Bt[:, start:start + self._block].toarray())
        return _symmetrized(W)

    def delassus(self, B: sp.spmatrix, K: sp.spmatrix | None = None, coarse: Callable | None = None) -> Delassus:
        """W = B K⁻¹ Bᵀ as an operator, never formed (see :class:`Delassus`); with ``K`` (the matrix factorized), it
        carries the approximation of W by the slab of K next to B's columns (and ``coarse`` functions beyond it, see
        :func:`slab`); where that is the whole body, its matrices are factorized by :meth:`twin`."""
        return Delassus(B, self.solve, None if K is None else replace(slab(K, B, coarse, self.twin), fill=self.fill))

    def twin(self, *terms: sp.spmatrix) -> Factorization:
        """Factors of the sum of ``terms``, on (part of) K's pattern (see :func:`stored_sum`)."""
        return factorize(stored_sum(*terms), self.backend)


SLAB = 1 / 3
"""Most DOFs of the slab, as a fraction of K's: on a 2-D whole-face strip (10⁵ DOFs, 1001 contact nodes)
CG on W took 103 iterations to 1e-12 unpreconditioned, 31 with an 8-layer slab (18% of the DOFs, 0.1 s to
factorize) and 21 with 16 layers (34%, 0.16 s, against 0.5 s for K); on a 3-D block (10⁵ DOFs, 1681 nodes)
126, 30 with 2 layers (15%, 0.2 s) and 23 with 4 (25%, 0.5 s, against 6 s for K)."""
LAYERS = 8
"""Most layers of elements in the slab. 16 before the coarse functions beyond it (:mod:`..fem.coarse`); with them
the slab's thickness hardly changes the Krylov iterations (2-D strip at 10⁶ DOFs, Tresca, 4001 nodes: 48
products with W at 16 layers, 48 at 8, 47 at 4) and a thinner one is cheaper to factorize (Signorini, 10,001
nodes: contact solve 5.8 s at 16 layers, 4.3 s at 8, 3.3 s at 4; Tresca, 4001 nodes: ~7, 6.7, 7.7 s)."""

COARSE_LAYERS = 2
"""Fewest layers of a slab that gets coarse functions beyond it. A slab of fewer is the face of a body too thin
for more (a third of its DOFs): the functions then cost more than they gain (2-D strip 4 cells high, 10⁵ contact
nodes, Tresca: contact solve 5.6 s with them against 4.0 s without; 3-D block 9 cells high, a 3-layer slab: 40
products with W against 73), and the approximation is then the whole body (see :func:`slab`)."""


@dataclass(frozen=True)
class Approximation:
    """W ≈ G H⁻¹ Gᵀ with H sparse SPD (K on a slab of DOFs next to the contact, its first ``slab`` rows, and on
    coarse functions beyond it) and G = B on them; ``factorize(H, *terms)`` returns the factors of H + the terms, on
    a pattern that holds every entry a term stores, zeros included (:func:`stored_sum`), an object with ``solve``,
    ``refactorize(*terms)`` (new values on that pattern, the sum of the terms) and ``hold(*terms)`` (a sum every later
    refactorization adds its terms to: H, placed once)."""

    G: sp.csr_matrix
    H: sp.csr_matrix
    factorize: Callable
    slab: int | None = None  # None: every row of H is a DOF's
    fill: int | None = None  # nonzeros of K's factors, whose solve is one product with W (None: not known)

    @functools.cached_property
    def diagonal(self) -> np.ndarray:
        """W_jj up to a factor that varies slowly along the face: each row's Delassus with the body clamped a few
        layers from its support (:func:`~convexcontact.fem.local_delassus.local_diagonal`)."""
        from .local_delassus import local_diagonal

        slab = self.H.shape[0] if self.slab is None else self.slab
        if slab == self.H.shape[0]:  # the whole body: no copy of K
            return local_diagonal(self.H, self.G)
        return local_diagonal(self.H[:slab, :slab], self.G[:, :slab])

    def reduced(self, G: sp.spmatrix) -> np.ndarray:
        """G H⁻¹ Gᵀ (dense, symmetric) for a few rows G on H's columns (the coarse start's summed rows,
        solvers/newton_cg.py): with PARDISO the Schur complement of [H Gᵀ; G 0] onto G's rows, formed by one sparse
        factorization (:func:`_appended`, as :class:`Saddle`'s W); else H's factors
        (``factorize``) and a solve with G's rows as right-hand sides. The pair at 1.4·10⁶ DOFs (H 3.2·10⁵ DOFs, 64
        rows): 1.17–1.27 s against 1.82–2.39 s for H's factors and the solves, 16 right-hand sides at a time; the
        factors' fill 1.5 % more, the contact phase's peak within 10 MB of its 2.36 GB."""
        G = sp.csr_matrix(G)
        if _pardiso() is None:
            return self.factorize(self.H).schur(G)
        return _appended(self.H, G)[1]


def slab(K: sp.spmatrix, B: sp.spmatrix, coarse: Callable | None = None, whole: Callable | None = None) -> Approximation:
    """K on the DOFs within a few layers of B's columns (the rest clamped), and B on them: the same Delassus
    operator for a thin body, which has the contact face's short waves right (they decay within a few
    layers) and only its long ones wrong; as a preconditioner it leaves CG few iterations.

    ``coarse(inside, contact)`` (the slab's mask, B's columns) may give functions of the DOFs, zero on the slab
    (n × c, as :class:`~convexcontact.fem.coarse.Functions`, see :func:`~convexcontact.fem.coarse.far_functions`):
    the rest of the body then moves with them instead of being clamped, K on slab + functions (a Galerkin
    approximation of K) has the long waves too, and CG needs fewer iterations still; only beyond a slab of
    COARSE_LAYERS layers or more. Functions that leave that K singular (dependent on the rest) are dropped.

    A body too thin for COARSE_LAYERS layers is its own approximation (G = B, H = K: exact, one more factorization
    of K's size, by ``whole``). A strip clamped at its ends has W's long waves from beam bending, which neither a
    clamped slab nor grid functions beyond it have (aspect 100, 5 cells high: W's first bending mode 4·10⁴ times the
    slab's); its Signorini dual at aspect 400 (2.4·10⁴ DOFs) took 17,006 CG iterations with the 1-layer slab, 1694
    with coarse functions beyond it, 22 with the whole strip (docs/performance.md, "Shapes"). ``whole`` factorizes the
    approximation where it is the whole body (K's factors' :meth:`Factorization.twin`: numeric only, on K's own
    analysis), else :func:`factorize`."""
    K, B = sp.csr_matrix(K), sp.csr_matrix(B)
    contact = np.unique(B.indices)
    inside = np.zeros(K.shape[0], dtype=bool)
    inside[contact] = True
    count, last = contact.size, contact  # the DOFs inside, the last layer's
    for layers in range(LAYERS):  # the layers grown, read after the loop
        last = _next_layer(K, inside, last)
        if count + last.size > SLAB * K.shape[0] or last.size == 0:
            break
        inside[last], count = True, count + last.size
    else:
        layers = LAYERS
    if layers < COARSE_LAYERS:  # too thin for coarse functions: the whole body
        inside[:] = True
    index = np.flatnonzero(inside)
    if inside.all():  # the whole body: K itself, not a copy
        return Approximation(B, K, whole or factorize_sum, index.size)
    rows = K[index]
    G, H = B[:, index], rows[:, index]
    far = None if coarse is None or layers < COARSE_LAYERS else coarse(inside, contact)
    if far is not None and far.shape[1]:
        energy = _nodes_energy(K, far.nodes)
        block = _energy(energy, far.combination)
        keep = independent(block)  # K's energy on the functions formed once here (before, once more in the
        # selection: 3.7 s of the 11 s of the pair's coarse functions at 1.4·10⁶ DOFs). The kept block is definite:
        # its factorization there left every pivot above INDEPENDENT (a second one to check it, PARDISO's and an
        # inverse-iteration solve, 0.04 s on the pair's 3,588 functions at 1.4·10⁶ DOFs, never found it singular)
        far = far.kept(keep).localized()  # the kept span in its nodal basis, G H⁻¹ Gᵀ the same: a hierarchical
        # function over every finer one coupled the slab's DOFs to a third of the functions, which its elimination
        # joined. The pair at 1.4·10⁶ DOFs (3,940 functions): H's block of functions and its coupling 4.1·10⁵ and
        # 9.9·10⁵ nonzeros → 1.4·10⁵ and 2.2·10⁵, H's fill 1.54·10⁷ → 1.13·10⁷ (the slab's alone 9.4·10⁶), the
        # flops of its numeric factorization 1.11·10⁹ → 5.6·10⁸; localized in 0.05 s
        if keep.size:
            block = _energy(energy, far.combination)
            coupling = (rows @ far.nodes) @ far.combination
            H = sp.bmat([[H, coupling], [coupling.T, block]])
            G = sp.hstack([G, sp.csr_matrix((B.shape[0], keep.size))])
    return Approximation(G.tocsr(), H.tocsr(), factorize_sum, index.size)


def _next_layer(K: sp.csr_matrix, inside: np.ndarray, last: np.ndarray) -> np.ndarray:
    """The DOFs outside ``inside`` with a nonzero entry of K (a stored zero is none) in a column inside, found among
    the neighbours of the ``last`` layer grown (K's pattern is symmetric; an entry's row checked, as the product of K's
    pattern with the mask it replaces read it): a product over all of K's rows a layer, and K's pattern held as
    int32s for it, took 0.15–0.35 s of the pair's slab at 1.4·10⁶ DOFs (8 layers), these ~0.02 s."""
    near = K[last].indices
    near = np.unique(near[~inside[near]])
    rows = K[near]
    reached = (rows.data != 0) & inside[rows.indices]
    return near[np.add.reduceat(reached, rows.indptr[:-1]) > 0] if near.size else near


def _symmetrized(A: np.ndarray, scale: float = 1.0, block: int = 256) -> np.ndarray:
    """scale · (A + Aᵀ) / 2 in A's own memory, a pair of blocks at a time: ``A += A.T`` makes a copy of A (numpy's
    rule for overlapping operands), an m² array at the dense dual's peak (the 2-D pair at 3.2·10⁵ DOFs with Tresca:
    165 MB of its 847). Blocks of 256² (1 MB a temporary): of 1024² they added 16 MB to the pair's peak at 2.6·10⁵
    DOFs, right after the saddle's factorization (W 3628², 105 MB), and took 0.11 s against 0.035 s."""
    for i in range(0, A.shape[0], block):
        rows = slice(i, i + block)
        for j in range(i, A.shape[0], block):
            columns = slice(j, j + block)
            mean = (A[rows, columns] + A[columns, rows].T) * (0.5 * scale)
            A[rows, columns], A[columns, rows] = mean, mean.T
    return A


def factorize_sum(*terms: sp.spmatrix) -> Factorization:
    """Factors of the :func:`stored_sum` of ``terms``: an approximation's own (see :class:`Approximation`)."""
    return factorize(stored_sum(*terms))


def same_shape(terms, caller: str) -> None:
    """ValueError naming the shapes where ``terms`` are not all of one."""
    if any(term.shape != terms[0].shape for term in terms):
        raise ValueError(f"{caller}: terms of shapes {[term.shape for term in terms]}: give each the matrix's shape")


def stored_sum(*terms: sp.spmatrix) -> sp.csr_matrix:
    """The sum of ``terms`` holding every entry any of them stores, zeros included (scipy's sums drop them, and a
    later refactorization on the pattern needs them). A CSR term's rows are expanded straight into the one triplet
    list: its COO copy, abs(H) and the sum of patterns this replaces held ~100 bytes per entry of H at once, the
    preconditioner's peak on thin bodies (strip 400 : 1 clamped, 3.4·10⁴ DOFs, Tresca: ~40 MB beside its 13 MB
    factor)."""
    same_shape(terms, "stored_sum")
    if len(terms) == 1:
        return sp.csr_matrix(terms[0])
    index = np.int64 if max(terms[0].shape) >= 2**31 else np.int32  # row and column numbers

    def triplets(term):  # (values, rows, columns)
        if sp.isspmatrix_csr(term):
            return term.data, np.repeat(np.arange(term.shape[0], dtype=index), np.diff(term.indptr)), term.indices
        term = sp.coo_matrix(term)
        return term.data, term.row, term.col

    data, rows, columns = (np.concatenate(parts) for parts in zip(*map(triplets, terms)))
    return sp.csr_matrix((data, (rows.astype(index, copy=False), columns.astype(index, copy=False))),
                         shape=terms[0].shape)


CHUNK = 2**17
"""Rows of K a partial product of :func:`_energy` takes: K F whole was the contact phase's peak on the pair at
1.4·10⁶ DOFs (3,940 functions, 3.9·10⁷ nonzeros, and its copy in columns: 900 MB); by chunks of this many rows, 356
MB in the same time."""


def _nodes_energy(K: sp.csr_matrix, N: sp.csr_matrix) -> sp.csr_matrix:
    """Nᵀ K N for the nodes N of :class:`~convexcontact.fem.coarse.Functions`, summed over chunks of CHUNK rows of
    K."""
    energy = sp.csr_matrix((N.shape[1], N.shape[1]))
    for start in range(0, K.shape[0], CHUNK):
        rows = slice(start, start + CHUNK)
        energy += N[rows].T @ (K[rows] @ N)
    return energy


def _energy(energy: sp.csr_matrix, C: sp.csr_matrix) -> sp.csr_matrix:
    """Fᵀ K F for F = N C (C the combination) from the nodes' ``energy`` Nᵀ K N (:func:`_nodes_energy`), as
    Cᵀ (Nᵀ K N) C; symmetrized: scipy's products drop the sums that cancel to 0, so round-off stored (i, j) and not
    (j, i) (−1.2e-16 on the punch's foundation at h 0.005): an H whose pattern is not symmetric, where a
    factorization of it whole (an LU) read an entry its Cholesky never held."""
    energy = C.T @ energy @ C
    return ((energy + energy.T) * 0.5).tocsr()


class Delassus(spla.LinearOperator):
    """W = B K⁻¹ Bᵀ as a symmetric operator: each product is one solve with K's factors, and W is never formed
    (memory O(n + nnz(L)) whatever the number of rows of B). ``approximation``: a cheaper W for
    preconditioning, or None."""

    def __init__(self, B: sp.spmatrix, solve: Callable, approximation: Approximation | None = None):
        super().__init__(float, (B.shape[0], B.shape[0]))
        self.B, self._Bt, self._solve = sp.csr_matrix(B), sp.csr_matrix(B.T), solve
        self.approximation = approximation

    def _matvec(self, r):
        return self.B @ self._solve(self._Bt @ r)

    _rmatvec = _matmat = _matvec


class _Direct(Factorization):
    def __init__(self, K: sp.spmatrix, backend: str, dim: int):
        start = time.perf_counter()
        self.backend, self._dim = backend, dim
        self._factors = None
        if backend == "pardiso":
            self._factors = _pardiso_factors(K)
            self._solve, self._block = self._factors.solve, _pardiso().BLOCK
        else:
            self._solve, self._pattern = _superlu(K, dim), _structure(K)
        self.timings = {"factorization": time.perf_counter() - start}
        _check_definite(K, self.solve)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._solve(b)

    @property
    def fill(self) -> int | None:
        return None if self._factors is None else self._factors.fill

    @property
    def flops(self) -> float | None:
        return None if self._factors is None else self._factors.flops

    def twin(self, *terms: sp.spmatrix) -> Factorization:
        """Factors of the sum of ``terms``, on (part of) K's pattern (the preconditioner of a body that is its own
        approximation: K and a contact block within K's node blocks): with PARDISO a second numeric factorization on
        K's analysis (:meth:`~convexcontact.fem.pardiso.Pardiso.twin`: no second ordering, nor its memory, and the
        terms placed, not summed: a K-sized sum was Signorini's peak on a clamped plate, 1.90 against 1.78 × the
        linear solve's at 9.4·10⁴ DOFs); else, or where a term has entries outside K's pattern or PARDISO holds its
        most factorizations, factors of their :func:`stored_sum`."""
        same_shape(terms, "twin")  # before the try: not to be taken for an entry outside the pattern
        try:
            factors = self._factors and self._factors.twin(*terms)
        except ValueError:  # outside K's pattern
            factors = None
        if not factors:
            return factorize(stored_sum(*terms), self.backend, self._dim)
        twin = object.__new__(_Direct)
        twin.backend, twin._dim, twin._factors, twin._block = self.backend, self._dim, factors, self._block
        twin._solve, twin.timings = factors.solve, {}
        return twin

    _held: tuple = ()  # SuperLU's base of later refactorizations (see hold)

    def refactorize(self, *terms: sp.spmatrix) -> None:
        """Factorize new values, the sum of ``terms`` and of the base :meth:`hold` set, on the sparsity pattern of the
        first K (entries outside it: ValueError), without the singularity check: PARDISO keeps its ordering and redoes
        only the numeric factorization, placing each term's entries (their sum is not formed: a K-sized temporary)."""
        if self._factors is not None:
            self._factors.refactorize(*terms)
            return
        K = sum(self._held + terms[1:], terms[0])
        if (_structure(K) > self._pattern).nnz:
            raise ValueError("refactorize: the matrix has entries outside the pattern factorized")
        self._solve = _superlu(K, self._dim)  # SuperLU has no numeric-only factorization: a new one

    def hold(self, *terms: sp.spmatrix) -> None:
        """Make the sum of ``terms`` the base of the next refactorizations (until the next call): each factorizes it +
        its own terms. PARDISO places the base once (:meth:`~convexcontact.fem.pardiso.Pardiso.hold`)."""
        if self._factors is not None:
            self._factors.hold(*terms)
        else:
            self._held = terms


def _structure(K: sp.spmatrix) -> sp.csr_matrix:
    """The entries K stores, explicit zeros included (``abs(K) > 0`` would drop them)."""
    K = sp.csr_matrix(K)
    return sp.csr_matrix((np.ones(K.nnz, dtype=bool), K.indices, K.indptr), shape=K.shape)


def factorize(K: sp.spmatrix, backend: str = "auto", dim: int = 2) -> Factorization:
    """Factorize the SPD stiffness on the free DOFs.

    Parameters
    ----------
    K : sparse symmetric positive definite (n, n).
    backend : "auto" (PARDISO if pypardiso loads, else SuperLU), "pardiso" or "superlu".
    dim : spatial dimension of the mesh; picks SuperLU's column ordering.

    Raises
    ------
    SceneError
        field "dirichlet" if K is (numerically) singular; checking costs one more solve.
    """
    return _Direct(K, _backend(backend), dim)



class Condensation(Factorization):
    """K partitioned into interior DOFs I and contact DOFs C, condensed onto C (see :func:`condense`).

    Attributes
    ----------
    C : sorted contact DOF indices.
    S : dense symmetric Schur complement K_CC − K_CI K_II⁻¹ K_IC, (|C|, |C|): computed again from its Cholesky
        factor where asked for (the derivatives, drivers/linearized.py), not held beside it.
    backend : "pardiso" or "superlu".
    timings : seconds for "factorization", "schur" (building S; PARDISO returns S with its
        factors, so there "factorization" includes it) and "cholesky" (of S).
    """

    def _finish(self, K: sp.spmatrix, S: np.ndarray, start: float) -> None:
        self.timings["schur"] = time.perf_counter() - start
        start = time.perf_counter()
        try:  # S's lower triangle (S.T's upper, Fortran order), factored in S's own memory: S (|C|² doubles) held
            # beside its factor and symmetrized by S += S.T (a transposed copy) were three |C|² arrays at once, the
            # dense dual's peak on the 2-D pair (|C| = 2566: 53 MB each), and the symmetrization 0.15 s of its 1.2 s
            self._cho = la.cho_factor(S.T, overwrite_a=True, check_finite=False)
        except la.LinAlgError:
            raise singular_stiffness("its Schur complement on the contact DOFs is not positive definite") from None
        self.timings["cholesky"] = time.perf_counter() - start
        _check_definite(K, self.solve)

    @functools.cached_property
    def S(self) -> np.ndarray:
        """S = UᵀU from its Cholesky factor (symmetric: numpy forms Xᵀ X by BLAS's syrk)."""
        U = np.triu(self._cho[0])
        return U.T @ U

    @abstractmethod
    def load(self, f: np.ndarray) -> np.ndarray:
        """Condensed load f_C − K_CI K_II⁻¹ f_I, for f of shape (n,) or (n, k)."""

    @abstractmethod
    def lift(self, u_C: np.ndarray, f: np.ndarray) -> np.ndarray:
        """All free DOFs u with u_C given and u_I = K_II⁻¹(f_I − K_IC u_C)."""

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K⁻¹ b = lift(S⁻¹ load(b), b)."""
        return self.lift(la.cho_solve(self._cho, self.load(b)), b)

    def schur(self, B: sp.spmatrix) -> np.ndarray:
        """W = B K⁻¹ Bᵀ = B_C S⁻¹ B_Cᵀ (dense, symmetrized) for B whose nonzero columns lie in C."""
        B = sp.csc_matrix(B)
        outside = np.ones(B.shape[1], dtype=bool)
        outside[self.C] = False
        if abs(B[:, outside]).sum() > 0:
            raise ValueError("B has nonzero columns outside the condensed DOFs C: condense onto every DOF B touches")
        # W = XᵀX, X = U⁻ᵀ B_Cᵀ (S = UᵀU): one triangular solve and BLAS's syrk (numpy's Xᵀ X; symmetric as it is
        # formed), half the flops of S⁻¹ B_Cᵀ by two (cho_solve) and a product (the pair at 10⁵ DOFs: 0.67 → 0.4 s)
        X = la.solve_triangular(self._cho[0], sp.csr_matrix(B[:, self.C]).T.toarray(order="F"), trans="T",
                                lower=self._cho[1], overwrite_b=True, check_finite=False)
        return X.T @ X


class _Interior(Condensation):
    """SuperLU factors of K_II; S from solves with K_IC's columns, :data:`BLOCK` at a time."""

    def __init__(self, K: sp.csr_matrix, C: np.ndarray, dim: int):
        start = time.perf_counter()
        self.C, self.backend = C, "superlu"
        self._I = np.setdiff1d(np.arange(K.shape[0]), C)
        rows_C, rows_I = K[C], K[self._I]
        self._K_CI, self._K_IC = rows_C[:, self._I].tocsr(), rows_I[:, C].tocsc()
        self._solve_II = _superlu(rows_I[:, self._I], dim)
        self.timings = {"factorization": time.perf_counter() - start}
        start = time.perf_counter()
        S = rows_C[:, C].toarray()
        near = np.flatnonzero(np.diff(self._K_IC.tocsr().indptr))  # interior DOFs coupled to C
        K_CN = self._K_CI[:, near]
        for j in range(0, C.size, BLOCK):
            S[:, j:j + BLOCK] -= K_CN @ self._solve_II(self._K_IC[:, j:j + BLOCK].toarray())[near]
        self._finish(K, S, start)

    def load(self, f: np.ndarray) -> np.ndarray:
        f = np.asarray(f, dtype=float)
        return f[self.C] - self._K_CI @ self._solve_II(f[self._I])

    def lift(self, u_C: np.ndarray, f: np.ndarray) -> np.ndarray:
        f = np.asarray(f, dtype=float)
        u = np.empty(f.shape)
        u[self.C] = u_C
        u[self._I] = self._solve_II(f[self._I] - self._K_IC @ u_C)
        return u


class _Schur(Condensation):
    """PARDISO's Schur complement (iparm[35] = 2): one factorization of K with C ordered last.

    Its factors are L = [L_II 0; L_CI I], so the forward phase leaves the condensed load
    on C, and the backward phase from it with u_C put on C gives u_I (the lift).
    """

    def __init__(self, K: sp.csr_matrix, C: np.ndarray):
        start = time.perf_counter()
        self.C, self.backend = C, "pardiso"
        self._factors = _pardiso_factors(K, schur=C)
        self.timings = {"factorization": time.perf_counter() - start}
        S, self._factors.S = self._factors.S, None  # factored in place: no name left on what becomes its factor
        self._finish(K, S, time.perf_counter())

    def load(self, f: np.ndarray) -> np.ndarray:
        return self._factors.forward(f)[self.C]

    def lift(self, u_C: np.ndarray, f: np.ndarray) -> np.ndarray:
        y = self._factors.forward(f)
        y[self.C] = u_C
        return self._factors.backward(y)

    def solve(self, b: np.ndarray) -> np.ndarray:
        y = self._factors.forward(b)  # one forward phase serves load and lift
        y[self.C] = la.cho_solve(self._cho, y[self.C])
        return self._factors.backward(y)


def condense(K: sp.spmatrix, C: np.ndarray, backend: str = "auto", dim: int = 2) -> Condensation:
    """Condense the SPD stiffness onto the DOFs C (|C| ≪ n).

    PARDISO returns S from its factorization of K with C ordered last (iparm[35]); that
    cost about one plain factorization in 2-D and 1.2–2× one in 3-D, less than factoring
    K_II and building S from partial or blocked solves. SuperLU factors K_II and solves
    for K_IC's columns.

    Parameters
    ----------
    K : sparse symmetric positive definite (n, n), on the free DOFs.
    C : indices of the free DOFs to keep (contact DOFs); sorted and made unique.
    backend : "auto" (PARDISO if pypardiso loads, else SuperLU), "pardiso" or "superlu".
    dim : spatial dimension of the mesh; picks SuperLU's ordering.

    Raises
    ------
    SceneError
        field "dirichlet" if K is (numerically) singular; checking costs one more solve.
    """
    backend = _backend(backend)
    K = sp.csr_matrix(K)
    C = np.unique(np.asarray(C, dtype=np.int64))
    if C.size == 0 or C.size == K.shape[0] or C[0] < 0 or C[-1] >= K.shape[0]:
        raise ValueError(f"C must be a nonempty proper subset of the {K.shape[0]} DOFs")
    return _Schur(K, C) if backend == "pardiso" else _Interior(K, C, dim)


SADDLE_COLUMNS = 2000
"""Contact DOFs |C| from which the dense dual's W comes from :func:`saddle` (where PARDISO loads), not from
:func:`condense`: the condensation's dense S (|C|²), its Cholesky (|C|³/3) and the triangular solve and product that
form W from it (|C|² m + |C| m²) cost 0.6 s of the 2-D pair's 2 s contact phase at 10⁵ DOFs (|C| = 2566, m = 1434),
and 2.4× the linear solve's memory (docs/performance.md, "W from K's factors with B's rows appended"). Below, they
cost little, and a condensation serves the answer's derivatives as well (drivers/linearized.py)."""


SADDLE_FREED = 0.25
"""W's bytes (8 m²) as a fraction of a linear solve's memory (:data:`LINEAR_BYTES` per stored entry of K) from which
:class:`Saddle` frees the saddle's factors once W is formed and factors K alone for the solves: PARDISO keeps A's
m × m Schur block among them, a second W that no solve needs. The 2-D pair at 2.6·10⁵ DOFs (m = 3628, 0.39): A's
factors took 312 MB, K's 213, W 105; the dense dual's peak fell from 2.23× to 1.92× the linear solve's with Tresca,
2.43× to 2.07× with Coulomb. It costs K's own factorization (analysis and numeric phase, ~0.9 s CPU there against the
saddle's 2.4 s) and one Newton step more (all six rows of the pair at 10⁵ and 2.6·10⁵ DOFs): W and K's solves from
two factorizations each err by ~3·10⁻¹¹, and Px + q differs from the gradient's solves by 3·10⁻¹³ of q, where one
factorization gave 2·10⁻¹⁶; the stopping test, which checks with the gradient's solves, asks for one step more. Kept
where the peak stayed under 2× (the pair's friction rows at 1.4·10⁵ DOFs, 0.21: 1.77–1.81×; its Signorini rows at
2.6·10⁵, 0.10: 1.49–1.54×); at 1.7·10⁵, 0.26, 1.96–1.98×, at 2.1·10⁵, 0.32, 2.06–2.13× (docs/performance.md, "The
saddle's W without PARDISO's Schur block")."""

LINEAR_BYTES = 75
"""A linear solve's peak memory per stored entry of K: 1.00–1.04 kB per DOF on the 2-D pair from 5·10⁴ to 1.4·10⁶ DOFs,
13.8 entries of K per DOF (docs/performance.md, "The dense W's memory on the pair")."""


class Saddle(Factorization):
    """K factored with the contact rows B appended, A = [K Bᵀ; B 0], by PARDISO (symmetric indefinite, B's rows
    ordered last, K's block pivoted as K alone): A's Schur complement onto B's rows is −W, formed by the sparse
    factorization itself. Its forward, diagonal and backward phases with B's part set to zero solve with K; where W is
    large beside K (:data:`SADDLE_FREED`) those factors are freed once W is formed and K's own solve.

    Attributes
    ----------
    B : the rows factored; :meth:`schur` of other rows factors A again with them.
    """

    backend = "pardiso"

    def __init__(self, K: sp.spmatrix, B: sp.spmatrix):
        self._K, self.timings = sp.csr_matrix(K), {}
        self._factor(B)
        _check_definite(self._K, self.solve)

    def _factor(self, B: sp.spmatrix) -> None:
        start = time.perf_counter()
        self.B, self._factors, self._W = sp.csr_matrix(B), None, None  # the former factors and W freed first
        self._factors, self._W = _appended(self._K, self.B)
        self._own = 8.0 * self.B.shape[0] ** 2 >= SADDLE_FREED * LINEAR_BYTES * self._K.nnz
        if self._own:
            self._factors = None  # A's factors, their Schur block with them, freed before K's are made
            self._factors = _pardiso_factors(self._K)
        self.timings["factorization"] = time.perf_counter() - start

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._own:
            return self._factors.solve(b)
        b = np.asarray(b, dtype=float)
        n = self._K.shape[0]
        y = self._factors.diagonal(self._factors.forward(np.concatenate([b, np.zeros((self.B.shape[0],) + b.shape[1:])])))
        y[n:] = 0.0
        return self._factors.backward(y)[:n]

    @property
    def fill(self) -> int:
        """Nonzeros of the factors held: A's (its Schur block's among them), or K's own."""
        return self._factors.fill

    def schur(self, B: sp.spmatrix) -> np.ndarray:
        B = sp.csr_matrix(B)
        if B.shape != self.B.shape or (B != self.B).nnz:
            self._factor(B)
        return self._W


def _appended(K: sp.csr_matrix, B: sp.csr_matrix) -> tuple:
    """PARDISO's factors of A = [K Bᵀ; B 0] (symmetric indefinite, B's rows ordered last, K's block pivoted as K
    alone) and B K⁻¹ Bᵀ, −(A's Schur complement onto B's rows) symmetrized, formed by the sparse factorization itself
    (:class:`Saddle`'s W, :meth:`Approximation.reduced`)."""
    n, m = K.shape[0], B.shape[0]
    zeros = sp.csr_matrix((np.zeros(m), np.arange(m), np.arange(m + 1)), shape=(m, m))  # stored: PARDISO's rule
    A = sp.bmat([[sp.triu(K), B.T], [None, zeros]], format="csr")  # its own upper triangle: factored as it is
    A.sum_duplicates()  # canonical (sorted columns), in place
    factors = _pardiso_factors(A, schur=np.arange(n, n + m), mtype=_pardiso().SADDLE, upper=True)
    W, factors.S = _symmetrized(factors.S, -1.0), None
    return factors, W


def saddle(K: sp.spmatrix, B: sp.spmatrix) -> Saddle:
    """K's factorization with B's rows appended (:class:`Saddle`): W = B K⁻¹ Bᵀ with no dense Schur complement of
    K. Needs PARDISO.

    Raises
    ------
    SceneError
        field "dirichlet" if K is (numerically) singular.
    """
    if _pardiso() is None:
        raise ImportError("saddle needs pypardiso (pip install pypardiso); condense(K, C) serves without it")
    return Saddle(K, B)


def dual_factors(K: sp.spmatrix, C: np.ndarray, B: sp.spmatrix, dim: int = 2) -> Factorization:
    """What the dense dual forms W = B K⁻¹ Bᵀ from: :func:`saddle` where B touches :data:`SADDLE_COLUMNS` DOFs or
    more (``C``), has fewer rows than those DOFs (W smaller than S) and PARDISO loads, else :func:`condense` onto
    ``C``. Where the rows are as many as the DOFs (one body with friction: every DOF of a node a row) the saddle
    gained nothing (the 2-D punch at 10⁶ DOFs, Tresca, 2002 rows: contact CPU 14.6 against 17.8 s, memory 1.15 against
    1.21×, under load; the clamped strip 20 : 1, 4.72 against 4.65), and the condensation serves the derivatives."""
    if saddle_applies(np.unique(C).size, B.shape[0]):
        return saddle(K, B)
    return condense(K, C, dim=dim)


def saddle_applies(columns: int, rows: int) -> bool:
    """Whether :func:`dual_factors` takes :func:`saddle` for ``rows`` dual rows touching ``columns`` DOFs."""
    return columns >= SADDLE_COLUMNS and rows < columns and _pardiso() is not None
