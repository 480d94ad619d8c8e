"""A body that is its own approximation (H = K: the plates 20 : 20 : 1) factors its preconditioner H + Gᵀ D⁻¹ G on K's
own PARDISO analysis, a second numeric factorization (mnum 2), not a second ordering (docs/performance.md, "The
plates' preconditioner on K's own analysis")."""

import gc
import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.fem import factorization
from convexcontact.solvers import newton_cg
from convexcontact.solvers.cone_polish import bound_form
from convexcontact.studies.benchmarks.bench import scene_of

pardiso = pytest.importorskip("convexcontact.fem.pardiso")
if factorization._pardiso() is None:
    pytest.skip("PARDISO does not load", allow_module_level=True)


def laplacian(n: int) -> sp.csr_matrix:
    """An SPD 3-D grid Laplacian (n³ unknowns) plus the identity."""
    d = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    return sp.csr_matrix(sp.kronsum(sp.kronsum(d, d), d) + sp.eye(n**3))


def test_a_twin_solves_with_its_own_values_on_the_first_s_analysis():
    """The twin's solve agrees with SuperLU's of its matrix (K plus a diagonal block, on part of K's pattern), the first
    factors still solve K, and a refactorization of the twin changes only the twin."""
    K = laplacian(8)
    n = K.shape[0]
    rng = np.random.default_rng(0)
    A = K + sp.diags(rng.uniform(0, 5, n))
    first = pardiso.Pardiso(K)
    twin = first.twin(A)
    assert twin._handle[0] is first._handle[0] and 2 <= twin._handle[-1] <= pardiso.MAXFCT  # its analysis, mnum > 1
    b = rng.standard_normal(n)
    np.testing.assert_allclose(twin.solve(b), spla.spsolve(sp.csc_matrix(A), b), rtol=1e-10)
    np.testing.assert_allclose(first.solve(b), spla.spsolve(sp.csc_matrix(K), b), rtol=1e-10)
    twin.refactorize(K, sp.diags(np.full(n, 3.0)))
    np.testing.assert_allclose(twin.solve(b), spla.spsolve(sp.csc_matrix(K + 3 * sp.eye(n)), b), rtol=1e-10)
    np.testing.assert_allclose(first.solve(b), spla.spsolve(sp.csc_matrix(K), b), rtol=1e-10)


def test_twins_are_numbered_up_to_maxfct_and_freed_with_their_factors():
    """MAXFCT − 1 twins at once, then None (the caller factorizes anew); a twin's number is free again when it is
    collected, and after an entry outside the pattern (ValueError)."""
    K = laplacian(4)
    first = pardiso.Pardiso(K)
    twins = [first.twin(K) for _ in range(pardiso.MAXFCT - 1)]
    assert sorted(twin._handle[-1] for twin in twins) == list(range(2, pardiso.MAXFCT + 1))
    assert first.twin(K) is None
    del twins
    gc.collect()
    outside = sp.csr_matrix(([1.0], ([0], [K.shape[0] - 1])), shape=K.shape)
    with pytest.raises(ValueError):
        first.twin(K, outside + outside.T)
    assert sorted(first._free) == list(range(2, pardiso.MAXFCT + 1))


@pytest.mark.parametrize("inside", [True, False])
def test_a_twin_of_terms_solves_their_sum_on_k_s_analysis_or_with_its_own_outside_it(inside):
    """K and a block given as terms, not summed (duplicates and explicit zeros in the block): within K's pattern a
    twin on K's analysis; with an entry outside it, factors of their own (of the stored sum). Both solve K + the
    block."""
    K = laplacian(4)
    n = K.shape[0]
    direct = factorization.factorize(K)
    rng = np.random.default_rng(6)
    stored = sp.coo_matrix(K)
    pick = rng.choice(stored.nnz, 30)
    rows, columns, values = stored.row[pick], stored.col[pick], rng.uniform(0.0, 1.0, 30)
    values[0] = 0.0
    if not inside:
        rows, columns, values = np.append(rows, [0, n - 1]), np.append(columns, [n - 1, 0]), np.append(values, [1, 1])
    block = sp.coo_matrix((values, (rows, columns)), shape=K.shape)
    block = block + block.T
    twin = direct.twin(K, block)
    assert (twin._factors._handle[0] is direct._factors._handle[0]) == inside
    b = np.ones(n)
    np.testing.assert_allclose(twin.solve(b), spla.spsolve(sp.csc_matrix(K + block), b), rtol=1e-10)


def test_terms_of_another_shape_are_refused_not_taken_for_entries_outside_the_pattern():
    """A term of the wrong shape (a COO pattern whose shape was inferred from its largest index) is an error that
    names the shapes, not a silent factorization of its own."""
    K = laplacian(4)
    short = sp.coo_matrix(([0.0], ([0], [1])))
    with pytest.raises(ValueError, match="shapes"):
        factorization.factorize(K).twin(K, short)


@pytest.mark.parametrize("law", ["signorini", "tresca"])
def test_the_clamped_plate_s_preconditioner_is_placed_on_k_s_twin_without_a_k_sized_sum(law):
    """The first factorization of the plate's K + Gᵀ D⁻¹ G (with balls: at the first system, on every later face's
    pattern) places K and the contact terms on K's analysis: a twin, and numpy holds at most 1.5 × K's bytes while it
    is built (3·10⁴ DOFs: 1.20 Signorini, 1.25 Tresca measured; a K-sized stored sum held 2.66 and 1.52)."""
    model = cc.prepare(scene_of("plate-clamped-20", 3, law, 3e4), "dual-matrix-free")
    approximation = model.program.P.approximation
    sets = newton_cg._bounds(model.program, bound_form(model.program))
    shift = newton_cg.SHIFT * newton_cg._shifts(approximation, sets, lambda: 1.0)
    n, p = sets.scale.size, sets.balls.shape[1]
    built = []

    def build():
        built.append(newton_cg._Preconditioner(approximation, sets.scale, sets.balls, shift))
        if p:  # with balls the factorization is at the first Newton system's
            built[0].system(newton_cg._expansion(n, np.arange(n), sets.balls[:0], np.zeros((0, p, p - 1))), np.zeros(n))

    tracemalloc.start()
    try:
        build()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    H = approximation.H
    assert built[0].factors._factors._handle[-1] >= 2  # PARDISO's mnum: a twin
    assert peak <= 1.5 * (H.data.nbytes + H.indices.nbytes + H.indptr.nbytes)


@pytest.mark.parametrize("law", ["signorini", "tresca"])
def test_the_plate_s_preconditioner_is_k_s_twin_with_the_same_newton_steps(monkeypatch, law):
    """The plate 20 : 20 : 1 matrix-free: no PARDISO analysis in the solve (K's, at prepare, serves the preconditioner
    too), and the same Newton steps, products and answer as with a factorization of its own."""
    analyses, products = [], []
    init, matvec = pardiso.Pardiso.__init__, factorization.Delassus._matvec
    monkeypatch.setattr(pardiso.Pardiso, "__init__", lambda self, *a, **k: analyses.append(1) or init(self, *a, **k))
    monkeypatch.setattr(factorization.Delassus, "_matvec", lambda self, r: products.append(1) or matvec(self, r))

    def solved():
        model = cc.prepare(scene_of("plate-free-20", 3, law, 3e3), "dual-matrix-free")
        analyses.clear(), products.clear()
        result = newton_cg.solve(model.program)
        return result, len(analyses), len(products), model.result(result, {}, model.slip_bound).certificate.worst

    twin, twin_analyses, twin_products, twin_certificate = solved()
    monkeypatch.setattr(factorization._Direct, "twin",
                        lambda self, *terms: factorization.factorize(factorization.stored_sum(*terms), self.backend))
    own, own_analyses, own_products, own_certificate = solved()
    assert (twin_analyses, own_analyses) == (0, 1)
    assert twin.status == own.status == "solved" and twin.iterations == own.iterations and twin_products == own_products
    assert twin_certificate < 1e-10 and own_certificate < 1e-10
    np.testing.assert_allclose(twin.x, own.x, rtol=0, atol=1e-8 * np.abs(own.x).max())
