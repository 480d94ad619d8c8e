"""Bad FClib files and bad ``fclib solve``/``fclib export`` options: each refused where it enters, naming the dataset
or the option (exit code 2 on the command line), never a traceback, a crash or a silent acceptance."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

h5py = pytest.importorskip("h5py")

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from convexcontact import cli
from convexcontact.interop import fclib
from convexcontact.interop.fclib_cli import EXIT, main

SURFACES = ("convexcontact fclib solve", "convexcontact fclib export", "reader fclib")

EXAMPLES = Path(__file__).parents[1] / "examples" / "scenes"
SHIPPED = Path(__file__).parent / "data" / "fclib" / "local_problem_test.hdf5"


def local_problem():
    """Two 3-D contacts, W SPD, with a solution and a guess."""
    W = np.diag([2.0, 1, 1, 2, 1, 1])
    W[0, 3] = W[3, 0] = 0.1  # 8 entries: p = [0, 2, 3, 4, 6, 7, 8], i = [0, 3, 1, 2, 0, 3, 4, 5] in compressed columns
    W = sp.csr_matrix(W)
    return fclib.LocalProblem(W, np.array([-1.0, 0.2, 0, 1, 0, 0]), np.array([0.3, 0.5]), 3, {"title": "two"})


def global_problem():
    """One 2-D contact on 3 DOFs: M SPD, H 3 × 2."""
    M = sp.csr_matrix(np.array([[2.0, -1, 0], [-1, 2, -1], [0, -1, 2]]))
    H = sp.csr_matrix(np.array([[1.0, 0], [0, 1], [0, 0]]))
    return fclib.GlobalProblem(M, H, np.array([0.0, 0, -1]), np.array([-0.1, 0]), np.array([0.4]), 2)


@pytest.fixture
def local_file(tmp_path):
    answer = fclib.Solution(r=np.zeros(6), u=np.zeros(6))
    return fclib.write(tmp_path / "local.hdf5", local_problem(), answer, (answer,))


@pytest.fixture
def global_file(tmp_path):
    return fclib.write(tmp_path / "global.hdf5", global_problem(), fclib.Solution(np.zeros(2), np.zeros(2), np.zeros(3)))


def replace(path, name, value):
    """Dataset (or group) ``name`` of ``path`` replaced by ``value`` (None: removed; "group": an empty group)."""
    with h5py.File(path, "a") as file:
        if name in file:
            del file[name]
        if isinstance(value, str) and value == "group":
            file.create_group(name)
        elif value is not None:
            file.create_dataset(name, data=value)
    return path


def refused(path, start):
    with pytest.raises(ValueError) as error:
        fclib.read(path)
    assert str(error.value).startswith(start), str(error.value)
    return str(error.value)


LOCAL_CASES = [
    ("fclib_local/vectors/q", None, "fclib_local/vectors/q: missing; an FClib local problem needs W, q and mu"),
    ("fclib_local/vectors/mu", None, "fclib_local/vectors/mu: missing"),
    ("fclib_local/W", None, "fclib_local/W: missing"),
    ("fclib_local/vectors", None, "fclib_local/vectors: missing"),
    ("fclib_local/spacedim", np.array([], dtype=np.int32), "fclib_local/spacedim: expected one integer, got 0"),
    ("fclib_local/spacedim", np.array([4], dtype=np.int32), "fclib_local/spacedim: must be 2 or 3"),
    ("fclib_local/spacedim", np.array([3.0]), "fclib_local/spacedim: expected one integer"),
    ("fclib_local/vectors/q", np.bytes_(b"one two"), "fclib_local/vectors/q: expected numbers"),
    ("fclib_local/vectors/q", np.array([np.nan, 0, 0, 0, 0, 0]), "fclib_local/vectors/q: entry 0 is nan"),
    ("fclib_local/vectors/q", np.array([0, 0, np.inf, 0, 0, 0]), "fclib_local/vectors/q: entry 2 is inf"),
    ("fclib_local/vectors/q", np.zeros(5), "fclib_local/W/m, n: 6 × 6, but the problem's vectors make it 5 × 5"),
    ("fclib_local/vectors/mu", np.array([0.3, np.nan]), "fclib_local/vectors/mu: entry 1 is nan"),
    ("fclib_local/vectors/mu", np.array([0.3, -1.0]), "fclib_local/vectors/mu: friction coefficients must be"),
    ("fclib_local/vectors/mu", np.array([0.3]), "fclib_local/W: 6 contact unknowns are not 1 contacts"),
    ("fclib_local/W/x", np.array([np.nan] * 8), "fclib_local/W/x: entry 0 is nan"),
    ("fclib_local/W/x", np.ones(3), "fclib_local/W/p: ends at 8, but i and x hold 3 entries"),
    ("fclib_local/W/i", np.array([0, 3, 1, 2, 0, 99, 4, 5], dtype=np.int32), "fclib_local/W/i: entry 5 is 99"),
    ("fclib_local/W/i", np.array([0, -3, 1, 2, 0, 3, 4, 5], dtype=np.int32), "fclib_local/W/i: entry 1 is -3"),
    ("fclib_local/W/p", np.array([0, 2, 1, 4, 6, 7, 8], dtype=np.int32), "fclib_local/W/p: not nondecreasing"),
    ("fclib_local/W/p", np.array([0, 2, 3, 4], dtype=np.int32), "fclib_local/W/p: 4 pointers"),
    ("fclib_local/W/p", np.array([0.0, 2, 3, 4, 6, 7, 8]), "fclib_local/W/p: expected integer"),
    ("fclib_local/W/nz", np.array([-3], dtype=np.int32), "fclib_local/W/nz: -3 is no FClib storage"),
    ("fclib_local/W/nz", np.array([20], dtype=np.int32), "fclib_local/W/i: 8 entries, the matrix needs 20"),
    ("fclib_local/W/nz", np.array([7], dtype=np.int32), "fclib_local/W/p: entry 4 is 6, outside the 6 columns"),
    ("fclib_local/W/m", np.array([-6], dtype=np.int32), "fclib_local/W/m: -6 rows or columns"),
    ("fclib_local/W/m", np.bytes_(b"6"), "fclib_local/W/m: expected one integer"),
    ("fclib_local/W/n", None, "fclib_local/W/n: missing; an FClib matrix is a group of m, n, nz, p, i and x"),
    ("fclib_local/W/x", -np.ones(8), "fclib_local/W: diagonal entry 0 is -1 < 0"),
    ("fclib_local/W", np.ones(3), "fclib_local/W: expected a group, found a dataset"),
    ("fclib_local/vectors/q", "group", "fclib_local/vectors/q: expected a dataset, found a group"),
    ("fclib_local/info/title", np.bytes_(b"two"), None),  # a harmless change: read
    ("solution/r", np.zeros(5), "solution/r: 5 entries, the problem needs 6"),
    ("solution/u", np.array([np.nan] * 6), "solution/u: entry 0 is nan"),
    ("guesses/number_of_guesses", np.array([3], dtype=np.int32), "guesses/2: missing; number_of_guesses is 3"),
    ("guesses/number_of_guesses", np.array([-1], dtype=np.int32), "guesses/number_of_guesses: -1 < 0"),
    ("guesses/1", np.zeros(2), "guesses/1: expected a group, found a dataset"),
]


@pytest.mark.parametrize("name, value, start", LOCAL_CASES)
def test_a_bad_local_file_is_refused_naming_the_dataset(local_file, name, value, start):
    replace(local_file, name, value)
    if start is None:
        assert fclib.read(local_file)[0].info["title"] == "two"
    else:
        refused(local_file, start)


GLOBAL_CASES = [
    ("fclib_global/vectors/f", None, "fclib_global/vectors/f: missing; an FClib global problem needs M, H, f, w and mu"),
    ("fclib_global/vectors/w", None, "fclib_global/vectors/w: missing"),
    ("fclib_global/H", None, "fclib_global/H: missing"),
    ("fclib_global/M", None, "fclib_global/M: missing"),
    ("fclib_global/vectors/f", np.array([0.0, np.inf, 0]), "fclib_global/vectors/f: entry 1 is inf"),
    ("fclib_global/M/x", np.zeros(7), "fclib_global/M: diagonal entry 0 is 0; M is positive definite"),
    ("fclib_global/vectors/w", np.zeros(4), "fclib_global/H/m, n: 3 × 2, but the problem's vectors make it 3 × 4"),
    ("fclib_global/vectors/b", np.zeros(1), "fclib_global/G: missing; the equalities Gᵀ v + b = 0 need both"),
    ("solution/v", np.zeros(4), "solution/v: 4 entries, the problem needs 3"),
]


@pytest.mark.parametrize("name, value, start", GLOBAL_CASES)
def test_a_bad_global_file_is_refused_naming_the_dataset(global_file, name, value, start):
    refused(replace(global_file, name, value), start)


@pytest.mark.parametrize("field, start", [("q", "fclib_local/vectors/q: not finite"),
                                           ("W", "fclib_local/W/x: not finite")])
def test_a_problem_built_in_python_with_nan_is_refused(field, start):
    problem = local_problem()
    values = {"W": problem.W.multiply(np.nan).tocsr(), "q": np.full(6, np.inf)}
    with pytest.raises(ValueError, match=f"^{start}"):
        fclib.LocalProblem(**{**vars(problem), field: values[field]})


def test_a_non_symmetric_m_is_kept_as_stored_and_warned_of(global_file):
    """fclib.h says M is symmetric; a file whose M is not is the file's problem: read as stored, and said so."""
    replace(global_file, "fclib_global/M/x", np.array([2.0, -1, 5, 2, -1, -1, 2]))  # M[0, 1] = 5, M[1, 0] = −1
    problem, _, _ = fclib.read(global_file)
    assert problem.M[0, 1] == 5 and problem.M[1, 0] == -1
    assert problem.warnings == [("fclib_global/M: not symmetric (max |M − Mᵀ| = 6, max |M| = 5) although fclib.h "
                                 "says it is; kept as stored")]


def triplet(file, name, m, n, rows, columns, values, nz=None):
    """A triplet matrix group as fclib writes one (rows in i, columns in p)."""
    group = file.require_group(name)
    for key in list(group):
        del group[key]
    for key, value in {"nzmax": len(values), "m": m, "n": n, "nz": len(values) if nz is None else nz}.items():
        group.create_dataset(key, data=np.array([value], dtype=np.int32))
    group.create_dataset("i", data=np.asarray(rows, dtype=np.int32))
    group.create_dataset("p", data=np.asarray(columns, dtype=np.int32))
    group.create_dataset("x", data=np.asarray(values, dtype=float))


@pytest.mark.parametrize("rows, columns, start", [
    ([0, 3], [0, 1], "fclib_global/H/i: entry 1 is 3, outside the 3 rows [0, 3)"),
    ([0, 1], [0, 2], "fclib_global/H/p: entry 1 is 2, outside the 2 columns [0, 2)"),
    ([0], [0, 1], "fclib_global/H/i: 1 entries, the matrix needs 2"),
    ([0, 1], [0], "fclib_global/H/p: 1 entries, the matrix needs 2"),
])
def test_a_triplet_with_an_index_out_of_range_is_refused_before_scipy_sees_it(global_file, rows, columns, start):
    """Read unchecked, such an index segfaulted the solve (rc −11) or ended it in exit 1."""
    with h5py.File(global_file, "a") as file:
        triplet(file, "fclib_global/H", 3, 2, rows, columns, [1.0, 1.0], nz=2)
    refused(global_file, start)


def test_a_singular_m_is_refused_by_the_solve_naming_m(tmp_path, capsys):
    """M = [[1, 1, 0], [1, 1, 0], [0, 0, 1]]: symmetric, positive diagonal, singular (today PARDISO said "not
    enough memory")."""
    singular = sp.csr_matrix(np.array([[1.0, 1, 0], [1, 1, 0], [0, 0, 1]]))
    problem = global_problem()
    path = fclib.write(tmp_path / "s.hdf5", fclib.GlobalProblem(singular, problem.H, problem.f, problem.w,
                                                                  problem.mu, 2))
    assert main(["solve", str(path)]) == 2
    assert capsys.readouterr().err.startswith("error: fclib_global/M: singular")


def test_a_global_problem_too_large_to_condense_is_refused_before_the_work(global_file, capsys, monkeypatch):
    """The condensed W is dense, 24 bytes an entry (16 measured): one 2-D contact's 2 unknowns need 96 bytes, so a
    machine with 90 bytes available refuses them, naming H, before any factorization."""
    from convexcontact.scene import meshing

    monkeypatch.setattr(meshing, "available_memory", lambda: 90.0)
    assert main(["solve", str(global_file)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: fclib_global/H: 2 contact unknowns; condensing onto them") and "GiB available" in err


@pytest.mark.parametrize("content, start", [(None, "no such file"), (b"", "not an HDF5 file"),
                                            (b"W = [1, 2]\n", "not an HDF5 file"), ("folder", "a folder")])
def test_what_is_not_an_fclib_file_is_refused(tmp_path, content, start):
    path = tmp_path / "problem.hdf5"
    if content == "folder":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content)
    refused(path, f"{path}: {start}")


def test_an_hdf5_file_without_a_problem_is_refused(tmp_path):
    with h5py.File(tmp_path / "other.hdf5", "w") as file:
        file.create_group("fclib_global_rolling")
    message = refused(tmp_path / "other.hdf5", f"{tmp_path / 'other.hdf5'}: no /fclib_local nor /fclib_global")
    assert "fclib_global_rolling is not supported" in message
    replace(tmp_path / "other.hdf5", "fclib_local", np.zeros(3))
    refused(tmp_path / "other.hdf5", "fclib_local: expected a group, found a dataset")


# --- random corruptions of a valid file: a valid problem or a ValueError naming a dataset --------------------------

def valid_file(folder, kind):
    """A valid local file (W in compressed columns) or global one (M and H in triplets, as Siconos writes them)."""
    if kind == "local":
        answer = fclib.Solution(r=np.zeros(6), u=np.zeros(6))
        return fclib.write(folder / "fuzz.hdf5", local_problem(), answer, (answer,))
    problem = global_problem()
    path = fclib.write(folder / "fuzz.hdf5", problem, fclib.Solution(np.zeros(2), np.zeros(2), np.zeros(3)))
    with h5py.File(path, "a") as file:
        for name in ("M", "H"):
            A = sp.coo_matrix(getattr(problem, name))
            triplet(file, f"fclib_global/{name}", *A.shape, A.row, A.col, A.data)
    return path


MATRIX_PARTS = ("m", "n", "nz", "nzmax", "p", "i", "x")
DATASETS = {
    "local": [*(f"fclib_local/W/{key}" for key in MATRIX_PARTS), "fclib_local/spacedim", "fclib_local/vectors/q",
              "fclib_local/vectors/mu", "fclib_local/vectors/s", "fclib_local/V/x", "fclib_local/R/nz",
              "fclib_local/info/title", "solution/r", "solution/u", "solution/l",
              "guesses/number_of_guesses", "guesses/1/r"],
    "global": [*(f"fclib_global/{name}/{key}" for name in "MH" for key in MATRIX_PARTS), "fclib_global/spacedim",
               *(f"fclib_global/vectors/{key}" for key in ("f", "w", "mu", "b")), "fclib_global/G/x", "solution/v",
               "solution/r"],
}
NUMBERS = st.one_of(st.integers(-2**31, 2**31 - 1), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0, 1, -1, 2, 3, 6, 7, 8, -2]))
CORRUPTIONS = st.one_of(
    st.none(), st.just("group"), st.binary(max_size=8).map(np.bytes_),
    st.lists(NUMBERS, max_size=10).map(lambda values: np.array(values, dtype=float)),
    st.lists(st.integers(-3, 9), max_size=10).map(lambda values: np.array(values, dtype=np.int32)),
    st.lists(st.integers(-2**62, 2**62), min_size=1, max_size=3).map(lambda values: np.array(values, dtype=np.int64)),
    st.lists(st.booleans(), max_size=4).map(np.array))


@pytest.mark.parametrize("kind", ["local", "global"])
@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_randomly_damaged_file_is_read_or_refused_naming_a_dataset(tmp_path, kind, data):
    path = valid_file(tmp_path, kind)
    changes = data.draw(st.lists(st.tuples(st.sampled_from(DATASETS[kind]), CORRUPTIONS), min_size=1, max_size=3))
    for name, value in changes:
        replace(path, name, value)
    try:
        problem, solution, guesses = fclib.read(path)
    except ValueError as error:
        assert str(error).split(":")[0].split("/")[0] in (f"fclib_{kind}", "solution", "guesses"), str(error)
        return
    m = problem.mu.size * problem.spacedim
    matrix, vector = (problem.W, problem.q) if kind == "local" else (problem.H, problem.w)
    assert matrix.shape[1] == vector.size == m and np.all(np.isfinite(vector)) and np.all(np.isfinite(matrix.data))
    for found in (solution, *guesses):
        assert found is None or all(x is None or x.size == m for x in (found.r, found.u))


# --- the command line: every value-taking option of solve and export ------------------------------------------------

def exit_code(argv):
    """``convexcontact fclib ARGV``'s exit code (argparse's own refusals exit with 2 as well)."""
    try:
        return cli.main(["fclib", *argv])
    except SystemExit as stop:
        return stop.code


SOLVE_OPTIONS = [
    (["--merit-tol", "-1"], "--merit-tol: -1.0 is not a finite number > 0"),
    (["--merit-tol", "nan"], "--merit-tol: nan is not a finite number > 0"),
    (["--merit-tol", "inf"], "--merit-tol: inf is not"),
    (["--merit-tol", "0"], "--merit-tol: 0.0 is not"),
    (["--merit-tol", "abc"], "argument --merit-tol: invalid float value"),
    (["--max-iterations", "0"], "--max-iterations: 0 is not an integer ≥ 1"),
    (["--max-iterations", "-5"], "--max-iterations: -5 is not"),
    (["--max-iterations", "2.5"], "argument --max-iterations: invalid int value"),
    (["--relaxation", "0"], "--relaxation: 0.0 is not in (0, 1]"),
    (["--relaxation", "1.5"], "--relaxation: 1.5 is not in (0, 1]"),
    (["--relaxation", "nan"], "--relaxation: nan is not in (0, 1]"),
    (["--tol=-1e-8"], "--tol: -1e-08 is not a finite number > 0"),
    (["--tol", "inf"], "--tol: inf is not"),
    (["--solver", "bogus"], "--solver: unknown 'bogus'"),
    (["--solver", "osqp"], "--solver: osqp takes linear cones only"),
]


@pytest.mark.parametrize("options, start", SOLVE_OPTIONS)
def test_a_bad_solve_option_exits_2_naming_it(capsys, options, start):
    assert exit_code(["solve", str(SHIPPED), *options]) == 2
    err = capsys.readouterr().err
    assert start in err and "Traceback" not in err


EXPORT_OPTIONS = [
    (["--tol", "0"], "--tol: 0.0 is not a finite number > 0"),
    (["--tol", "nan"], "--tol: nan is not"),
    (["--solver", "bogus"], "--solver: unknown 'bogus'"),
    (["--solver", "cvxpy:NOSUCH"], "--solver: cvxpy has no solver 'NOSUCH'"),
]


@pytest.mark.parametrize("options, start", EXPORT_OPTIONS)
def test_a_bad_export_option_exits_2_naming_it(tmp_path, capsys, options, start):
    out = tmp_path / "p.hdf5"
    assert exit_code(["export", str(EXAMPLES / "frictional_punch.toml"), "--out", str(out), *options]) == 2
    assert start in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("command, option", [("solve", "--out"), ("solve", "--json"), ("export", "--out")])
@pytest.mark.parametrize("target, start", [("folder", "is a folder; give a file's name"),
                                           ("no_such_folder/x.hdf5", "the folder"),
                                           ("existing.hdf5", "exists; pass --overwrite to replace it")])
def test_an_output_that_would_fail_or_replace_a_file_is_refused_before_any_work(tmp_path, capsys, command, option,
                                                                                target, start):
    (tmp_path / "folder").mkdir()
    (tmp_path / "existing.hdf5").write_bytes(b"keep me")
    source = str(SHIPPED) if command == "solve" else str(EXAMPLES / "frictional_punch.toml")
    assert exit_code([command, source, option, str(tmp_path / target)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {option}: ") and start in err
    assert (tmp_path / "existing.hdf5").read_bytes() == b"keep me"


def test_json_and_out_must_be_two_files(tmp_path, capsys):
    same = str(tmp_path / "x.hdf5")
    assert exit_code(["solve", str(SHIPPED), "--json", same, "--out", same]) == 2
    assert "--json: " in capsys.readouterr().err


@pytest.mark.parametrize("argv, start", [
    (["solve", "missing.hdf5"], "missing.hdf5: no such file"),
    (["export", "missing.toml", "--out", "{tmp}/p.hdf5"], "scene: missing.toml: no such file"),
    (["export", "{tmp}", "--out", "{tmp}/p.hdf5"], "a folder; give a scene TOML file"),
    (["export", str(EXAMPLES / "sliding_block.toml"), "--out", "{tmp}/p.hdf5"],
     "history: cannot be exported to FClib: a file holds one static problem — export one step: remove the [history]"),
    (["export", str(EXAMPLES / "tresca_punch.toml"), "--out", "{tmp}/p.hdf5"], "contact.law: cannot be exported"),
])
def test_a_bad_file_argument_exits_2_naming_it(tmp_path, capsys, argv, start):
    assert exit_code([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    assert start in capsys.readouterr().err


def test_a_compliance_scene_is_told_a_fix_that_export_takes(tmp_path, capsys):
    """It used to be told "use formulation='primal'", an option export does not have."""
    text = (EXAMPLES / "frictional_punch.toml").read_text().replace("max_iterations = 100",
                                                                    "max_iterations = 100\nstiffness = 1e3")
    (tmp_path / "compliance.toml").write_text(text.replace("nx = 80", "nx = 8").replace("ny = 40", "ny = 4"))
    assert exit_code(["export", str(tmp_path / "compliance.toml"), "--out", str(tmp_path / "p.hdf5")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: contact.stiffness: ") and "remove stiffness" in err and "formulation" not in err


def test_the_exit_codes_are_the_commands():
    """fclib's 0 / 3 / 1 mean what ``convexcontact``'s do: solved, an answer with a caveat, no answer."""
    assert EXIT == {"solved": cli.EXIT["solved"], "answered": cli.EXIT["inaccurate"], "no answer": cli.EXIT.get("failed", 1)}
