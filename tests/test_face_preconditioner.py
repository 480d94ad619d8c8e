"""The Newton systems' preconditioner (solvers/newton_cg.py, _Preconditioner): a face's exact inverse from the factors
of an earlier face updated by low rank (UPDATE_RANK), exact up to rounding, so the Newton path is the one of a
refactorization at every face; and with bounds alone, the faces' exact inverse once the restriction's CG costs more
than a refactorization (_Preconditioner.spent)."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.fem import factorization
from convexcontact.fem.factorization import factorize
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def test_the_update_solves_the_updated_matrix():
    """M + Uᵀ diag(w) U with terms joining (w > 0) and leaving (w < 0, M holding them) against a fresh solve."""
    rng = np.random.default_rng(0)
    n, k = 300, 7
    A = sp.random(n, n, density=0.02, random_state=rng)
    U = sp.random(k, n, density=0.05, random_state=rng, format="csr")
    leaving = np.arange(k) >= 4
    weights = np.where(leaving, -1.0, 2.0) * rng.uniform(1.0, 3.0, k)
    # M holds the leaving terms: M − their sum stays SPD
    M = sp.csc_matrix(A @ A.T + sp.eye(n) + U.T @ sp.diags(np.where(leaving, -weights, 0.0)) @ U)
    factors = factorize(M)
    updated = newton_cg._Updated(factors, U, factors.solve(U.T.toarray()), weights)
    b = rng.standard_normal(n)
    exact = spla.spsolve(sp.csc_matrix(M + U.T @ sp.diags(weights) @ U), b)
    assert np.abs(updated.solve(b) - exact).max() <= 1e-11 * np.abs(exact).max()


def test_a_face_s_terms_are_keyed_by_each_column_s_rows_values_and_d():
    """Each column of R (0 to 3 entries, unsorted rows) keyed by its sorted rows', values' and d's bytes, to its
    index, in the columns' order: the same terms between two faces are the same keys."""
    rng = np.random.default_rng(1)
    counts = rng.integers(0, 4, 40)
    rows = np.concatenate([rng.choice(30, count, replace=False) for count in counts])
    R = sp.csc_matrix((rng.standard_normal(rows.size), rows, np.concatenate([[0], np.cumsum(counts)])), shape=(30, 40))
    d = rng.uniform(1.0, 2.0, 40)
    S = R.sorted_indices()
    column = [S.indices[a:b].tobytes() + S.data[a:b].tobytes() + d[j].tobytes()
              for j, (a, b) in enumerate(zip(S.indptr[:-1], S.indptr[1:]))]
    assert not R.has_sorted_indices and list(newton_cg._terms(R.tocsr(), d).items()) == [
        (key, j) for j, key in enumerate(column)]


@pytest.fixture(scope="module")
def pair():
    return cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free")


def solved(pair, monkeypatch, update):
    if not update:  # a refactorization at every face, as before the updates
        monkeypatch.setattr(newton_cg._Preconditioner, "_updated", lambda self, R, d, terms: None)
    solves = []
    solve = newton_cg.newton_cg
    monkeypatch.setattr(newton_cg, "newton_cg", lambda *a, **k: solves.append(solve(*a, **k)) or solves[-1])
    result = pair.solve()
    return result, solves[-1].info  # the top-level solve: the coarse start's program (COARSE_SETS) is solved inside it


def test_the_pair_s_path_is_the_refactorized_one(pair, monkeypatch):
    """The 2-D pair's Tresca dual at 2·10⁴ DOFs, forced matrix-free: updated where faces differ by few terms, the same
    Newton steps, products and CG iterations as with a refactorization at every face, the same answer to rounding,
    fewer factorizations."""
    fresh, every = solved(pair, monkeypatch, False)
    monkeypatch.undo()
    result, info = solved(pair, monkeypatch, True)
    assert every["updates"] == 0 and info["updates"] > 0
    assert info["factorizations"] + info["updates"] == every["factorizations"]
    for name in ("steps", "products", "cg_iterations"):
        assert info[name] == every[name], name
    assert result.certificate.worst <= 1e-10
    scale = np.abs(fresh.contact.forces).max()
    assert np.abs(result.contact.forces - fresh.contact.forces).max() <= 1e-9 * scale


def signorini(shape, dim, size, restricted, monkeypatch):
    """Newton's info on the Signorini dual of a bench shape forced matrix-free; ``restricted``: the restriction
    throughout, as before the switch."""
    if restricted:
        monkeypatch.setattr(newton_cg._Preconditioner, "spent", lambda self, iterations: None)
    solves, costs = [], []
    solve, spent = newton_cg.newton_cg, newton_cg._Preconditioner.spent
    monkeypatch.setattr(newton_cg, "newton_cg", lambda *a, **k: solves.append(solve(*a, **k)) or solves[-1])
    monkeypatch.setattr(newton_cg._Preconditioner, "spent",
                        lambda self, iterations: costs.append(self._cost) or spent(self, iterations))
    result = cc.prepare(scene_of(shape, dim, "signorini", size), "dual-matrix-free").solve()
    monkeypatch.undo()
    [solution] = solves
    assert result.certificate.worst <= 1e-10
    return solution.info, costs[0] if costs else None


@pytest.mark.skipif(factorization._pardiso() is None, reason="the costs come from PARDISO's flops")
def test_signorini_faces_exact_where_the_restriction_costs_more(monkeypatch):
    """The 2-D pair (2·10⁴ DOFs): a refactorization costs ~8 products, the restriction's first system more CG
    iterations than that, so the session switches: fewer products (and Newton steps no more). The 3-D pair (10⁴
    DOFs): a refactorization costs ~19 products (20.5 before the symmetry planes' 20 rows were emptied: the
    approximation's factor is smaller without them), more than any of its 3 systems' CG (29 iterations in all), so
    nothing changes."""
    before, _ = signorini("two-body", 2, 2e4, True, monkeypatch)
    after, cost = signorini("two-body", 2, 2e4, False, monkeypatch)
    assert 1 < cost < 20 and after["products"] < before["products"]
    assert sum(after["steps"].values()) <= sum(before["steps"].values())
    before, _ = signorini("two-body", 3, 1e4, True, monkeypatch)
    after, cost = signorini("two-body", 3, 1e4, False, monkeypatch)
    assert cost > 15 and after["products"] == before["products"] and after["factorizations"] == 0
