"""Bad input to ``demo``, ``run``, ``bench`` and every ``study`` but grid: each value-taking option given a wrong type,
NaN, infinity, a negative, zero, an absurd size, an unknown name or an output it must not touch is refused with exit
code 2 and ``error: OPTION: … fix``, before any work (the work is replaced by a failing stub) and with every file in
the working folder as it was."""

import hashlib
import math
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from convexcontact import cli
from convexcontact.studies import arguments

SURFACES = ("convexcontact demo", "convexcontact run", "convexcontact bench", "convexcontact study work-precision",
            "convexcontact study sweep", "convexcontact study stability", "convexcontact study uniqueness",
            "convexcontact study sfepy")

SCENE = str(Path(__file__).resolve().parents[1] / "examples" / "scenes" / "hertz.toml")

WORK = ("convexcontact.drivers.prepared.assemble", "convexcontact.drivers.history_run.run",
        "convexcontact.drivers.solve.all_solutions", "convexcontact.studies.benchmarks.bench.run",
        "convexcontact.studies.benchmarks.bench.friction_sweep", "convexcontact.studies.benchmarks.history_bench.case",
        "convexcontact.studies.precision.work_precision.run", "convexcontact.studies.precision.work_precision.overkill",
        "convexcontact.studies.crossvalidation.sweeps.penalty_sweep", "convexcontact.studies.crossvalidation.sweeps.regularization_sweep",
        "convexcontact.studies.precision.stability.run", "convexcontact.studies.verification.uniqueness.run",
        "convexcontact.studies.crossvalidation.sfepy_peer.penalty_study")
"""Where each command's work starts: reaching one fails the test."""


def digest(folder: Path) -> dict:
    return {path.relative_to(folder): hashlib.sha1(path.read_bytes()).hexdigest() if path.is_file() else None
            for path in folder.rglob("*")}


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A working folder holding a user's file, a folder, and the outputs of earlier runs; no work may start."""
    for target in WORK:
        monkeypatch.setattr(target, lambda *args, **kwargs: pytest.fail("the work started"))
    (tmp_path / "file").write_text("the user's")
    for name in ("summary.json", "bench_2d.csv", "history_bench.csv", "hertz.csv", "uniqueness.csv", "mesh.vtk"):
        (tmp_path / "earlier" / name).parent.mkdir(exist_ok=True)
        (tmp_path / "earlier" / name).write_text("an earlier run's")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def exit_code(arguments: list) -> int:
    """``convexcontact ARGUMENTS``'s exit code (argparse's own refusals exit through SystemExit)."""
    try:
        return cli.main(arguments)
    except SystemExit as exit_:
        return exit_.code


def check(capsys, folder: Path, arguments: list, *texts: str) -> None:
    """Exit code 2 and ``error: …`` holding ``texts`` on stderr, no traceback, every file in ``folder`` as it was."""
    before = digest(folder)
    assert exit_code(arguments) == 2
    err = capsys.readouterr().err
    assert "error: " in err and "Traceback" not in err, err
    for text in texts:
        assert text in err, err
    assert digest(folder) == before


NUMBERS = ["abc", "nan", "inf", "-1", "0"]
"""Wrong type, NaN, infinity, negative and zero: no option taking a positive number accepts any."""

POSITIVE = [("demo", "--tol"), ("run", "--tol"), ("bench", "--sizes"), ("bench --scenario whole-face", "--nodes"),
            ("bench --history 3", "--sizes"), ("study work-precision hertz", "--size"),
            ("study work-precision punch", "--reference-size"), ("study work-precision hertz", "--tol"),
            ("study sweep penalty", "--values"), ("study sweep regularization", "--values"),
            ("study uniqueness", "--max-friction"), ("study sfepy", "--depth"), ("study sfepy", "--stiffness")]
"""Options taking a positive number (command, option)."""

INTEGERS = {  # command, option: the smallest count it takes
    ("demo", "--nx"): 2, ("bench", "--sweep"): 1, ("bench", "--history"): 2, ("study sweep penalty", "--nx"): 2,
    ("study sweep regularization", "--nx"): 2, ("study uniqueness", "--frictions"): 2,
    ("study uniqueness", "--angles"): 2, ("study sfepy", "--cells"): 1,
}


def command_line(command: str, option: str, value: str) -> list:
    words = command.split()
    if words[0] == "run":
        words.append(SCENE)
    return words + [f"{option}={value}"]  # "=": argparse would take -1 for an option of its own


@pytest.mark.parametrize("command, option", POSITIVE)
def test_a_positive_number_is_refused_where_it_is_read(capsys, folder, command, option):
    """NaN, infinity and garbage by argparse (``argument --tol: expected a positive finite number, e.g. 1e-8; got
    'nan'``); a size below 100 DOFs by the bench (``--sizes: -1 DOFs; give sizes of at least 100 free DOFs, e.g.``)."""
    for value in NUMBERS:
        check(capsys, folder, command_line(command, option, value), f"{option}: ", "e.g.", f"{value}")


@pytest.mark.parametrize("command, option", list(INTEGERS))
def test_a_count_is_an_integer_of_at_least_its_minimum(capsys, folder, command, option):
    minimum = INTEGERS[command, option]
    for value in ["abc", "nan", "2.5", "-3", "0", str(minimum - 1), "1e4"]:
        check(capsys, folder, command_line(command, option, value),
              f"argument {option}: expected an integer ≥ {minimum}, e.g.", f"got '{value}'")


@pytest.mark.parametrize("command, option", POSITIVE + [("fclib solve x.hdf5", "--merit-tol")])
def test_the_end_of_options_is_not_a_value(capsys, folder, command, option):
    """``--tol=--``: argparse 3.11 passes an empty list on, past every type (the long profile's find)."""
    check(capsys, folder, command_line(command, option, "--"), f"{option}: expected a value, got '--'", "give")


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])  # the stubs and the folder hold for all
@given(value=st.one_of(st.floats(max_value=0.0), st.sampled_from([math.inf, -math.inf, math.nan]),
                       st.text(alphabet="abexyz,;+- ", min_size=1, max_size=6)),
       command_option=st.sampled_from(POSITIVE))
def test_no_bad_number_reaches_the_work(capsys, folder, value, command_option):
    """Any number ≤ 0, NaN, ±infinity or garbage, for any option taking a positive number: exit 2, naming it."""
    command, option = command_option
    assert exit_code(command_line(command, option, str(value))) == 2
    assert f"{option}: " in capsys.readouterr().err


@pytest.mark.parametrize("arguments, texts", [
    (["demo", "--solver", "bogus"], ["--solver: unknown 'bogus'", "use one of"]),
    (["run", SCENE, "--solver", "gurobi"], ["--solver: unknown 'gurobi'", "use one of"]),
    (["demo", "--solver", "cvxpy:NOSUCH"], ["cvxpy has no solver 'NOSUCH'", "it has"]),
    (["demo", "--formulation", "both"], ["--formulation: unknown 'both'", "use one of", "'dual-matrix-free'"]),
    (["run", SCENE, "--formulation", "bogus"], ["--formulation: unknown 'bogus'", "use one of", "'primal'"]),
    (["run", SCENE, "--solutions", "some"], ["argument --solutions: invalid choice: 'some'", "'all'"]),
    (["run", "missing.toml"], ["cannot read missing.toml"]),
    (["study", "granite"], ["argument kind: invalid choice: 'granite'", "work-precision"]),
    (["bench", "--dim", "4"], ["argument --dim: invalid choice: 4", "2, 3"]),
    (["bench", "--dim", "two"], ["argument --dim: invalid int value"]),
    (["bench", "--laws", "mohr"], ["argument --laws: invalid choice: 'mohr'", "coulomb"]),
    (["bench", "--scenario", "wall"], ["argument --scenario: invalid choice: 'wall'", "whole-face"]),
    (["bench", "--scenario", "shapes", "--nodes", "1e3"], ["--nodes: ", "with --scenario whole-face"]),
    (["bench", "--formulation", "both"], ["--formulation: unknown 'both'", "dual-matrix-free"]),
    (["bench", "--solver", "bogus"], ["solver: unknown 'bogus'", "use one of"]),
    (["bench", "--sizes", "50"], ["--sizes: 50 DOFs", "at least 100 free DOFs"]),
    (["bench", "--nodes", "1e3"], ["--nodes: ", "with --scenario whole-face"]),
    (["bench", "--scenario", "whole-face", "--nodes", "1"], ["--nodes: ", "at least 2 contact nodes"]),
    (["bench", "--history", "3", "--law", "mohr"], ["argument --law: invalid choice: 'mohr'", "tresca"]),
    (["bench", "--history", "3", "--sizes", "50"], ["--sizes: 50 DOFs", "at least 100 DOFs"]),
    (["bench", "--history"], ["argument --history: expected one argument"]),
    (["study", "work-precision", "granite"], ["invalid choice: 'granite'", "hertz"]),
    (["study", "work-precision", "hertz", "--size", "2.5"], ["--size: hertz's size is nx, an integer ≥ 2"]),
    (["study", "work-precision", "hertz", "--reference-size", "1"], ["--reference-size: ", "integer ≥ 2"]),
    (["study", "work-precision", "punch", "--size", "0.5"], ["--size: punch's size", "below 0.2", "e.g. 0.02"]),
    (["study", "work-precision", "hertz", "--solvers", "osqp", "bogus"], ["--solvers: unknown 'bogus'", "use one of"]),
    (["study", "work-precision", "hertz", "--formulations", "both"],
     ["argument --formulations: invalid choice: 'both'", "dual-matrix-free"]),
    (["study", "sweep", "friction"], ["invalid choice: 'friction'", "regularization"]),
    (["study", "sweep", "penalty", "--solver", "bogus"], ["solver: unknown 'bogus'", "use one of"]),
    (["study", "sweep", "regularization", "--solver", "cvxpy:NOSUCH"], ["cvxpy has no solver"]),
    (["study", "stability", "--cases", "nosuch"], ["--cases: no case named 'nosuch'", "'zero load'"]),
    (["study", "uniqueness", "--nu", "0.5"], ["--nu: 0.5", "0 ≤ ν < 0.5"]),
    (["study", "uniqueness", "--nu", "-0.2"], ["--nu: -0.2", "0 ≤ ν < 0.5"]),
    (["study", "uniqueness", "--nu", "nan"], ["argument --nu: expected a finite number"]),
    (["study", "uniqueness", "--angle-range", "-90", "-180"], ["--angle-range: FROM -90 must be below TO -180"]),
    (["study", "uniqueness", "--angle-range", "-90", "-90"], ["--angle-range: ", "e.g. --angle-range -180 -90"]),
    (["study", "uniqueness", "--angle-range", "nan", "0"], ["argument --angle-range: expected a finite number"]),
    (["study", "uniqueness", "--angle-range", "-90", "inf"], ["argument --angle-range: expected a finite number"]),
    (["study", "uniqueness", "--angle-range", "0"], ["argument --angle-range: expected 2 arguments"]),
    (["study", "sfepy", "--depth", "0.8"], ["--depth: 0.8 sinks the whole sphere", "e.g. 0.05"]),
    (["study", "sfepy", "--non-penetration", "mortar"], ["argument --non-penetration: invalid choice", "gauss"]),
])
def test_a_bad_name_or_value_is_refused_with_the_valid_ones(capsys, folder, arguments, texts):
    check(capsys, folder, arguments, *texts)


@pytest.fixture
def roomy(monkeypatch):
    """A machine of unlimited memory: a size is refused for the hours it would take."""
    monkeypatch.setattr("convexcontact.scene.meshing.available_memory", lambda: float("inf"))


@pytest.mark.parametrize("arguments, option", [
    (["demo", "--nx", "1000000"], "--nx"),
    (["bench", "--sizes", "1e13"], "--sizes"),
    (["bench", "--dim", "3", "--sizes", "1e4", "1e9"], "--sizes"),
    (["bench", "--scenario", "two-body", "--sizes", "1e13"], "--sizes"),
    (["bench", "--scenario", "shapes", "--sizes", "1e13"], "--sizes"),
    (["bench", "--scenario", "shapes", "--dim", "3", "--sizes", "1e4", "1e9"], "--sizes"),
    (["bench", "--scenario", "two-body", "--dim", "3", "--sizes", "1e9"], "--sizes"),
    (["bench", "--scenario", "whole-face", "--nodes", "1e12"], "--sizes/--nodes"),
    (["bench", "--history", "3", "--sizes", "1e13"], "--sizes"),
    (["study", "work-precision", "hertz", "--size", "1e6"], "--size"),
    (["study", "work-precision", "punch", "--size", "1e-9"], "--size"),
    (["study", "work-precision", "hertz", "--reference-size", "1e6"], "--reference-size"),
    (["study", "sweep", "penalty", "--nx", "1000000"], "--nx"),
    (["study", "sweep", "regularization", "--nx", "1000000"], "--nx"),
    (["study", "sfepy", "--cells", "100000"], "--cells"),
])
def test_a_size_beyond_the_memory_is_refused_with_the_estimate(capsys, folder, arguments, option):
    check(capsys, folder, arguments, f"error: {option}: ", "GiB; this machine has", "of this shape fit")


@pytest.mark.parametrize("arguments, option", [
    (["bench", "--sweep", "100000"], "--sweep"),
    (["bench", "--sizes", "1e8"], "--sizes"),
    (["bench", "--history", "1000000", "--sizes", "1e4"], "--history"),
    (["study", "work-precision", "hertz", "--size", "800"], "--size"),
    (["study", "sweep", "penalty", "--nx", "3000", "--values", *["1e3"] * 10], "--nx/--values"),
    (["study", "uniqueness", "--frictions", "1000", "--angles", "1000"], "--frictions/--angles"),
    (["study", "sfepy", "--cells", "60", "--stiffness", *["1e3"] * 300], "--cells/--stiffness"),
])
def test_a_run_of_hours_is_refused_with_the_estimate_and_the_limit(capsys, folder, roomy, arguments, option):
    check(capsys, folder, arguments, f"error: {option}: ", " h, beyond the 1 h a run may take here", "of them fit")


FILE_OUTPUTS = [["study", "sweep", "penalty"], ["study", "sweep", "regularization"], ["study", "stability"]]
FOLDER_OUTPUTS = [["demo"], ["run", SCENE], ["bench"], ["bench", "--history", "3"],
                  ["study", "work-precision", "hertz"], ["study", "uniqueness"], ["study", "sfepy"]]


@pytest.mark.parametrize("command", FOLDER_OUTPUTS, ids=" ".join)
def test_an_output_folder_that_is_a_file_is_refused(capsys, folder, command):
    check(capsys, folder, command + ["--out", "file"], "--out: file is a file", "give a folder")


@pytest.mark.parametrize("command", FOLDER_OUTPUTS, ids=" ".join)
def test_an_output_folder_holding_an_earlier_run_is_not_overwritten(capsys, folder, command):
    """The earlier run's files (summary.json, bench_2d.csv, history_bench.csv, hertz.csv, uniqueness.csv,
    mesh.vtk) stay byte for byte without --overwrite."""
    check(capsys, folder, command + ["--out", "earlier"], "--out: earlier already holds", "--overwrite to replace")


@pytest.mark.parametrize("command", FILE_OUTPUTS, ids=" ".join)
@pytest.mark.parametrize("target, texts", [
    ("earlier", ["--out: earlier is a folder", "give a file's name"]),
    ("missing/table.md", ["--out: the folder missing does not exist", "create it"]),
    ("file", ["--out: file exists", "--overwrite to replace it"]),
])
def test_an_output_file_is_checked_before_the_work(capsys, folder, command, target, texts):
    check(capsys, folder, command + ["--out", target], *texts)


@pytest.mark.parametrize("command", [["demo"], ["run", SCENE]], ids=" ".join)
@pytest.mark.parametrize("target, texts", [
    ("earlier", ["--json: earlier is a folder", "give a file's name"]),
    ("missing/summary.json", ["--json: the folder missing does not exist"]),
    ("file", ["--json: file exists", "--overwrite to replace it"]),
])
def test_the_json_summary_is_checked_before_the_solve(capsys, folder, command, target, texts):
    check(capsys, folder, command + ["--json", target], *texts)


def test_the_estimates_refuse_only_beyond_the_limit():
    """One run under the limit passes, the same count over it is refused: the estimate, not a guess at the caller."""
    arguments.check_duration("--x", 10, arguments.LONG_RUN / 10, "solves", "fewer")
    with pytest.raises(ValueError, match=r"^--x: 11 solves of about 3.6e\+02 s each would take about 1.1 h"):
        arguments.check_duration("--x", 11, arguments.LONG_RUN / 10, "solves", "fewer")


def test_a_study_that_answered_no_case_exits_1(monkeypatch, tmp_path, capsys):
    """Every case failed: code 1, each row having said why; one answered case: 0."""
    failed = [{"case": "c", "status": status} for status in ("crash", "input error", "infeasible")]
    monkeypatch.setattr("convexcontact.studies.precision.stability.run", lambda **kwargs: failed)
    monkeypatch.setattr("convexcontact.studies.precision.stability.table", lambda rows: "table")
    assert cli.main(["study", "stability"]) == 1
    monkeypatch.setattr("convexcontact.studies.precision.stability.run", lambda **kwargs: failed + [{"status": "inaccurate"}])
    assert cli.main(["study", "stability"]) == 0
    assert not cli.failed_all([]) and not cli.failed_all(None)  # a resumed grid with nothing left failed nothing


def test_a_study_reference_that_cannot_be_solved_is_an_error_without_a_traceback(monkeypatch, capsys, tmp_path):
    def unsolved(*args):
        raise RuntimeError("overkill reference: Clarabel returned 'failed': stalled")

    monkeypatch.setattr("convexcontact.studies.precision.work_precision.overkill", unsolved)
    assert cli.main(["study", "work-precision", "punch", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err == "error: overkill reference: Clarabel returned 'failed': stalled\n"


def test_overwrite_replaces_the_earlier_files_and_nothing_else(tmp_path, capsys):
    """With --overwrite the earlier run's files are replaced (by a real run of four cases), the user's other files
    untouched."""
    (tmp_path / "uniqueness.csv").write_text("an earlier run's")
    (tmp_path / "notes.txt").write_text("mine")
    assert cli.main(["study", "uniqueness", "--frictions", "2", "--angles", "2", "--out", str(tmp_path),
                     "--overwrite"]) == 0
    assert (tmp_path / "uniqueness.csv").read_text().startswith("friction,angle,")
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert sorted(os.listdir(tmp_path)) == ["notes.txt", "uniqueness.csv", "uniqueness.png"]
