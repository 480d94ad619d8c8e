"""The dense dual's cost (issue 25, docs/performance.md "The dense dual's cost on the pair and whole faces"): a grown
face solved from its Newton step's first Cholesky factor, the Newton systems gathered from P̃'s block, one
globalization for a dense W and an operator, W from one triangular solve, S factored in its own memory, and the
program's P on W's own values."""

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp

import convexcontact as cc
from convexcontact import blas, solvers
from convexcontact.conic import dense_matrix, dense_values
from convexcontact.fem.factorization import condense
from convexcontact.formulations.dual import contact_rows
from convexcontact.solvers import newton_cg
from convexcontact.solvers.cone_polish import tangent_bases
from convexcontact.studies.benchmarks.bench import two_body_scene


def spd(rng, n: int) -> np.ndarray:
    G = rng.standard_normal((n, n))
    return G @ G.T / n + 1e-2 * np.eye(n)


def test_a_grown_face_from_the_kept_factor_is_its_own_cholesky_to_round_off():
    """H[keep, keep] x = b from H's factor and a Schur complement on the 9 variables held more: the solve of a fresh
    Cholesky of the submatrix, to round-off; and with none held more, H's own solve."""
    rng = np.random.default_rng(3)
    H = spd(rng, 80)
    keep = np.ones(80, bool)
    keep[rng.choice(80, 9, replace=False)] = False
    rhs = rng.standard_normal(keep.sum())
    fresh = la.cho_solve(la.cho_factor(H[np.ix_(keep, keep)]), rhs)
    x = newton_cg._on_face(la.cho_factor(H), keep, rhs)
    assert np.abs(x - fresh).max() < 1e-12 * np.abs(fresh).max()
    b = rng.standard_normal(80)
    assert np.abs(newton_cg._on_face(la.cho_factor(H), np.ones(80, bool), b) - np.linalg.solve(H, b)).max() < 1e-12


def test_the_kept_factor_serves_only_where_it_costs_less():
    """A face that holds a variable the factored one had free is no principal submatrix; one that holds most of them
    costs more from the factor than a Cholesky of its own (REFACTOR)."""
    factored = np.arange(100)
    assert newton_cg._cheaper_on_face(factored, np.delete(factored, [3, 50]))
    assert not newton_cg._cheaper_on_face(np.delete(factored, 3), factored[:90])
    assert not newton_cg._cheaper_on_face(factored, factored[:40])


@pytest.fixture(scope="module")
def pair():
    """The bench's two bodies at 10⁴ DOFs, Tresca, the dense dual (296 unknowns; its slip zone grows faces)."""
    return cc.prepare(two_body_scene("tresca", 1e4), "dual")


def test_the_kept_factor_leaves_the_newton_points_as_they_were(pair, monkeypatch):
    """The pair's dense Tresca dual: its grown faces solved from their step's factor (17 of 32 systems) and each
    factored afresh (REFACTOR = 0) give the same Newton steps, faces and answer to round-off, certified."""
    used = []
    on_face = newton_cg._on_face
    monkeypatch.setattr(newton_cg, "_on_face", lambda *args: used.append(1) or on_face(*args))
    kept = newton_cg.solve(pair.program)
    monkeypatch.setattr(newton_cg, "REFACTOR", 0.0)
    fresh = newton_cg.solve(pair.program)
    assert len(used) >= 10 and kept.status == fresh.status == "solved"
    assert (kept.iterations, kept.info["grown"]) == (fresh.iterations, fresh.info["grown"])
    assert np.abs(kept.x - fresh.x).max() < 1e-10 * np.abs(fresh.x).max()
    assert pair.result(kept, {}, pair.slip_bound).certificate.worst < 1e-10


def test_the_dense_dual_reads_w_without_a_copy(pair):
    """P is W's own values (a CSC matrix of every entry), and newton-cg's P̃ is a view of them (the scale is 1)."""
    P = pair.program.P
    W = pair.condensation.schur(sp.vstack([pair.C @ pair.fem.contact.N, -pair.friction.R]))
    assert np.shares_memory(P.data, W) and np.array_equal(P.toarray(), W)
    assert np.shares_memory(newton_cg._scaled(P, np.ones(P.shape[0])), W)
    scale = np.linspace(1.0, 2.0, P.shape[0])
    assert np.allclose(newton_cg._scaled(P, scale), scale[:, None] * W * scale, rtol=1e-15, atol=0)


def test_a_newton_system_is_the_block_of_p_it_touches():
    """Rᵀ P̃ Z gathered from P̃'s rows that Z touches: the free variables' block itself, and with tangent coordinates
    of discs on their spheres the product with Z, as formed densely."""
    rng = np.random.default_rng(4)
    n = 30
    P = spd(rng, n)
    free = np.array([0, 3, 4, 9, 17])
    balls = np.array([[20, 21], [25, 26]])
    bases = tangent_bases(rng.standard_normal((2, 2)))
    Z = newton_cg._expansion(n, free, balls, bases)
    assert np.array_equal(newton_cg._reduced(P, newton_cg._expansion(n, free, balls[:0], bases[:0]),
                                             newton_cg._expansion(n, free, balls[:0], bases[:0])), P[np.ix_(free, free)])
    dense = Z.toarray()
    assert np.abs(newton_cg._reduced(P, Z, Z) - dense.T @ P @ dense).max() < 1e-14 * np.abs(P).max()


def test_a_dense_w_is_held_on_its_own_memory_without_an_index_per_entry():
    """dense_matrix holds W's values where W lies (a leading block's view too, the frictionless start's) with two
    indices, and scipy reads it as W: products, the upper triangle the adapters pass, the CSC the polish takes."""
    rng = np.random.default_rng(5)
    W = spd(rng, 40)
    W = 0.5 * (W + W.T)
    x = rng.standard_normal(40)
    for values in (W, W[:25, :25]):
        P = dense_matrix(values)
        assert np.shares_memory(dense_values(P), W) and P.indices.nbytes + P.indptr.nbytes <= 12
        assert np.array_equal(P.toarray(), values) and np.allclose(P @ x[:len(values)], values @ x[:len(values)])
        assert np.array_equal(sp.triu(P, format="csc").toarray(), np.triu(values))
        assert np.array_equal(sp.csc_matrix(P).toarray(), values)
    assert dense_values(sp.csc_matrix(W)) is None and dense_matrix(np.zeros((0, 0))).shape == (0, 0)


def test_the_pair_s_coulomb_programs_hold_one_w():
    """The friction dual's P and the frictionless start's are views of one W with no index per entry: the CSC
    they were held as kept m² int32 row indices for each and a contiguous copy of the start's block (the pair at
    2.8·10⁵ DOFs: 2.09× the linear solve's peak memory, 1.74× without)."""
    model = cc.prepare(two_body_scene("coulomb", 2e4), "dual")
    start, _, _ = model.build(None, None, None, model.fem.contact)
    W, block = dense_values(model.program.P), dense_values(start.P)
    m = block.shape[0]
    assert W is not None and 0 < m < W.shape[0] and np.shares_memory(block, W)
    assert np.array_equal(block, W[:m, :m]) and model.program.P.indices.nbytes + start.P.indices.nbytes <= 8


@pytest.mark.parametrize("backend", ["superlu", "pardiso"])
def test_the_condensation_factors_s_in_its_own_memory(backend):
    """condense holds one |C|² array at a time (S, factored where it lies) where S, its transposed copy for the
    symmetrization and its factor were three; S asked for again is S (UᵀU, symmetric) and W = XᵀX is B K⁻¹ Bᵀ."""
    n, C = 1200, np.arange(300, 700)
    K = sp.diags([np.full(n - 1, -1.0), np.full(n, 2.05), np.full(n - 1, -1.0)], [-1, 0, 1], format="csr")
    tracemalloc.start()
    try:
        condensed = condense(K, C, backend=backend)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1.8 * C.size**2 * 8
    dense = K.toarray()
    interior = np.setdiff1d(np.arange(n), C)
    S = dense[np.ix_(C, C)] - dense[np.ix_(C, interior)] @ np.linalg.solve(dense[np.ix_(interior, interior)],
                                                                            dense[np.ix_(interior, C)])
    assert np.abs(condensed.S - S).max() < 1e-10 * np.abs(S).max() and np.array_equal(condensed.S, condensed.S.T)
    B = sp.random(50, C.size, density=0.05, random_state=7, format="csr")
    B = sp.hstack([sp.csr_matrix((50, 300)), B, sp.csr_matrix((50, n - 700))]).tocsr()
    W = condensed.schur(B)
    exact = B @ np.linalg.solve(dense, B.T.toarray())
    assert np.array_equal(W, W.T) and np.abs(W - exact).max() < 1e-10 * np.abs(exact).max()


def test_a_dense_w_takes_the_segment_before_the_arc():
    """One globalization for a dense W and an operator: the least f on the segment to Newton's point, then the arc.
    The pair's dense Tresca dual at 3·10⁴ DOFs (422 unknowns) took 9 Newton steps and 33 grown faces with Π(Newton's
    point) first (the dense order before), 5 and 12 after; at 10⁵ DOFs 17 and 74 against 8 and 25. Since a step's
    faces are the natural map's at Newton's point (newton_cg.GROW, released sets too), 3 and 20."""
    model = cc.prepare(two_body_scene("tresca", 3e4), "dual")
    solution = newton_cg.solve(model.program)
    assert solution.status == "solved" and solution.iterations <= 4 and solution.info["grown"] <= 20
    assert model.result(solution, {}, model.slip_bound).certificate.worst < 1e-10


def test_a_zero_column_stored_by_dense_matrix_is_still_costless():
    """dense_matrix keeps W's exact zeros (a contact node with no free DOF: its row and column of W), and the polish
    must still read that variable as costless (a failed grazing Coulomb polish, pressure 6e-9 where 0, when it
    counted stored entries)."""
    from convexcontact.solvers.polish import free_variables

    W = np.array([[2.0, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 3.0]])
    A = sp.csr_matrix(-np.eye(3))
    by_values = free_variables(sp.csc_matrix(W), np.zeros(3), A, np.zeros(3, bool))
    assert by_values.tolist() == [False, True, False]
    assert free_variables(dense_matrix(W), np.zeros(3), A, np.zeros(3, bool)).tolist() == by_values.tolist()


def test_the_dense_newton_systems_run_on_one_blas_thread(pair, monkeypatch):
    """Each dense Newton system is gathered and factored with BLAS on DENSE_THREADS thread(s), the process's own
    setting restored after it: the pair's systems (a few hundred unknowns) paid a second thread's start at every call
    (docs/performance.md, "The dense Newton systems on one BLAS thread")."""
    threads = lambda: {pool["num_threads"] for pool in blas.pools().info() if pool["user_api"] == "blas"}
    outside, inside = threads(), []
    direct = newton_cg._direct
    monkeypatch.setattr(newton_cg, "_direct", lambda *args: inside.append(threads()) or direct(*args))
    solution = newton_cg.solve(pair.program)
    assert solution.status == "solved" and inside and all(count == {newton_cg.DENSE_THREADS} for count in inside)
    assert threads() == outside


def test_the_recovery_takes_the_stopping_test_s_solve_where_its_load_is_the_same(monkeypatch):
    """newton-cg stops on a fresh gradient, whose solve K⁻¹(f − Bᵀr) is the recovery's displacement: the pair's
    Signorini dual recovers it with no solve, the same to the last bit; another point, or the same one once its
    displacement has left with the fields, is solved again."""
    model = cc.prepare(two_body_scene("signorini", 1e4), "dual")
    solution = solvers.solve(model.program, "newton-cg")
    assert solution.solved
    reused, solves = model.condensation, []
    solve = reused.solve
    monkeypatch.setattr(reused, "solve", lambda b: solves.append(1) or solve(b))
    fields = model.recover(solution)
    assert not solves
    B = contact_rows(model.fem.contact, model.C, None)
    assert np.array_equal(fields.u, solve(model.fem.f - B.T @ fields.pressure))
    assert np.array_equal(model.recover(solution).u, fields.u) and len(solves) == 1
    half = model.recover(replace(solution, x=0.5 * solution.x))
    assert len(solves) == 2 and not np.allclose(half.u, fields.u)
