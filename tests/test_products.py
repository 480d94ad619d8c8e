"""The products newton-cg takes that are no CG iterations (solvers/newton_cg.py; docs/performance.md, "The pair's
products that are not CG iterations"): no curvature probe where P's diagonal is known, no product at x = 0 (∇f = q)."""

import numpy as np
import scipy.sparse.linalg as spla

import convexcontact as cc
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
