"""The products newton-cg takes that are no CG iterations (solvers/newton_cg.py; docs/performance.md, "The pair's
products that are not CG iterations"): no curvature probe where P's diagonal is known, no product at x = 0 (∇f = q),
no fresh sum against a loose tolerance (the coarse program's)."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.conic import ConicProgram, nonnegative
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def recorded(monkeypatch):
    """The vectors newton-cg multiplies by P (its own operator) and the points of P's own formula of ∇f."""
    products, formulas = [], []
    operator, affine = newton_cg._operator, newton_cg._affine

    def recording_operator(P):
        inner = operator(P)
        return spla.LinearOperator(inner.shape, matvec=lambda x: products.append(np.array(x)) or inner.matvec(x),
                                   dtype=float)

    def recording_affine(program):
        as_sum, own = affine(program)
        return as_sum, own and (lambda x: formulas.append(np.array(x)) or own(x))

    monkeypatch.setattr(newton_cg, "_operator", recording_operator)
    monkeypatch.setattr(newton_cg, "_affine", recording_affine)
    return products, formulas


def pair_products(monkeypatch):
    """The vectors multiplied by W and the points of its own formula of ∇f in the 2-D pair's Tresca dual at 2·10⁴ DOFs,
    forced matrix-free (the coarse program's too)."""
    products, formulas = recorded(monkeypatch)
    result = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free").solve()
    assert result.solved and result.certificate.worst <= 1e-10
    return products, formulas


def test_the_pair_s_dual_takes_no_curvature_probe_where_its_diagonal_is_known(monkeypatch):
    """W's approximation estimates its diagonal: the step lengths need no probe, which took one product of each
    newton-cg call, the coarse program's too."""
    products, _ = pair_products(monkeypatch)
    probe = np.random.default_rng(0).standard_normal(products[0].size)  # the fine program's probe (scale 1)
    assert not any(x.size == probe.size and np.array_equal(x, probe) for x in products)


def test_the_pair_s_dual_takes_no_product_at_zero(monkeypatch):
    """∇f at the start x = 0 is q: it took one product, by W's own formula and, in the coarse program (no such
    formula), a product with 0."""
    products, formulas = pair_products(monkeypatch)
    assert not any(not x.any() for x in products + formulas)


def dense_program(n: int = 40, seed: int = 5) -> ConicProgram:
    """min ½ xᵀPx + qᵀx over x ≥ 0, P a random SPD matrix applied as an operator (no diagonal known)."""
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    P = Q @ np.diag(np.geomspace(1.0, 1e-2, n)) @ Q.T
    return ConicProgram(spla.aslinearoperator(0.5 * (P + P.T)), rng.standard_normal(n), -sp.eye(n, format="csc"),
                        np.zeros(n), (nonnegative(n),))


@pytest.mark.parametrize("tol, fresh", [(1e-3, False), (1e-12, True)])
def test_a_fresh_sum_at_the_answer_only_against_a_tolerance_below_the_square_root_of_eps(monkeypatch, tol, fresh):
    """A program without its own formula of ∇f (the coarse program's): at tol 1e-3 (COARSE_TOL) the stopping test
    takes the sum CG's updates left (their rounding is ~ε a product), not a fresh product at the answer, which it
    took before; at 1e-12 it does."""
    products, _ = recorded(monkeypatch)
    solution = newton_cg.solve(dense_program(), tol=tol)
    assert solution.solved and solution.iterations >= 1
    assert any(np.array_equal(x, solution.x) for x in products) == fresh
