"""W from K's factorization with the dual's rows appended (fem/factorization.py, `Saddle`; docs/performance.md, "W
from K's factors with B's rows appended"): the same W and the same solves with K as the condensation onto the contact
DOFs, a singular K refused as before, and the dense dual on it solved and certified as on the condensation."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact import solvers
from convexcontact.drivers import rules
from convexcontact.drivers.rules import contact_columns
from convexcontact.fem import factorization
from convexcontact.fem.factorization import Condensation, Saddle, condense, dual_factors, factorize, saddle
from convexcontact.formulations.dual import contact_rows
from convexcontact.scene.description import SceneError
from convexcontact.scene.library import pressure_patch
from convexcontact.studies.benchmarks.bench import punch_scene, two_body_scene

pytestmark = pytest.mark.skipif(factorization._pardiso() is None, reason="Saddle needs PARDISO")


def rows_of(model):
    return contact_rows(model.fem.contact, model.C, model.friction)


def assert_close(a, b, tol):
    assert np.abs(a - b).max() <= tol * np.abs(b).max()


@pytest.mark.parametrize("scene, more_rows", [(lambda: two_body_scene("tresca", 1e4), False),
                                              (lambda: punch_scene(3, "tresca", 3000), True)])
def test_w_and_the_solves_are_the_condensations(scene, more_rows):
    """The pair (mortar rows on both bodies) and a 3-D punch whose friction rows outnumber the DOFs they touch (W
    singular: PARDISO perturbs the Schur block's own pivots, which serve nothing): W equals B_C S⁻¹ B_Cᵀ of the
    condensation, K⁻¹ b equals the plain factorization's, for one and several right-hand sides."""
    model = cc.prepare(scene(), "primal")
    K, B, C = model.fem.K, rows_of(model), contact_columns(model.fem)
    assert (B.shape[0] > C.size) == more_rows
    W = saddle(K, B).schur(B)
    assert np.array_equal(W, W.T)
    assert_close(W, condense(K, C, dim=model.fem.dim).schur(B), 1e-11)
    b = np.random.default_rng(0).standard_normal((K.shape[0], 3))
    s, plain = saddle(K, B), factorize(K, dim=model.fem.dim)
    assert_close(s.solve(b[:, 0]), plain.solve(b[:, 0]), 1e-11)
    assert_close(s.solve(b), plain.solve(b), 1e-11)


def test_other_rows_are_factored_again():
    """schur of rows other than those factored: W of the new rows (a second factorization), not the kept one."""
    model = cc.prepare(two_body_scene("tresca", 1e4), "primal")
    K, B = model.fem.K, rows_of(model)
    s = saddle(K, B)
    other = B[::2]
    W = s.schur(other)
    assert s.B.shape == other.shape
    assert_close(W, factorize(K).schur(other), 1e-11)


def test_a_singular_stiffness_is_refused_and_auto_falls_back_to_the_primal(monkeypatch):
    """A body held only by the contact and a roller: saddle refuses K by name (field "dirichlet") although the
    saddle-point matrix with the contact rows is regular, and `auto` falls back to the primal as with the
    condensation."""
    scene = dataclasses.replace(pressure_patch(nx=8), dirichlet=(cc.Dirichlet("left", ux=0.0),))
    model = cc.prepare(scene, "primal")
    with pytest.raises(SceneError) as error:
        saddle(model.fem.K, rows_of(model))
    assert error.value.field == "dirichlet"
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)
    model = cc.prepare(scene)
    assert model.formulation == "primal" and "singular" in model.reason


@pytest.fixture(scope="module")
def both():
    """The bench's pair at 10⁴ DOFs, Tresca, the dense dual on the condensation and on the saddle."""
    scene = two_body_scene("tresca", 1e4)
    on_condensation = cc.prepare(scene, "dual")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(factorization, "SADDLE_COLUMNS", 0)
        on_saddle = cc.prepare(scene, "dual")
    return on_condensation, on_saddle


def test_the_dense_dual_on_the_saddle_is_the_same_answer(both):
    """Both solved by `auto`'s solver, certified, the same displacement to 10⁻⁹; the saddle's result keeps no
    condensation (its derivatives condense K themselves) and differentiates to the condensation's numbers."""
    on_condensation, on_saddle = both
    assert isinstance(on_saddle.condensation.factorization, Saddle)
    assert not isinstance(on_condensation.condensation.factorization, Saddle)
    first, second = on_condensation.solve(), on_saddle.solve()
    assert first.status == second.status == "solved" and second.certificate.worst < 1e-10
    assert_close(second.displacement, first.displacement, 1e-9)
    assert second.condensation is None and first.condensation is not None
    name = "materials[upper].E"
    a, b = cc.sensitivity(first, [name])[name].derivative, cc.sensitivity(second, [name])[name].derivative
    assert_close(b.pressure, a.pressure, 1e-8)


def test_the_frictionless_seed_reads_the_leading_block(both):
    """The frictionless program that seeds the friction solve has the first rows of B: its W is the leading block of
    the kept W (prepared.Reused), with no second factorization."""
    _, on_saddle = both
    reused = on_saddle.condensation
    factors = reused.factorization._factors
    frictionless = on_saddle.C @ on_saddle.fem.contact.N
    W = reused.schur(frictionless)
    assert reused.factorization._factors is factors
    assert_close(W, factorize(on_saddle.fem.K).schur(frictionless), 1e-11)


def test_the_saddle_serves_where_w_is_smaller_than_s(monkeypatch):
    """dual_factors: the saddle where B has fewer rows than the DOFs it touches (from SADDLE_COLUMNS on), the
    condensation where as many (W as large as S: nothing gained) or fewer DOFs."""
    n = 300
    K = sp.diags([np.full(n - 1, -1.0), np.full(n, 2.05), np.full(n - 1, -1.0)], [-1, 0, 1], format="csr")
    C = np.arange(100, 140)
    fewer, as_many = (sp.csr_matrix((np.ones(k), (np.arange(k), C[:k])), shape=(k, n)) for k in (20, 40))
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 40)
    assert isinstance(dual_factors(K, C, fewer), Saddle)
    assert isinstance(dual_factors(K, C, as_many), Condensation)
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 41)
    assert isinstance(dual_factors(K, C, fewer), Condensation)


def test_auto_limits_the_saddles_rows_not_its_columns(monkeypatch):
    """Where W comes from the saddle, MATRIX_FREE_COLUMNS bounds the dual's rows, not the DOFs they touch: a pair over
    that many columns keeps its dense W while its rows fit, and goes matrix-free, saying why, once they do not."""
    scene = cc.bodies_library.punch_on_foundation(0.05)
    columns = rules.contact_columns(cc.prepare(scene, "primal").fem).size
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", columns - 1)
    model = cc.prepare(scene)
    rows = model.program.P.shape[0]
    assert rows < columns - 1 and isinstance(model.condensation.factorization, Saddle)
    assert not solvers.matrix_free(model.program)
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", rows - 1)
    model = cc.prepare(scene)
    assert solvers.matrix_free(model.program) and f"{rows} contact unknowns exceed {rows - 1}" in model.reason


def test_a_large_3d_pair_keeps_its_dense_w_from_the_saddle(monkeypatch):
    """DENSE_DOFS_3D sends a large 3-D body matrix-free because condensing it onto the contact DOFs costs more than a
    factorization; where the saddle forms W (fewer rows than the DOFs they touch: a pair's slave rows on both bodies'
    DOFs) there is no such condensation, and the pair keeps its dense W, certified. One body (its rows on its own
    nodes' DOFs) keeps the rule where its contact DOFs are over MATRIX_FREE_COLUMNS, and the pair without the saddle
    goes matrix-free by them, saying why (docs/performance.md, "The 3-D pair of spheres through the saddle's W")."""
    scene = two_body_scene("tresca", 2e3, dim=3)
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)
    monkeypatch.setattr(rules, "DENSE_DOFS_3D", 10)
    model = cc.prepare(scene)
    assert model.fem.dim == 3 and model.program.P.shape[0] < contact_columns(model.fem).size
    assert model.formulation == "dual" and isinstance(model.condensation.factorization, Saddle)
    result = model.solve()
    assert result.status == "solved" and result.certificate.worst < 1e-10
    one_body = punch_scene(3, "signorini", 3000)  # its rows on its own nodes' DOFs: the rule holds
    columns = contact_columns(cc.prepare(one_body).fem).size
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", columns - 1)  # over it: the contact DOFs, not the rows
    one_body = cc.prepare(one_body)
    assert one_body.program.P.shape[0] < columns and solvers.matrix_free(one_body.program)
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 10**9)
    monkeypatch.setattr(rules, "MATRIX_FREE_COLUMNS", contact_columns(model.fem).size - 1)
    model = cc.prepare(scene)
    assert solvers.matrix_free(model.program) and "DOFs to condense onto exceed" in model.reason



def test_a_large_w_frees_the_saddles_factors_for_ks_own(monkeypatch):
    """Where W is large beside K (SADDLE_FREED) the saddle's factors (A = [K Bᵀ; B 0], PARDISO's m × m Schur block
    among them: a second W) are freed once W is formed and K's own serve the solves: the factors held are a plain
    factorization's, W the same array, the solves K's to round-off (the pair at 2.6·10⁵ DOFs: the peak 2.23× → 1.92×
    the linear solve's with Tresca, 2.43× → 2.07× with Coulomb). The pair at 10⁴ DOFs (W 0.01 of its linear solve's
    memory) keeps A's factors, which hold more than K's."""
    model = cc.prepare(two_body_scene("tresca", 1e4), "primal")
    K, B = model.fem.K, rows_of(model)
    plain, kept = factorize(K), saddle(K, B)
    assert kept.fill > plain.fill + B.shape[0] ** 2 // 2
    monkeypatch.setattr(factorization, "SADDLE_FREED", 0.0)
    freed = saddle(K, B)
    assert freed.fill == plain.fill
    assert np.array_equal(freed.schur(B), kept.schur(B))
    b = np.random.default_rng(1).standard_normal((K.shape[0], 2))
    assert_close(freed.solve(b), plain.solve(b), 1e-13)
    assert_close(freed.solve(b), kept.solve(b), 1e-10)
