"""Bad input to the refinement comparison of ``study work-precision SCENE --refinement LEVELS`` and to its Python
entry: each value-taking option given a wrong type, a value out of range, a size beyond the machine or an option the
comparison would ignore is refused with exit code 2 and ``error: OPTION: … fix`` before any work (the work is a
failing stub), every file in the working folder as it was."""

import hashlib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from convexcontact import cli
from convexcontact.scene.library import hertz_punch, hertz_sphere
from convexcontact.studies.precision import refinement

SURFACES = ("convexcontact study work-precision",)

STUDY = ["study", "work-precision", "hertz", "--refinement"]


def digest(folder: Path) -> dict:
    return {path.relative_to(folder): hashlib.sha1(path.read_bytes()).hexdigest() if path.is_file() else None
            for path in folder.rglob("*")}


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A working folder with a user's file and an earlier comparison's outputs; the comparison may not start."""
    for target in ("convexcontact.studies.precision.refinement.compare", "convexcontact.studies.precision.work_precision.run"):
        monkeypatch.setattr(target, lambda *args, **kwargs: pytest.fail("the work started"))
    (tmp_path / "file").write_text("the user's")
    (tmp_path / "earlier").mkdir()
    (tmp_path / "earlier" / "hertz_refinement.csv").write_text("an earlier run's")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def check(capsys, folder: Path, arguments: list, *texts: str) -> None:
    """Exit code 2 and ``error: …`` holding ``texts`` on stderr, no traceback, every file as it was."""
    before = digest(folder)
    try:
        code = cli.main(arguments)
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert "error: " in err and "Traceback" not in err, err
    for text in texts:
        assert text in err, err
    assert digest(folder) == before


@pytest.mark.parametrize("value", ["1", "0", "-3", "2.5", "abc", "nan", "inf"])
def test_refinement_levels_must_be_an_integer_of_at_least_two(capsys, folder, value):
    check(capsys, folder, STUDY + [value], "argument --refinement: expected an integer ≥ 2, e.g. 4")


@pytest.mark.parametrize("option, values", [("--tol", ["1e-6"]), ("--solvers", ["osqp"]),
                                            ("--formulations", ["dual"]), ("--reference-size", ["80"])])
def test_an_option_of_the_solver_grid_is_refused_not_ignored(capsys, folder, option, values):
    check(capsys, folder, STUDY + ["3", option, *values], f"error: {option}: the refinement comparison",
          f"drop {option} or --refinement")


def test_more_than_one_size_is_refused(capsys, folder):
    check(capsys, folder, STUDY + ["3", "--size", "8", "16"], "error: --size: --refinement starts from one mesh",
          "give one --size")


@pytest.mark.parametrize("arguments, texts", [
    (["--size", "2.5"], ["--size: hertz's size is nx, an integer ≥ 2"]),
    (["--size", "nan"], ["argument --size: expected a positive finite number"]),
    (["--size", "-8"], ["argument --size: "]),
])
def test_a_bad_size_is_refused(capsys, folder, arguments, texts):
    check(capsys, folder, STUDY + ["3", *arguments], *texts)


def test_a_reference_beyond_the_memory_is_refused_with_the_estimate(capsys, folder):
    check(capsys, folder, STUDY + ["12"], "error: --refinement: ", "GiB; this machine has", "of this shape fit")


def test_a_comparison_of_hours_is_refused(capsys, folder, monkeypatch):
    monkeypatch.setattr("convexcontact.scene.meshing.available_memory", lambda: float("inf"))
    check(capsys, folder, STUDY + ["9"], "error: --refinement: ", " h, beyond the 1 h a run may take here")


def test_outputs_of_an_earlier_comparison_are_kept_without_overwrite(capsys, folder):
    check(capsys, folder, STUDY + ["3", "--out", "earlier"], "--out: ", "--overwrite")


def test_an_output_folder_that_is_a_file_is_refused(capsys, folder):
    check(capsys, folder, STUDY + ["3", "--out", "file"], "--out: file is a file", "give a folder")


@settings(max_examples=25, deadline=None)
@given(st.one_of(st.integers(max_value=1), st.floats(), st.text(max_size=4), st.booleans(), st.none()))
def test_compare_refuses_levels_that_are_not_an_integer_of_at_least_two(levels):
    with pytest.raises(ValueError, match="^levels: "):
        refinement.compare(hertz_punch(nx=4), levels)


@pytest.mark.parametrize("scene", [hertz_punch(nx=4, element="Q1"), hertz_sphere(2, "Q2")], ids=["Q1", "Q2-3D"])
def test_compare_refuses_cells_that_are_no_simplices_before_any_solve(monkeypatch, scene):
    """Quadrilaterals and hexahedra (uniform refinement only, their P1/P2 prolongation not written) are refused by the
    scene's field, with the elements that work."""
    monkeypatch.setattr("convexcontact.studies.precision.refinement.solve", lambda *a, **k: pytest.fail("solved"))
    with pytest.raises(ValueError, match="^scene: .*give a P1 or P2 scene on triangles or tetrahedra"):
        refinement.compare(scene, 2)


@pytest.mark.parametrize("value", ["P3", "Q1", "p2", "2", ""])
def test_the_element_is_one_the_comparison_knows(capsys, folder, value):
    check(capsys, folder, STUDY + ["3", "--element", value], "argument --element: invalid choice", "P1", "P2")


def test_the_element_without_refinement_is_refused(capsys, folder):
    check(capsys, folder, ["study", "work-precision", "hertz", "--element", "P2"], "error: --element: ",
          "drop --element or add --refinement LEVELS")


def test_p2_counts_in_the_size_checks(capsys, folder, monkeypatch):
    """The memory check counts P2's DOFs (about 4× P1's on one mesh): 6 levels from nx = 8 pass it with P1 (the work
    starts) and are refused with P2 (its reference: 5.9·10⁶ DOFs, 30 GiB)."""
    class Started(Exception):
        pass

    monkeypatch.setattr("convexcontact.studies.precision.refinement.compare",
                        lambda *args, **kwargs: (_ for _ in ()).throw(Started()))
    with pytest.raises(Started):
        cli.main(STUDY + ["6", "--element", "P1"])
    check(capsys, folder, STUDY + ["6", "--element", "P2"], "error: --refinement: ", "GiB")


@pytest.mark.parametrize("element", ["P1", "P2"])
def test_the_element_reaches_both_families(monkeypatch, tmp_path, element):
    """--element sets the elements of the scene the comparison refines (the comparison itself stubbed)."""
    seen = []
    monkeypatch.setattr("convexcontact.studies.precision.refinement.compare",
                        lambda scene, *args, **kwargs: seen.append(scene.body.element) or [])
    monkeypatch.setattr("convexcontact.studies.precision.refinement.plot", lambda *args, **kwargs: None)
    monkeypatch.setattr("convexcontact.studies.precision.refinement.table", lambda *args, **kwargs: "")
    assert cli.main(["study", "work-precision", "flat-punch", "--refinement", "2", "--element", element,
                     "--out", str(tmp_path)]) == 0
    assert seen == [element]
