"""A Newton step's later faces are the natural map's at Newton's point (solvers/newton_cg.py, GROW): sets held at
the wrong end are flipped, those whose multipliers point inward released, a set released once in a step not again;
the gradient there comes from CG's own products. On the 2-D pair's Tresca dual (nearly every node slipping) the
faces that only grew left intervals at the wrong end and Newton's point refused (docs/performance.md, "Tresca's
plateau on the pair")."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import convexcontact as cc
from convexcontact.conic import ConicProgram, nonnegative, soc
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import scene_of


def grown_only(monkeypatch):
    """The faces before: only grown by the sets Newton's point leaves (newton_cg._grown)."""
    monkeypatch.setattr(newton_cg, "_released", lambda y, newton, g, c, sets, released, then, now: (
        newton_cg._grown(y, newton, sets, then), False))


@pytest.mark.parametrize("grown", [False, True])
def test_the_pair_s_tresca_dual_applied_matrix_free_takes_newton_s_point_at_every_step(monkeypatch, grown):
    """2·10⁴ DOFs, forced matrix-free: with faces that only grew, 7 Newton steps, one of them the segment towards a
    refused Newton point (its residual 4.3e-2 → 1.7e-2, not halved), 99 products; now 5 steps, Newton's point taken
    at each (3 without the released-once rule). From no start: the coarse start (newton_cg.COARSE_SETS) shortens
    this path (tests/test_coarse_start.py), and the faces here are the first step's."""
    monkeypatch.setattr(newton_cg, "COARSE_SETS", 10**9)  # no coarse start: the sets too few for it
    if grown:
        grown_only(monkeypatch)
    solves = []
    solve = newton_cg.newton_cg
    monkeypatch.setattr(newton_cg, "newton_cg", lambda *a, **k: solves.append(solve(*a, **k)) or solves[-1])
    model = cc.prepare(scene_of("two-body", 2, "tresca", 2e4), "dual-matrix-free")
    result = model.solve()
    assert result.formulation == model.formulation and result.certificate.worst <= 1e-10
    [solution] = solves
    assert solution.info["steps"] == ({"residual": 6, "segment": 1, "arc": 0, "gradient": 0, "face": 0} if grown else
                                      {"residual": 5, "segment": 0, "arc": 0, "gradient": 0, "face": 0})


def sets(n_bounds: int, n_intervals: int, slip: float) -> newton_cg._Bounds:
    """v_j ≥ 0 on the first variables, |v_k| ≤ ``slip`` on the rest (intervals: balls of one variable)."""
    n = n_bounds + n_intervals
    return newton_cg._Bounds(np.ones(n), np.zeros(n), np.arange(n_bounds),
                             np.arange(n_bounds, n).reshape(-1, 1), np.full(n_intervals, slip))


def test_the_face_at_newton_s_point_flips_and_releases_and_releases_once():
    """Bounds 0, 1, 2 and intervals 3, 4 (|v| ≤ 1), c = 1. y holds bound 0 (multiplier ∇f₀ = −1 at the point: it
    points inward), bound 1 (∇f₁ = 2: held), interval 3 at +1 (∇f₃ = 3 > 2: pushed past −1) and interval 4 at −1
    (∇f₄ = −0.5: released); bound 2 is free, Newton's point leaves it (−0.2)."""
    at = sets(3, 2, 1.0)
    y = np.array([-1.0, -1.0, 0.5, 2.0, -3.0])
    newton = np.array([0.0, 0.0, -0.2, 1.0, -1.0])
    g = np.array([-1.0, 2.0, 0.0, 3.0, -0.5])
    released = np.zeros(5, bool)
    face, any_released = newton_cg._released(y, newton, g, 1.0, at, released, at.radius, at.radius)
    assert any_released and released.tolist() == [True, False, False, False, True]
    assert face[0] >= 0 and face[1] < 0 and face[2] < 0  # bound 0 released, 1 held, 2 held (the point left it)
    assert face[3] < -1 and -1 <= face[4] <= 1  # interval 3 flipped to −1, 4 released
    # the face stays: Newton's point on it, the same multipliers' signs
    assert newton_cg._released(face, np.array([0.1, 0.0, 0.0, -1.0, 0.3]), np.array([0, 2, 1, 3, 0]), 1.0, at,
                               released, at.radius, at.radius) == (None, False)
    # a set released once in the step is held as the last face held it, where its multiplier says release again
    again = y.copy()
    again[0] = -1.0
    face, any_released = newton_cg._released(again, newton, g, 1.0, at, released, at.radius, at.radius)
    assert not any_released and face[0] == -1.0 and face[4] == -3.0 and face[3] < -1


def test_the_gradient_at_newton_s_point_from_cg_s_products_is_a_fresh_one():
    """A Newton step by CG on an operator P (8 bounds, 6 intervals, a random SPD P): ∇f at its point, accumulated from
    the products CG took, against P x + q at that point."""
    rng = np.random.default_rng(3)
    n = 14
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    P = Q @ np.diag(np.geomspace(1.0, 1e-2, n)) @ Q.T
    P = 0.5 * (P + P.T)
    q = rng.standard_normal(n)
    rows = [-sp.eye(8, n)] + [sp.vstack([sp.csr_matrix((1, n)), -sp.eye(1, n, 8 + k)]) for k in range(6)]
    program = ConicProgram(spla.aslinearoperator(P), q, sp.vstack(rows).tocsc(),
                           np.concatenate([np.zeros(8)] + [[0.3, 0.0]] * 6), (nonnegative(8),) + (soc(2),) * 6)
    at = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    c = np.full(n, 0.1)
    v = newton_cg._project(rng.standard_normal(n), at)
    affine = lambda x: P @ x + q
    y = v - c * (at.scale * affine(at.shift + at.scale * v))
    point, iterations, gradient = newton_cg._step(spla.aslinearoperator(P), affine, at, v, y, c, 1e-14, [0], None)
    assert iterations > 2
    fresh = at.scale * affine(at.shift + at.scale * point)
    assert np.abs(gradient - fresh).max() <= 1e-10 * np.abs(fresh).max()


def test_the_pair_s_coulomb_newton_takes_the_natural_map_s_faces_at_every_point(monkeypatch):
    """Newton's Coulomb solve (radii that move, GMRES) on the 2-D pair at 2·10⁴ DOFs, forced matrix-free: with the
    natural map's faces only where Newton's point was refused, at most GROW_MOVING = 3 of them (before), its residual
    fell 7.4e-3 → 7.0e-3 → 3.7e-3 → 2.7e-3 → 8.8e-4 in 6 steps and 118 products; with them at every Newton point
    (RELEASE_MOVING) the first step reaches 2.8e-6, 3 steps and 69 products (docs/performance.md, "Newton's Coulomb
    plateau on the pair")."""
    solves = []
    coupled = newton_cg.coupled
    monkeypatch.setattr(newton_cg, "coupled", lambda *a, **k: solves.append(coupled(*a, **k)) or solves[-1])
    result = cc.prepare(scene_of("two-body", 2, "coulomb", 2e4), "dual-matrix-free").solve()
    assert result.certificate.worst <= 1e-10
    [solution] = solves
    assert solution.solved and solution.iterations == 3 and solution.info["residuals"][1] < 1e-5
    assert solution.info["products"] < 80
