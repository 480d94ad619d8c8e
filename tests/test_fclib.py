"""FClib (Siconos' frictional-contact problem library): the format, the mapping of our dual onto its local
problem, fclib's merit function, and solving imported problems (docs/fclib.md)."""

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.scene.library import frictional_punch, punch_3d
from convexcontact.scene.toml import load_scene

h5py = pytest.importorskip("h5py")

from convexcontact.cli import main as cli_main
from convexcontact.interop import fclib, fclib_scene
from convexcontact.interop.fclib_cli import main
from convexcontact.interop.fclib_solve import condense, merit, natural_residuals, solve_global, solve_local

DATA = Path(__file__).parent / "data" / "fclib"
SHIPPED = DATA / "local_problem_test.hdf5"
LMGC_GLOBAL = DATA / "LMGC_GlobalFrictionContactProblem00046.hdf5"  # Siconos' test data (NOTICE.md)
LMGC_LOCAL = DATA / "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5"


def punch_2d():
    return frictional_punch(h=0.02, depth=0.02, element="Q1", law=cc.Coulomb(friction=0.6, tol=1e-12))


def punch_3d_small():
    return punch_3d(cells=4, law=cc.Coulomb(friction=0.3, tol=1e-12))


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Each scene exported as a local and a global problem, and read back."""
    folder, files = tmp_path_factory.mktemp("fclib"), {}
    for name, scene in (("2d", punch_2d()), ("3d", punch_3d_small())):
        for kind in ("local", "global"):
            path = folder / f"{name}_{kind}.hdf5"
            problem, solution, result = fclib_scene.export(scene, path, kind)
            files[name, kind] = (path, problem, solution, result, fclib.read(path))
    return files


def one_contact(mu=0.3):
    """W = I, q = (−1, ½, 0): the contact closes and slides, r = (1, −μ, 0), u = (0, ½ − μ, 0)."""
    return fclib.LocalProblem(sp.identity(3, format="csr"), np.array([-1.0, 0.5, 0.0]), np.array([mu]), 3)


def test_merit_is_zero_at_a_closed_form_answer_and_uses_fclibs_normalization():
    problem = one_contact()
    assert merit(problem, np.array([1.0, -0.3, 0.0])) == pytest.approx(0.0, abs=1e-15)
    # r = 0: ‖Π_C(−û)‖ with û = q + (μ‖q_T‖, 0, 0), over 1 + √‖q‖ (fclib: sqrt(error)/(1 + sqrt(dnrm2(q))))
    projection = np.hypot(1.0, 0.3) / 1.09
    assert merit(problem, np.zeros(3)) == pytest.approx(projection / (1 + 1.25**0.25), rel=1e-12)
    answer = solve_local(problem)
    np.testing.assert_allclose(answer.r, [1.0, -0.3, 0.0], atol=1e-9)
    np.testing.assert_allclose(answer.u, [0.0, 0.2, 0.0], atol=1e-9)


def test_merit_of_a_perturbed_answer_is_about_the_perturbation(exported):
    _, problem, solution, _, _ = exported["2d", "local"]
    """The merit is a natural-map residual: Lipschitz in r (constant ~ 1 + ‖W‖), and not smaller than a
    fraction of the error (unlike a product of complementary quantities, which squares it)."""
    normalization = 1 + np.sqrt(np.linalg.norm(problem.q))
    lipschitz = 3 * (1 + np.linalg.norm(problem.W.toarray(), 2))
    for size in (1e-3, 1e-6):
        delta = size * np.random.default_rng(1).standard_normal(solution.r.size)
        value = merit(problem, solution.r + delta) * normalization
        assert 0.1 * np.linalg.norm(delta) < value < lipschitz * np.linalg.norm(delta)


@pytest.mark.parametrize("name", ["2d", "3d"])
def test_our_certified_answer_satisfies_fclibs_law(exported, name):
    """The exported /solution: fclib's merit ~1e-13, u = W r + q, and u_N ≥ 0 ⊥ r_N ≥ 0 in FClib's signs."""
    _, problem, _, result, (read_back, stored, guesses) = exported[name, "local"]
    assert result.status == "solved" and guesses == []
    d = problem.spacedim
    assert d == (2 if name == "2d" else 3) and problem.W.shape == (d * problem.mu.size,) * 2
    assert merit(read_back, stored.r) < 1e-10
    assert max(natural_residuals(read_back, stored.r).values()) < 1e-10
    u, r = stored.u.reshape(-1, d), stored.r.reshape(-1, d)
    scale = np.abs(u).max()
    assert u[:, 0].min() > -1e-10 * scale and np.abs(u[:, 0] * r[:, 0]).max() < 1e-10 * scale * r[:, 0].max()


def test_the_file_holds_what_was_written(exported):
    path, problem, solution, _, (read_back, stored, _) = exported["3d", "local"]
    with h5py.File(path) as file:
        assert int(file["fclib_local/spacedim"][0]) == 3 and int(file["fclib_local/W/nz"][0]) == -1
        assert file["fclib_local/W/p"].dtype == np.int32 and "Scaled units" in file["fclib_local/info/description"][
            ()].decode()
    assert abs(read_back.W - problem.W).max() == 0 and np.array_equal(read_back.q, problem.q)
    assert np.array_equal(read_back.mu, problem.mu) and np.array_equal(stored.r, solution.r)


def test_a_written_file_is_whole_and_readable_by_others(tmp_path):
    """Written beside its name and moved in (nothing left behind), with the permissions of any new file (umask),
    not a temporary file's 0600."""
    umask = os.umask(0o022)
    os.umask(umask)
    path = fclib.write(tmp_path / "p.hdf5", one_contact())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.hdf5"]
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


def test_the_mapping_of_unknowns_and_signs():
    """Π puts contact k's (λ_N, λ_T) at [N, T]; q = our linear cost = −h; u_T is the slip, r_T opposes it."""
    model = cc.prepare(punch_2d(), "dual")
    problem, order = fclib_scene.local_problem(model)
    m = model.fem.contact.m
    np.testing.assert_array_equal(order[:4], [0, m, 1, m + 1])
    result = model.solve()
    r = fclib_scene.multipliers(model, result)[order]
    u = (problem.W @ r + problem.q).reshape(-1, 2)
    sliding = np.char.startswith(result.contact.status.astype(str), "slip")
    assert sliding.sum() >= 4
    assert np.all(np.sign(u[sliding, 1]) == np.sign(result.contact.slip[sliding]))
    assert np.all(np.sign(r.reshape(-1, 2)[sliding, 1]) == -np.sign(result.contact.slip[sliding]))


@pytest.mark.parametrize("name", ["2d", "3d"])
def test_round_trip_gives_our_answer(exported, name):
    _, _, _, _, (problem, stored, _) = exported[name, "local"]
    answer = solve_local(problem)
    assert answer.status == "solved" and answer.merit < 1e-10
    np.testing.assert_allclose(answer.r, stored.r, atol=1e-8 * np.abs(stored.r).max())
    np.testing.assert_allclose(answer.u, stored.u, atol=1e-8 * np.abs(stored.u).max())


def test_weak_non_penetration_exports_the_same_law(tmp_path):
    """Hild's continuous P1 multipliers (C = M): W and h change, the law at the nodes does not."""
    law = cc.Coulomb(friction=0.6, tol=1e-12, non_penetration="weak")
    *_, result = fclib_scene.export(frictional_punch(h=0.02, depth=0.02, element="Q1", law=law), tmp_path / "weak.hdf5")
    problem, stored, _ = fclib.read(tmp_path / "weak.hdf5")
    assert result.status == "solved" and merit(problem, stored.r) < 1e-10
    answer = solve_local(problem)
    np.testing.assert_allclose(answer.r, stored.r, atol=1e-8 * np.abs(stored.r).max())


@pytest.mark.parametrize("pull", [None, 0.1])
def test_a_prescribed_obstacle_force_is_fclibs_mixed_problem(tmp_path, pull):
    """Hertz under force control: a_ᵀ r = P is Vᵀ r + R λ + s = 0 (R = 0, s = −P), λ = −(obstacle advance);
    a tangential force Q = 0.1 P pulling the obstacle adds a second column (and an all-stick start)."""
    scene = cc.library.hertz_punch(nx=40, law=cc.Coulomb(friction=0.3, tol=1e-12))
    force = cc.library.HERTZ_FORCE
    obstacle = cc.Obstacle("parabolic", radius=1.0, force=force, tangential_force=pull and pull * force)
    scene = dataclasses.replace(scene, contact=dataclasses.replace(scene.contact, obstacle=obstacle))
    *_, result = fclib_scene.export(scene, tmp_path / "hertz.hdf5")
    problem, stored, _ = fclib.read(tmp_path / "hertz.hdf5")
    motion = [result.obstacle_advance] + ([result.obstacle_shift] if pull else [])
    assert problem.V.shape == (problem.q.size, len(motion)) and problem.R.count_nonzero() == 0
    assert stored.l == pytest.approx(-np.array(motion) / result.fem.scaling.displacement)
    assert merit(problem, stored.r, stored.l) < 1e-10
    answer = solve_local(problem)
    assert answer.status == "solved" and answer.merit < 1e-10
    np.testing.assert_allclose(answer.r, stored.r, atol=1e-8 * np.abs(stored.r).max())
    np.testing.assert_allclose(answer.l, stored.l, rtol=1e-8)


@pytest.mark.parametrize("name", ["2d", "3d"])
def test_global_problem_condenses_to_the_local_one(exported, name):
    _, local, _, _, _ = exported[name, "local"]
    _, _, _, _, (problem, stored, _) = exported[name, "global"]
    assert problem.M.shape[0] > problem.H.shape[1] and problem.G is None
    condensed, _ = condense(problem)
    np.testing.assert_allclose(condensed.W.toarray(), local.W.toarray(), atol=1e-10 * abs(local.W).max())
    np.testing.assert_allclose(condensed.q, local.q, atol=1e-10 * np.abs(local.q).max())
    answer = solve_global(problem)
    assert answer.status == "solved" and answer.merit < 1e-10 and answer.residuals["equilibrium"] < 1e-10
    np.testing.assert_allclose(answer.r, stored.r, atol=1e-8 * np.abs(stored.r).max())
    np.testing.assert_allclose(answer.v, stored.v, atol=1e-8 * np.abs(stored.v).max())


def test_fclibs_own_test_problem():
    """src/tests/data/local_problem_test.hdf5 of fclib: 48 contacts of stacked boxes, W of rank 72."""
    problem, stored, guesses = fclib.read(SHIPPED)
    assert problem.spacedim == 3 and problem.mu.size == 48 and np.all(problem.mu == 0.7)
    assert problem.info["title"] == "Boxes Stack" and len(guesses) == 1
    assert abs(problem.W - problem.W.T).max() < 1e-9 * abs(problem.W).max()
    # its /solution is r = 0 (u is not W r + q): fclib's own merit rejects it
    assert np.all(stored.r == 0) and merit(problem, stored.r) > 1e-3
    answer = solve_local(problem)
    assert answer.status == "solved" and answer.merit < 1e-10
    assert max(natural_residuals(problem, answer.r).values()) < 1e-8


def test_siconos_global_lmgc_file_is_read_as_written():
    """LMGC_GlobalFrictionContactProblem00046 (Siconos' test data, written by LMGC90 through Siconos): H is 162 × 27
    in triplets, its p below n = 27 and its i up to 107 — only "i rows, p columns" fits; M is stored as its upper
    triangle. Read so, the problem is solved to fclib merit 1e-14 with equilibrium 1e-13; judged on the literal
    triangle instead, the same answer's equilibrium residual is of order one."""
    with h5py.File(LMGC_GLOBAL) as file:
        H = file["fclib_global/H"]
        assert int(H["nz"][0]) == 405 and H["p"][()].max() < int(H["n"][0]) == 27 <= H["i"][()].max()
        M = file["fclib_global/M"]
        rows, columns = M["i"][()], M["p"][()]
        assert np.all(rows <= columns) and np.sum(rows < columns) > 2800  # the upper triangle only
        triangle = sp.csr_matrix((M["x"][()], (rows, columns)), shape=(162, 162))
    problem, stored, guesses = fclib.read(LMGC_GLOBAL)
    assert problem.H.shape == (162, 27) and problem.mu.size == 9 and np.all(problem.mu == 0.3) and stored is None and guesses == []
    assert abs(problem.M - problem.M.T).max() == 0 and problem.warnings[0].startswith("fclib_global/M: stored as its")
    answer = solve_global(problem)
    assert answer.status == "solved" and answer.merit < 1e-12 and answer.residuals["equilibrium"] < 1e-10
    literal = triangle @ answer.v - problem.H @ answer.r - problem.f
    assert np.abs(literal).max() > 0.1 * np.abs(triangle @ answer.v).max()
    from convexcontact.fem.factorization import _pardiso, factorize

    if _pardiso() is not None:  # the backends agree on M as read (on the literal triangle they differed by 28 %)
        superlu, pardiso = (factorize(problem.M, backend).solve(problem.f) for backend in ("superlu", "pardiso"))
        assert np.linalg.norm(superlu - pardiso) < 1e-12 * np.linalg.norm(superlu)


def test_siconos_local_lmgc_file_is_read_as_written():
    """LMGC_100_PR_PerioBox (Siconos' test data): 60 contacts of rigid particles, W 180 × 180 in compressed rows,
    symmetric and positive semi-definite of rank 72 (6 per particle), μ ∈ {0.3, 0.5}."""
    problem, stored, guesses = fclib.read(LMGC_LOCAL)
    assert problem.W.shape == (180, 180) and problem.mu.size == 60 and set(problem.mu) == {0.3, 0.5}
    assert stored is None and guesses == [] and problem.warnings == []
    W = problem.W.toarray()
    assert np.abs(W - W.T).max() < 1e-15 * np.abs(W).max()
    eigenvalues = np.linalg.eigvalsh(W)
    assert eigenvalues[0] > -1e-12 * eigenvalues[-1] and np.sum(eigenvalues > 1e-10 * eigenvalues[-1]) == 72


def test_refused_problems_say_why(tmp_path):
    with pytest.raises(cc.SceneError, match="contact.law"):
        fclib_scene.export(cc.library.tresca_punch(nx=8), tmp_path / "t.hdf5")
    history = load_scene(Path(__file__).parents[1] / "examples" / "scenes" / "sliding_block.toml")
    with pytest.raises(cc.SceneError, match="history"):
        fclib_scene.export(history, tmp_path / "h.hdf5")
    gauss = cc.Coulomb(friction=0.3, quadrature="gauss")
    with pytest.raises(cc.SceneError, match="contact.quadrature"):
        fclib_scene.local_problem(cc.prepare(punch_3d(cells=2, law=gauss), "dual"))
    mixed = one_contact()
    mixed.V, mixed.R, mixed.s = sp.csr_matrix(np.ones((3, 1))), sp.csr_matrix(np.ones((1, 1))), np.zeros(1)
    with pytest.raises(ValueError, match="fclib_local/R"):
        solve_local(mixed)
    with pytest.raises(ValueError, match="needs their multipliers"):
        merit(mixed, np.zeros(3))
    force = cc.library.hertz_punch(nx=8, law=cc.Coulomb(friction=0.3))
    with pytest.raises(cc.SceneError, match="obstacle.force"):
        fclib_scene.global_problem(cc.prepare(force, "dual"))
    with pytest.raises(ValueError, match="contacts"):
        fclib.LocalProblem(sp.identity(4, format="csr"), np.zeros(4), np.ones(1), 3)


def siconos_matrix(group, A, storage="triplet"):
    """An FClib matrix group as Siconos writes one: its CSparse matrix's fields one to one (fclib_interface.c:
    ``W->p = spmat->p``, ``W->i = spmat->i``), so a triplet holds the row indices in i and the columns in p;
    integers as int32 arrays of one entry (fclib.c, write_matrix)."""
    coo, csc, csr = sp.coo_matrix(A), sp.csc_matrix(A), sp.csr_matrix(A)
    nz, p, i, x = {"triplet": (coo.nnz, coo.col, coo.row, coo.data), "csc": (-1, csc.indptr, csc.indices, csc.data),
                   "csr": (-2, csr.indptr, csr.indices, csr.data)}[storage]
    for key, value in {"nzmax": len(x), "m": A.shape[0], "n": A.shape[1], "nz": nz}.items():
        group.create_dataset(key, data=np.array([value], dtype=np.int32))
    group.create_dataset("p", data=np.asarray(p, dtype=np.int32))
    group.create_dataset("i", data=np.asarray(i, dtype=np.int32))
    group.create_dataset("x", data=np.asarray(x, dtype=np.float64))


@pytest.mark.parametrize("storage", ["triplet", "csc", "csr"])
def test_matrices_are_read_as_siconos_writes_them(tmp_path, storage):
    """A non-square and a non-symmetric matrix in each storage: read as the matrix written, not its transpose."""
    H = sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 0.0]]))  # 3 × 2: a transposed triplet is 2 × 3
    A = sp.random(5, 4, density=0.5, random_state=2, format="csr")
    skew = sp.csr_matrix(np.array([[1.0, 0.2, 0.0], [-0.2, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with h5py.File(tmp_path / "m.hdf5", "w") as file:
        for name, matrix in (("H", H), ("A", A), ("skew", skew)):
            siconos_matrix(file.create_group(name), matrix, storage)
        for name, matrix in (("H", H), ("A", A), ("skew", skew)):
            assert (fclib.read_matrix(file[name]) != matrix).nnz == 0


def test_a_non_symmetric_triplet_w_keeps_its_exact_answer(tmp_path):
    """W = [[1, .2, 0], [−.2, 1, 0], [0, 0, 1]], q = (−1, 0, 0), μ = .3: r = (1, .2, 0)/1.04 gives u = W r + q = 0 with
    r inside the cone (|r_T| = .2/1.04 < μ r_N): sticking, a solution. Read transposed, the same r would slide:
    u = (−.04, .4, 0)/1.04, and fclib's merit says so."""
    W = np.array([[1.0, 0.2, 0.0], [-0.2, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with h5py.File(tmp_path / "skew.hdf5", "w") as file:
        group = file.create_group("fclib_local")
        group.create_dataset("spacedim", data=np.array([3], dtype=np.int32))
        siconos_matrix(group.create_group("W"), sp.csr_matrix(W))
        group.create_dataset("vectors/q", data=np.array([-1.0, 0.0, 0.0]))
        group.create_dataset("vectors/mu", data=np.array([0.3]))
    problem, _, _ = fclib.read(tmp_path / "skew.hdf5")
    np.testing.assert_array_equal(problem.W.toarray(), W)
    r = np.array([1.0, 0.2, 0.0]) / 1.04
    assert merit(problem, r) < 1e-15
    transposed = dataclasses.replace(problem, W=sp.csr_matrix(W.T))
    assert merit(transposed, r) > 0.1


def test_a_global_problem_with_a_non_square_triplet_h(tmp_path):
    """M = 2 I (4 DOFs), H 4 × 2 (one 2-D contact) in triplets: read as written, condensed to W = Hᵀ M⁻¹ H."""
    H = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.5], [0.0, 0.0]])
    with h5py.File(tmp_path / "g.hdf5", "w") as file:
        group = file.create_group("fclib_global")
        group.create_dataset("spacedim", data=np.array([2], dtype=np.int32))
        siconos_matrix(group.create_group("M"), 2 * sp.identity(4))
        siconos_matrix(group.create_group("H"), sp.csr_matrix(H))
        for name, value in {"f": np.zeros(4), "w": np.array([-1.0, 0.0]), "mu": np.array([0.5])}.items():
            group.create_dataset(f"vectors/{name}", data=value)
    problem, _, _ = fclib.read(tmp_path / "g.hdf5")
    np.testing.assert_array_equal(problem.H.toarray(), H)
    local, _ = condense(problem)
    np.testing.assert_allclose(local.W.toarray(), H.T @ H / 2, atol=1e-15)


def upper_triangle_file(path, full):
    """A global problem whose M is stored as its upper triangle only, as LMGC90's dumps are (i ≤ p)."""
    with h5py.File(path, "w") as file:
        group = file.create_group("fclib_global")
        group.create_dataset("spacedim", data=np.array([3], dtype=np.int32))
        siconos_matrix(group.create_group("M"), sp.triu(sp.csr_matrix(full)))
        siconos_matrix(group.create_group("H"), sp.csr_matrix(np.eye(3)))
        for name, value in {"f": full @ np.ones(3), "w": np.zeros(3), "mu": np.array([0.3])}.items():
            group.create_dataset(f"vectors/{name}", data=value)


@pytest.mark.parametrize("backend", ["superlu", "pardiso"])
def test_a_matrix_stored_as_one_triangle_is_read_as_the_symmetric_one(tmp_path, backend):
    """M = [[4, 1, 0], [1, 3, 1], [0, 1, 2]] stored as its upper triangle, f = M (1, 1, 1) = (5, 5, 3): read as the
    full M (warned), so M⁻¹ f = (1, 1, 1) with either backend. The literal triangle would give (23/24, 7/6, 3/2) with SuperLU, (1, 1, 1) with
    PARDISO (which reads one triangle): answers that depended on the backend."""
    from convexcontact.fem.factorization import _pardiso, factorize

    if backend == "pardiso" and _pardiso() is None:
        pytest.skip("PARDISO (pypardiso) is not available")
    full = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]])
    upper_triangle_file(tmp_path / "triangle.hdf5", full)
    problem, _, _ = fclib.read(tmp_path / "triangle.hdf5")
    np.testing.assert_array_equal(problem.M.toarray(), full)
    assert len(problem.warnings) == 1 and problem.warnings[0].startswith("fclib_global/M: stored as its upper triangle")
    np.testing.assert_allclose(factorize(problem.M, backend).solve(problem.f), np.ones(3), rtol=1e-14)
    np.testing.assert_allclose(np.linalg.solve(np.triu(full), problem.f), [23 / 24, 7 / 6, 1.5], rtol=1e-14)


def test_command_line(tmp_path, capsys):
    assert cli_main(["fclib", "solve", str(SHIPPED), "--json", str(tmp_path / "s.json"), "--out", str(tmp_path / "s.hdf5")]) == 0
    report = capsys.readouterr().out
    assert "Boxes Stack" in report and "stored /solution" in report
    _, ours, _ = fclib.read(tmp_path / "s.hdf5")
    assert merit(fclib.read(SHIPPED)[0], ours.r) < 1e-10
    scene = Path(__file__).parents[1] / "examples" / "scenes" / "frictional_punch.toml"
    out = tmp_path / "punch.hdf5"
    assert main(["export", str(scene), "--out", str(out)]) == 0
    assert "fclib merit" in capsys.readouterr().out
    assert main(["export", str(scene), "--out", str(out)]) == 2  # exists: --overwrite to replace
    assert "--overwrite" in capsys.readouterr().err


def test_an_answer_above_the_certificate_exits_3_as_every_command(exported, capsys):
    """Stopped at merit 0.5 (the frictionless first iterate, merit ~3e-4): an answer above the certificate's 1e-8,
    reported inaccurate, exit 3 (cli.EXIT)."""
    path = exported["2d", "local"][0]
    assert main(["solve", str(path), "--merit-tol", "0.5"]) == 3
    assert "inaccurate" in capsys.readouterr().out
