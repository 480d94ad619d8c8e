"""newton-cg's preconditioner keeps its factors where they bound the Newton system (REUSE), and the coarse grids are
coarsened by the slope of the grids tried (issue 25: the thin bodies' fixed costs)."""

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.fem import coarse
from convexcontact.scene.description import Tresca
from convexcontact.scene.library import whole_face
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import law_of
from convexcontact.studies.benchmarks.shapes import shape_scene


@pytest.fixture(scope="module")
def face():
    """A 3-D Tresca whole face (discs: two tangential rows a node), its sets and its approximation's dense G̃ H⁻¹ G̃ᵀ."""
    program = cc.prepare(whole_face(3, 25, 6e2, Tresca(slip_bound=0.002)), "dual-matrix-free").program
    sets = newton_cg._bounds(program, newton_cg.bound_form_of(program))
    approximation = program.P.approximation
    G = (sp.diags(sets.scale) @ approximation.G).toarray()
    return program, sets, G @ np.linalg.solve(approximation.H.toarray(), G.T)


def preconditioner(face, shift=1e-3):
    program, sets, _ = face
    return newton_cg._Preconditioner(program.P.approximation, sets.scale, sets.balls, shift)


def system_of(face, R: sp.csr_matrix, d: np.ndarray) -> np.ndarray:
    """D + Rᵀ P̃_approx R, dense."""
    return R.T @ (face[2] @ R.toarray()) + np.diag(d)


def inverse_of(apply, size: int) -> np.ndarray:
    return np.column_stack([apply(e) for e in np.eye(size)])


def generalized_eigenvalues(apply, A: np.ndarray) -> np.ndarray:
    """The eigenvalues of M A, M the preconditioner ``apply`` (symmetric positive definite: checked)."""
    M = inverse_of(apply, A.shape[0])
    np.testing.assert_allclose(M, M.T, atol=1e-9 * np.abs(M).max())
    L = np.linalg.cholesky(0.5 * (M + M.T))
    return np.linalg.eigvalsh(L.T @ A @ L)


def a_face(sets, n: int, rng, spheres: np.ndarray, held: np.ndarray):
    """R of a face whose ``spheres`` (balls) are on their sphere with random tangent bases, ``held`` variables held."""
    held = held.copy()
    held[sets.balls[spheres].ravel()] = True
    bases = newton_cg.tangent_bases(rng.standard_normal((spheres.size, sets.balls.shape[1])))
    return newton_cg._expansion(n, np.flatnonzero(~held), sets.balls[spheres], bases), held


def test_the_same_face_keeps_its_factors_and_its_condition_stays_within_the_spread_of_d(face):
    """A system differing from the one factored only in D (spread ≤ REUSE), one tangent basis reversed: no
    factorization, and the kept inverse's eigenvalues against it within [min d/d₀, max d/d₀] (closed form: the two
    systems differ by a diagonal). A spread above REUSE refactorizes: then the exact inverse."""
    program, sets, _ = face
    rng = np.random.default_rng(4)
    n = program.n_variables
    spheres = np.flatnonzero(rng.random(sets.balls.shape[0]) < 0.5)
    R, held = a_face(sets, n, rng, spheres, rng.random(n) < 0.2)
    free = (~held).sum()
    curvature = np.concatenate([np.zeros(free), rng.uniform(0, 1, R.shape[1] - free)])
    kept = preconditioner(face)
    kept.system(R, curvature)
    assert kept.factorizations == 1
    reversed_basis = R.toarray()
    reversed_basis[:, free] *= -1  # the first sphere's basis, as tangent_bases may return it
    R2 = sp.csr_matrix(reversed_basis)
    d = (1e-3 + curvature) * rng.uniform(0.6, 0.6 * newton_cg.REUSE, curvature.size)
    ratio = d / (1e-3 + curvature)
    eigenvalues = generalized_eigenvalues(kept.system(R2, d - 1e-3), system_of(face, R2, d))
    assert kept.factorizations == 1
    assert ratio.min() * (1 - 1e-8) <= eigenvalues.min() and eigenvalues.max() <= ratio.max() * (1 + 1e-8)
    spread = (1e-3 + curvature) * np.where(np.arange(curvature.size) % 2, 1.0, 2 * newton_cg.REUSE)
    apply = kept.system(R2, spread - 1e-3)
    assert kept.factorizations == 2
    np.testing.assert_allclose(generalized_eigenvalues(apply, system_of(face, R2, spread)), 1.0, atol=1e-8)


def test_a_face_that_differs_by_a_few_columns_keeps_its_factors_updated_by_them(face):
    """A system on the factored face but for a few variables held or released and a ball off its sphere (the other
    spheres and their bases as they were, one reversed), D within a spread ≤ REUSE on the columns both hold: no
    refactorization but an update (the free plate 20 : 20 : 1 at 2.6·10⁵ DOFs, Tresca, refactorized such a face:
    5.4 s), the exact inverse of the factored system with the columns it holds and the changed ones as they are now,
    so against this one its eigenvalues are within [min d/d₀, max d/d₀] over the columns both hold and 1 (closed
    form: the two differ by a diagonal). Beyond REUSE's spread, a refactorization."""
    program, sets, _ = face
    rng = np.random.default_rng(6)
    n = program.n_variables
    spheres = np.flatnonzero(rng.random(sets.balls.shape[0]) < 0.5)
    bases = newton_cg.tangent_bases(rng.standard_normal((spheres.size, sets.balls.shape[1])))
    held = rng.random(n) < 0.2
    held[sets.balls[spheres].ravel()] = True
    free = sets.bounds[~held[sets.bounds]]
    changed = np.concatenate([rng.choice(free, 2, replace=False), rng.choice(sets.bounds[held[sets.bounds]], 1)])
    now = held.copy()
    now[changed] = ~now[changed]  # two held more, one released
    now[sets.balls[spheres[-1]]] = False  # a ball off its sphere: its tangent column leaves, its variables join
    changed = np.concatenate([changed, sets.balls[spheres[-1]]])
    R0 = newton_cg._expansion(n, np.flatnonzero(~held), sets.balls[spheres], bases)
    reversed_bases = bases[:-1].copy()
    reversed_bases[0] *= -1  # as tangent_bases may return it
    R = newton_cg._expansion(n, np.flatnonzero(~now), sets.balls[spheres[:-1]], reversed_bases)
    tangents = rng.uniform(0, 1, spheres.size)
    kept = preconditioner(face)
    kept.system(R0, np.concatenate([np.zeros(R0.shape[1] - spheres.size), tangents]))
    d0 = np.concatenate([np.full(R.shape[1] - spheres.size + 1, 1e-3), 1e-3 + tangents[:-1]])
    d = d0 * rng.uniform(0.6, 0.6 * newton_cg.REUSE, d0.size)
    eigenvalues = generalized_eigenvalues(kept.system(R, d - 1e-3), system_of(face, R, d))
    assert kept.factorizations == 1 and kept.updates == 1
    released = np.isin(np.arange(R.shape[1]), np.flatnonzero(np.isin(np.flatnonzero(~now), changed)))
    ratio = np.where(released, 1.0, d / d0)  # the released variable's term is as it is now
    assert ratio.min() * (1 - 1e-8) <= eigenvalues.min() and eigenvalues.max() <= ratio.max() * (1 + 1e-8)
    kept.system(R, d0 * np.where(np.arange(d0.size) % 2, 1.0, 2 * newton_cg.REUSE) - 1e-3)
    assert kept.factorizations == 2


def test_a_grown_face_keeps_its_step_s_factors_which_bound_it_from_below(face):
    """A grown face (bounds held more, balls put on their sphere; the rest as it was) from the factors of the face it
    grew from: SPD, its eigenvalues against the grown face's system ≥ 1, and at most as many above 1 as variables
    were held more (rank of the terms removed): the closed form of REUSE's second case."""
    program, sets, _ = face
    rng = np.random.default_rng(5)
    n = program.n_variables
    kept = preconditioner(face)
    first_held = np.zeros(n, dtype=bool)
    first_held[sets.bounds[rng.random(sets.bounds.size) < 0.2]] = True
    R0, _ = a_face(sets, n, rng, np.array([], dtype=int), first_held)
    kept.system(R0, np.zeros(R0.shape[1]))
    more = np.flatnonzero(rng.random(sets.balls.shape[0]) < 0.3)
    held = first_held.copy()
    held[sets.bounds[rng.random(sets.bounds.size) < 0.1]] = True
    R, held = a_face(sets, n, rng, more, held)
    free = (~held).sum()
    curvature = np.concatenate([np.zeros(free), rng.uniform(0, 1, R.shape[1] - free)])
    eigenvalues = generalized_eigenvalues(kept.system(R, curvature, grown=True), system_of(face, R, 1e-3 + curvature))
    assert kept.factorizations == 1 and kept.kept
    assert eigenvalues.min() >= 1 - 1e-8
    assert (eigenvalues > 1 + 1e-8).sum() <= (held & ~first_held).sum()


def test_the_plate_takes_the_same_newton_steps_with_two_factorizations(monkeypatch):
    """The plate 20 : 20 : 1 (its own approximation: each factorization K-sized), Tresca: the kept factors leave the
    Newton steps as they were (a factorization every system, REUSE = 0 and no grown face kept) for 2 factorizations
    against 6 here (9 at 7.9·10⁴ DOFs), and the answer certified."""
    model = cc.prepare(shape_scene("plate-free-20", law_of("tresca"), 3e3, dim=3), "dual-matrix-free")
    kept = newton_cg.solve(model.program)
    monkeypatch.setattr(newton_cg, "REUSE", 0.0)
    monkeypatch.setattr(newton_cg._Preconditioner, "_grows", property(lambda self: False, lambda self, value: None),
                        raising=False)
    every = newton_cg.solve(model.program)
    assert kept.status == every.status == "solved" and kept.iterations == every.iterations
    assert kept.info["factorizations"] == 2 and every.info["factorizations"] == kept.iterations + every.info["grown"]
    assert model.result(kept, {}, model.slip_bound).certificate.worst < 1e-10


@pytest.mark.parametrize("exponent, dim", [(1.0, 2), (1.0, 3), (2.0, 2), (3.0, 3), (1.5, 3)])
def test_coarser_grids_reach_the_dense_limit_in_a_few_tries(exponent, dim):
    """Functions going as spacing^−e (a strip's grids: e ≈ 1 in 2-D or 3-D; a block's: e = dim): at most 3 tries
    from 4 × DENSE_COLUMNS, the last within [FILL, 1] × DENSE_COLUMNS (where e = dim, the first: the former rule)."""
    def functions(spacing):
        return 4 * coarse.DENSE_COLUMNS * spacing**-exponent

    tried = [(1.0, functions(1.0))]
    while tried[-1][1] > coarse.DENSE_COLUMNS:
        spacing = coarse.coarser(tried, dim)
        tried.append((spacing, functions(spacing)))
    assert len(tried) <= 4 and coarse.FILL * coarse.DENSE_COLUMNS * (1 - 1e-9) <= tried[-1][1] <= coarse.DENSE_COLUMNS


def test_the_first_step_keeps_the_empty_face_s_factors_on_released_faces_too(monkeypatch):
    """From no start, the first Newton step's face is the empty one (every set free): its factors' terms, each
    variable's 1/δ, bound every face's, released sets included (REUSE). On the free plate 20 : 20 : 1 (5,043 Tresca
    unknowns) the first step's faces grow, then release a set: every system after the first keeps its factors, where a
    released face refactorized before (4 factorizations in all, now 3), and the answer is certified."""
    model = cc.prepare(shape_scene("plate-free-20", law_of("tresca"), 6e3, dim=3), "dual-matrix-free")
    systems, steps = [], []
    system = newton_cg._Preconditioner.system

    def recorded(self, R, curvature, grown=False):
        apply = system(self, R, curvature, grown)
        systems.append((len(steps), grown, self.kept, self.factorizations))
        return apply

    monkeypatch.setattr(newton_cg._Preconditioner, "system", recorded)
    solution = newton_cg.Session(model.program, progress=lambda step, residual: steps.append(step)).solve()
    first = [entry for entry in systems if entry[0] == 1]  # the systems of the step from the empty face
    assert len(first) >= 3 and first[0][3] == 1
    assert all(grown and kept and factorizations == 1 for _, grown, kept, factorizations in first[1:])
    assert solution.status == "solved" and solution.info["factorizations"] == 3
    assert model.result(solution, {}, model.slip_bound).certificate.worst < 1e-10


def test_the_first_step_s_later_grown_faces_stop_where_its_first_kept_one_did(monkeypatch):
    """Each grown face of a step starts from the last one's point, a few columns off, so its own first residual is
    already KEPT_FORCING smaller: its CG stops at KEPT_FORCING × the first kept face's residual, not its own
    (``grown_point``'s ``level``). The free plate 20 : 20 : 1 (5,043 Tresca unknowns): the first step's kept faces
    took 6 / 16 / 14 CG iterations and the solve 67 products, now 6 / 9 / 5 / 0 and 52, with the same 5 Newton steps,
    3 factorizations and a certified answer."""
    model = cc.prepare(shape_scene("plate-free-20", law_of("tresca"), 6e3, dim=3), "dual-matrix-free")
    iterations, steps = [], []
    step = newton_cg._step

    def recorded(*args, **options):
        out = step(*args, **options)
        iterations.append((len(steps), options.get("grown", False), out[1]))
        return out

    monkeypatch.setattr(newton_cg, "_step", recorded)
    solution = newton_cg.Session(model.program, progress=lambda step, residual: steps.append(step)).solve()
    kept = [count for at, grown, count in iterations if at == 1 and grown]
    assert len(kept) >= 3 and sum(kept) <= 25
    assert solution.status == "solved" and solution.iterations == 5 and solution.info["factorizations"] == 3
    assert solution.info["products"] <= 55
    assert model.result(solution, {}, model.slip_bound).certificate.worst < 1e-10
