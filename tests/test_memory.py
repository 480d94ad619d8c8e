"""Peak memory of the matrix-free dual on thin bodies (issue 25, docs/performance.md "Peak memory on thin bodies"):
the pieces that were rows × DOFs arrays or copies of K hold a few times K's bytes, and give what they gave."""

import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.fem import factorization, pardiso
from convexcontact.fem.local_delassus import local_diagonal
from convexcontact.solvers import newton_cg
from convexcontact.solvers.cone_polish import bound_form
from convexcontact.studies.benchmarks.bench import scene_of


def nbytes(A: sp.csr_matrix) -> int:
    return A.data.nbytes + A.indices.nbytes + A.indptr.nbytes


def traced_peak(build) -> int:
    """The most bytes numpy and Python held at once while ``build()`` ran (not SuperLU's or PARDISO's own)."""
    tracemalloc.start()
    try:
        build()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.fixture(scope="module")
def strip():
    """The clamped strip 400 : 1 (4.8·10³ DOFs, 801 contact nodes), its Tresca dual applied matrix-free."""
    return cc.prepare(scene_of("strip-clamped-400", 2, "tresca", 4e3), "dual-matrix-free")


def test_the_local_diagonal_holds_a_few_times_k(strip):
    """Each row's d_j is picked from the rows × slots products: the rows × region array of each row's slot's response
    it replaces took 6.2 × K's bytes here (and grows with the rows of a colour), now 2.3 ×."""
    K, B = sp.csr_matrix(strip.fem.K), sp.csr_matrix(strip.program.P.B)
    assert traced_peak(lambda: local_diagonal(K, B)) <= 3.5 * nbytes(K)


def test_a_thin_body_is_its_own_approximation_without_a_copy_of_k(strip):
    """Too thin for coarse functions, the body is its approximation: K itself (its arrays shared, not copied) and B,
    so G H⁻¹ Gᵀ is W."""
    approximation, K = strip.program.P.approximation, strip.fem.K
    assert np.shares_memory(approximation.H.data, K.data) and np.shares_memory(approximation.H.indices, K.indices)
    r = np.random.default_rng(0).standard_normal(strip.program.P.shape[0])
    G = approximation.G
    np.testing.assert_allclose(G @ approximation.factorize(approximation.H).solve(G.T @ r), strip.program.P @ r,
                               rtol=1e-10, atol=1e-12 * np.abs(strip.program.P @ r).max())


@pytest.mark.parametrize("shape, dim, dofs", [("strip-clamped-400", 2, 4e3), ("plate-free-20", 3, 3e3)])
def test_the_preconditioner_holds_a_few_times_k_while_it_is_built(shape, dim, dofs):
    """H + Gᵀ D⁻¹ G on the pattern of every later Newton system from one triplet list: abs(H), the sums of patterns and
    the COO copies it replaces took 6.8 × H's bytes on the strip and 7.5 × on the 3-D plate (measured), now ~3 ×."""
    model = cc.prepare(scene_of(shape, dim, "tresca", dofs), "dual-matrix-free")
    approximation = model.program.P.approximation
    sets = newton_cg._bounds(model.program, bound_form(model.program))
    shift = newton_cg.SHIFT * newton_cg._shifts(approximation, sets, lambda: 1.0)
    n, p = sets.scale.size, sets.balls.shape[1]
    every = newton_cg._expansion(n, np.arange(n), sets.balls[:0], np.zeros((0, p, p - 1)))  # every variable free
    # the factorization is at the first Newton system's (the pattern ordered for all of them, its values)
    peak = traced_peak(lambda: newton_cg._Preconditioner(approximation, sets.scale, sets.balls, shift).system(
        every, np.zeros(n)))
    assert peak <= 4.0 * nbytes(approximation.H)


def test_the_stored_sum_refuses_terms_of_another_shape():
    """A pattern whose shape was inferred from its largest index is an error that names the shapes."""
    with pytest.raises(ValueError, match=r"^stored_sum: terms of shapes \[\(5, 5\), \(2, 3\)\]"):
        factorization.stored_sum(sp.eye(5, format="csr"), sp.coo_matrix(([0.0], ([1], [2]))))


def test_the_stored_sum_keeps_every_entry_and_adds_the_values():
    """H + A with every entry either stores, explicit zeros and cancellations included (a later refactorization on
    the pattern needs them); the values those of the sum."""
    rng = np.random.default_rng(3)
    H = sp.coo_matrix(sp.random(30, 30, density=0.2, random_state=rng))
    i, j = H.row[0], H.col[0]  # A cancels H there
    A = sp.coo_matrix(([0.0, -H.data[0], 2.0], ([0, i, 7], [29, j, 7])), shape=(30, 30))
    total = sp.coo_matrix(factorization.stored_sum(sp.csr_matrix(H), A))
    np.testing.assert_allclose(total.toarray(), H.toarray() + A.toarray(), rtol=0, atol=1e-15)
    stored = set(zip(H.row, H.col)) | set(zip(A.row, A.col))
    assert set(zip(total.row, total.col)) == stored and total.nnz == len(stored)


@pytest.mark.parametrize("law, steps, products", [("tresca", 2, 12), ("signorini", 2, 13)])
def test_the_strip_takes_the_newton_steps_it_took(law, steps, products):
    """The storage changed, the method not: the clamped strip's dual takes the Newton steps the method takes (Tresca
    12 and 218 products with W when the storage changed, one more from the rounding of the local diagonal's sums;
    Signorini 6 and 50; since the empty face is tried first, FIRST_FORCING, 3 and 21, 3 and 23; since faces grow with
    bounds alone and the empty face's grown faces stop at GROWN_FORCING, 2 and 18, 2 and 19; since ∇f at a feasible
    Newton point comes from CG's products, newton_cg.GROW, 2 and 16, 2 and 17; with no product at x = 0, where ∇f is
    q, 2 and 16, 2 and 16; the second step from the gradient the first ended with, 2 and 14, 2 and 15; with the
    stopping test and a step's start on the updates of a fresh ∇f where their rounding is below the tolerance,
    newton_cg._fresh_enough, 2 and 12, 2 and 13: tests/test_products.py)."""
    model = cc.prepare(scene_of("strip-clamped-400", 2, law, 4e3), "dual-matrix-free")
    solution = newton_cg.solve(model.program)
    assert solution.status == "solved" and solution.iterations == steps
    assert abs(solution.info["products"] - products) <= 1


def test_refactorize_by_chunks_gives_what_one_chunk_gives_and_refuses_an_entry_outside(strip, monkeypatch):
    """PARDISO's refactorization places K's upper entries a few rows at a time: by chunks of 3 entries (every row
    its own chunks) the solves of one chunk (to the last bits PARDISO's threads vary); an entry outside the pattern
    in the last row is refused (the factors still solve the last matrix); by chunks of a sixteenth of K its numpy
    temporaries held ≤ 8 bytes per entry of K (the COO triangle and the keys of every entry it replaced: ~26 in one
    chunk, measured)."""
    if factorization._pardiso() is None:
        pytest.skip("PARDISO does not load here")
    K = sp.csr_matrix(strip.fem.K)
    rng = np.random.default_rng(2)
    factors = factorization.factorize(K, "pardiso")
    scaled = sp.diags(rng.uniform(0.5, 2.0, K.shape[0]))
    changed = (scaled @ K @ scaled).tocsr()
    b = rng.standard_normal(K.shape[0])
    monkeypatch.setattr(pardiso, "REFACTOR_CHUNK", K.nnz)
    factors.refactorize(changed)
    whole = factors.solve(b)
    monkeypatch.setattr(pardiso, "REFACTOR_CHUNK", K.nnz // 16)
    assert traced_peak(lambda: factors.refactorize(changed)) <= 8 * K.nnz
    factors.refactorize(K)
    monkeypatch.setattr(pardiso, "REFACTOR_CHUNK", 3)
    factors.refactorize(changed)
    np.testing.assert_allclose(factors.solve(b), whole, rtol=0, atol=1e-12 * np.abs(whole).max())
    n = K.shape[0]
    outside = changed + sp.csr_matrix(([1.0, 1.0], ([0, n - 1], [n - 1, 0])), shape=K.shape)
    with pytest.raises(ValueError, match="outside the pattern"):
        factors.refactorize(2.0 * outside)
    np.testing.assert_allclose(factors.solve(b), whole, rtol=0, atol=1e-12 * np.abs(whole).max())


@pytest.mark.parametrize("backend", ["pardiso", "superlu"])
def test_refactorize_of_terms_solves_with_their_sum(strip, backend):
    """The preconditioner refactorizes K and its contact block as two terms, never summed into a K-sized matrix:
    its solves are those of the sum refactorized (the same values placed; PARDISO's threads vary the last bits,
    4e-16 measured)."""
    if backend == "pardiso" and factorization._pardiso() is None:
        pytest.skip("PARDISO does not load here")
    K, B = sp.csr_matrix(strip.fem.K), sp.csr_matrix(strip.program.P.B)
    block = (B.T @ sp.diags(np.random.default_rng(4).uniform(1.0, 2.0, B.shape[0])) @ B).tocsr()
    factors = factorization.factorize(factorization.stored_sum(K, block), backend)  # K's stored zeros too
    b = np.random.default_rng(5).standard_normal(K.shape[0])
    factors.refactorize(2.0 * K, block)
    by_terms = factors.solve(b)
    factors.refactorize((2.0 * K + block).tocsr())
    np.testing.assert_allclose(by_terms, factors.solve(b), rtol=0, atol=1e-12 * np.abs(by_terms).max())


def test_refactorize_keeps_each_term_s_places_while_its_pattern_stays(strip, monkeypatch):
    """Each Newton step passes K and a contact block of the same patterns: their places in PARDISO's data are searched
    once; a block of another pattern in the same place (another free set) is placed anew, and the solves are those of
    the sum factorized afresh."""
    if factorization._pardiso() is None:
        pytest.skip("PARDISO does not load here")
    K, B = sp.csr_matrix(strip.fem.K), sp.csr_matrix(strip.program.P.B)
    rng = np.random.default_rng(6)
    factors = factorization.factorize(factorization.stored_sum(K, (B.T @ B).tocsr()), "pardiso")
    searched = []
    places = pardiso.Pardiso._places
    monkeypatch.setattr(pardiso.Pardiso, "_places", lambda self, *args: searched.append(1) or places(self, *args))
    b = rng.standard_normal(K.shape[0])
    counts = []
    for rows in (B, B, B[: B.shape[0] // 2]):
        block = (rows.T @ sp.diags(rng.uniform(1.0, 2.0, rows.shape[0])) @ rows).tocsr()
        before = len(searched)
        factors.refactorize(K, block)
        counts.append(len(searched) - before)
        fresh = factorization.factorize((K + block).tocsr(), "pardiso").solve(b)
        np.testing.assert_allclose(factors.solve(b), fresh, rtol=0, atol=1e-10 * np.abs(fresh).max())
    assert counts[0] > counts[2] > counts[1] == 0  # both terms; none; the new block only


@pytest.mark.parametrize("backend", ["pardiso", "superlu"])
def test_a_held_base_is_placed_once_and_each_refactorization_adds_its_terms(strip, backend, monkeypatch):
    """The preconditioner holds H as the base of its refactorizations: with PARDISO its values are placed at the
    first only (later ones place and hash the contact block's entries alone), and each solves with the base + the
    block (against a fresh factorization of the sum, ordered anew: 1.2e-10 on this strip of aspect 400), its values
    factorized bit for bit those of the two placed as terms; a base held anew (H changed) replaces the old one."""
    if backend == "pardiso" and factorization._pardiso() is None:
        pytest.skip("PARDISO does not load here")
    K, B = sp.csr_matrix(strip.fem.K), sp.csr_matrix(strip.program.P.B)
    rng = np.random.default_rng(7)
    factors = factorization.factorize(factorization.stored_sum(K, (B.T @ B).tocsr()), backend)
    placed, hashed = [], []
    if backend == "pardiso":
        values, blake2b = pardiso.Pardiso._upper_values, pardiso.hashlib.blake2b
        monkeypatch.setattr(pardiso.Pardiso, "_upper_values",
                            lambda self, term: (placed.append(term.nnz), values(self, term))[1])
        monkeypatch.setattr(pardiso.hashlib, "blake2b", lambda data: hashed.append(data.nbytes) or blake2b(data))
        terms = factorization.factorize(factorization.stored_sum(K, (B.T @ B).tocsr()), "pardiso")
    b = rng.standard_normal(K.shape[0])
    for base in (K, 2.0 * K):
        factors.hold(base)
        for first, rows in zip((True, False, False), (B, B[: B.shape[0] // 2], B)):
            block = (rows.T @ sp.diags(rng.uniform(1.0, 2.0, rows.shape[0])) @ rows).tocsr()
            placed.clear(), hashed.clear()
            factors.refactorize(block)
            fresh = factorization.factorize((base + block).tocsr(), backend).solve(b)
            np.testing.assert_allclose(factors.solve(b), fresh, rtol=0, atol=1e-8 * np.abs(fresh).max())  # 1.2e-10
            if backend == "pardiso":
                assert placed == ([K.nnz] if first else []) + [block.nnz]
                assert sum(hashed) <= block.indptr.nbytes + block.indices.nbytes
                terms._factors.refactorize(base, block)
                np.testing.assert_array_equal(factors._factors._handle[3], terms._factors._handle[3])


def test_a_dense_newton_system_with_tangent_bases_holds_two_arrays_of_its_size_at_once():
    """Rᵀ P̃ Z on turned tangent bases (newton_cg._reduced): its m × m temporaries freed as soon as used, two alive at
    a time (before, three: the pair's Coulomb at 2.6·10⁵ DOFs peaked at 2.07× the linear solve's memory, now 1.99×),
    and the same array as the product formed densely."""
    m = 600
    A = np.random.default_rng(0).standard_normal((m, m))
    P = A + A.T
    c, s = np.cos(0.3), np.sin(0.3)
    Z = sp.block_diag([np.array([[c, -s], [s, c]])] * (m // 2), format="csr")
    R = sp.csr_matrix(Z.multiply(2.0))
    tracemalloc.start()
    try:
        reduced = newton_cg._reduced(P, Z, R)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2.5 * 8 * m * m
    np.testing.assert_allclose(reduced, R.T.toarray() @ P @ Z.toarray(), atol=1e-12 * np.abs(P).max() * m)


@pytest.mark.skipif(factorization._pardiso() is None, reason="PARDISO does not load here")
def test_the_saddle_is_factored_as_its_own_upper_triangle(monkeypatch):
    """A = [K Bᵀ; B 0] is built as its upper triangle and PARDISO factors it as it is: while it factors, Python holds
    W's array and A's upper triangle once, with PARDISO's int32 copy of its indices (before, a second copy of A's
    upper triangle beside it: 22 MB of the pair's peak at 2.6·10⁵ DOFs); W the same to the bit."""
    from convexcontact.formulations.dual import contact_rows
    from convexcontact.studies.benchmarks.bench import two_body_scene

    model = cc.prepare(two_body_scene("tresca", 2e4), "primal")
    K, B = model.fem.K, contact_rows(model.fem.contact, model.C, model.friction)
    m, upper = B.shape[0], sp.triu(K).nnz + B.nnz + B.shape[0]
    held, call = [], pardiso._call

    def factoring(handle, phase, b, x, nrhs):
        if phase == 12:
            held.append(tracemalloc.get_traced_memory()[0])
        return call(handle, phase, b, x, nrhs)

    monkeypatch.setattr(pardiso, "_call", factoring)
    tracemalloc.start()
    try:
        W = factorization.saddle(K, B).schur(B)
    finally:
        tracemalloc.stop()
    A_bytes = 12 * upper + 4 * K.shape[0]  # float64 values, int32 indices and row pointers
    assert held[0] - 8 * m * m < 1.5 * A_bytes, (held[0] - 8 * m * m) / A_bytes  # before: 2.3 ×
    monkeypatch.setattr(pardiso, "_call", call)
    monkeypatch.setattr(factorization, "_pardiso_factors",
                        lambda A, schur, mtype, upper: pardiso.Pardiso(A, schur, mtype))
    assert np.array_equal(factorization.saddle(K, B).schur(B), W)  # A's upper triangle copied, as before


@pytest.mark.skipif(factorization._pardiso() is None, reason="PARDISO does not load here")
@pytest.mark.parametrize("size", [53, 47])
def test_pardiso_refuses_a_held_or_refactorized_term_of_another_shape(size):
    """A term larger than the matrix factorized had its rows beyond it never read (its entries there dropped
    silently); a smaller one failed on an index. Both are now a ValueError that names the shapes, from hold and from
    refactorize alike."""
    n = 50
    K = sp.diags([-np.ones(n - 1), 4.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    factors = pardiso.Pardiso(K)
    wrong = sp.eye(size, format="csr")
    for call in (factors.hold, factors.refactorize):
        with pytest.raises(ValueError, match=rf"a term of shape \({size}, {size}\).*\(50, 50\)"):
            call(wrong)
