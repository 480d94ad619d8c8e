"""Every class of bad input of issue 10 is a clear error that names the field and the fix — through the
Python API, the TOML loader and the command line — and no file of the user's changes."""

import dataclasses
import hashlib
from pathlib import Path

import meshio
import numpy as np
import pytest
import skfem as fe
from hypothesis import given
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact import cli
from convexcontact.scene.toml import scene_from_dict

BASE = cc.library.pressure_patch(nx=3)


def replaced(**fields):
    return lambda: dataclasses.replace(BASE, **fields)


def raises(build, field: str, fix: str):
    """``build()`` raises a SceneError or ValueError whose message starts with the field and carries a fix."""
    with pytest.raises(ValueError) as error:
        build()
    message = str(error.value)
    assert message.startswith(field) or getattr(error.value, "field", None) == field, message
    assert fix in message, message


@pytest.mark.parametrize("build, field, fix", [
    (lambda: cc.Body("mesh.msh"), "body.geometry", "cc.MeshFile(path)"),
    (lambda: cc.Contact("top", "flat"), "contact.obstacle", "cc.Obstacle"),
    (lambda: cc.Contact("top", cc.Obstacle(), "coulomb"), "contact.law", "cc.Coulomb(F)"),
    (lambda: cc.Contact(3), "contact.boundary", "name a boundary"),
    (replaced(dirichlet="bottom"), "dirichlet", "cc.Dirichlet"),
    (replaced(dirichlet=["bottom"]), "dirichlet[0]", "cc.Dirichlet"),
    (replaced(tractions=[("top", 1.0)]), "tractions[0]", "cc.Traction"),
    (replaced(body="rectangle"), "body", "cc.Body"),
    (replaced(contact="top"), "contact", "cc.Contact"),
    (replaced(materials="steel"), "materials", "cc.Material"),
    (replaced(history={"obstacle.depth": [0.1]}), "history", "cc.History"),
    (lambda: cc.Coulomb(friction=0.3, max_iterations=True), "contact.max_iterations", "positive integer"),
    (lambda: cc.solve(BASE.with_law(cc.Tresca(slip_bound=lambda x, y: np.ones(3)))), "contact.slip_bound",
     "one value per point"),
])
def test_the_python_api_checks_types_where_values_enter(build, field, fix):
    raises(build, field, fix)


@pytest.mark.parametrize("solver, options, field", [
    ("clarabel", {"tol": -1.0}, "tol"), ("clarabel", {"tol": float("nan")}, "tol"), ("osqp", {"tol": "1e-8"}, "tol"),
    ("cvxpy", {"tol": 0.0}, "tol"), ("clarabel", {"max_iter": -5}, "max_iter"), ("osqp", {"max_iter": 2.5}, "max_iter"),
    ("clarabel", {"verbose": "yes"}, "verbose"), ("clarabel", {"nosuch": 1}, "nosuch"),
    ("osqp", {"nosuch": 1}, "nosuch"), (None, {}, "solver"), ("cvxpy:NOSUCH", {}, "solver"),
    ("gurobi", {}, "solver"),
])
def test_solver_options_are_checked_before_any_work(solver, options, field):
    with pytest.raises(ValueError) as error:
        cc.solve(BASE, solver, **options)
    assert str(error.value).startswith(field), str(error.value)


@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True).filter(lambda t: not 0 < t < float("inf")),
                 st.text(max_size=5), st.booleans(), st.none().map(lambda _: -1)))
def test_no_bad_tolerance_reaches_a_solver(tol):
    with pytest.raises(ValueError, match="^tol"):
        cc.solvers.check_options({"tol": tol})


def test_a_failing_cvxpy_solve_is_a_failed_result():
    """cvxpy's SolverError is a result with status failed and the solver's words, like the other paths."""
    from convexcontact.scene.model import Box

    # Clarabel stalls on this 3-D Tresca block at 1e-12 (found by the fuzz suite); asked for that tol, cvxpy raises
    block = cc.Scene(name="block", body=cc.Body(Box(size=(1.0, 1.0, 0.5), cells=(3, 3, 3), origin=(-0.5, -0.5, 0.0)),
                                                "P1"),
                     materials=cc.Material(1.0, 0.0), dirichlet=(cc.Dirichlet("top", ux=5e-4, uy=0.0, uz=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("parabolic", radius=2.0, center=(0.0, 0.0, 0.0),
                                                              depth=1e-3), cc.Tresca(slip_bound=5e-4)))
    stalled = cc.prepare(block, "primal").solve("cvxpy", tol=1e-12)
    assert stalled.status == "failed" and stalled.solver_status.startswith("SolverError") and stalled.message
    assert cc.prepare(block, "primal").solve("cvxpy").status == "solved"  # at its default tol it retries looser


TOML = {"body": {"mesh": "rectangle", "nx": 3, "ny": 3}, "material": {"E": 1.0, "nu": 0.3},
        "dirichlet": [{"boundary": "bottom", "ux": 0.0, "uy": 0.0}], "contact": {"boundary": "top"}}


@pytest.mark.parametrize("edit, field, fix", [
    ({"contact": {"boundary": "top", "law": "normal_compliance"}}, "contact.stiffness", "stiffness ="),
    ({"obstacle": {"shape": "expression", "expression": "x**" + "9" * 400}}, "obstacle.expression", "below 1.8e308"),
    ({"contact": {"boundary": "top", "law": "tresca", "slip_bound": "1" + "0" * 400}}, "contact.slip_bound",
     "below 1.8e308"),
    ({"material": {"E": 1.0, "nu": 0.3, "viscosity": -1.0}}, "material.viscosity", "≥ 0"),
])
def test_the_toml_loader_names_the_key(edit, field, fix):
    raises(lambda: cc.solve(scene_from_dict({**TOML, **edit})), field, fix)


def square(points=None, cells=None) -> fe.MeshTri:
    mesh = fe.MeshTri.init_tensor(np.linspace(0, 1, 4), np.linspace(0, 1, 4))
    return fe.MeshTri(mesh.p if points is None else points, mesh.t if cells is None else cells)


def on(mesh) -> cc.Scene:
    named = mesh.with_boundaries({"bottom": lambda x: np.isclose(x[1], 0), "top": lambda x: np.isclose(x[1], 1),
                                  "left": lambda x: np.isclose(x[0], 0)})
    return dataclasses.replace(BASE, body=cc.Body(named, "P1"))


def cracked():
    """Node 5 doubled: half of its triangles use the copy, so the mesh is cut there."""
    mesh = square()
    cells = mesh.t.copy()
    uses = np.flatnonzero(cells.ravel() == 5)
    cells.ravel()[uses[::2]] = mesh.p.shape[1]
    return square(np.hstack([mesh.p, mesh.p[:, [5]]]), cells)


def collapsed():
    points = square().p.copy()
    points[:, 5] = points[:, 6]
    return square(points)


def sliver():
    """Interior node 5 moved onto the opposite side of one of its triangles: that triangle has no area."""
    mesh = square()
    cell = mesh.t[:, np.flatnonzero((mesh.t == 5).any(axis=0))[0]]
    a, b = (node for node in cell if node != 5)
    points = mesh.p.copy()
    points[:, 5] = (points[:, a] + points[:, b]) / 2 + 1e-14
    return square(points)


@pytest.mark.parametrize("mesh, problem", [
    (lambda: square(np.hstack([square().p, [[5.0], [5.0]]])), "belong to no cell"),
    (cracked, "share their place"),
    (collapsed, "share their place"),
    (sliver, "degenerate cells"),
])
def test_a_broken_mesh_is_named_with_the_fix(mesh, problem):
    with pytest.raises(cc.SceneError, match=problem) as error:
        cc.solve(on(mesh()))
    assert error.value.field == "body.mesh" and " — " in str(error.value)


def test_a_2d_mesh_file_with_z_is_not_flattened(tmp_path):
    mesh = square()
    path = tmp_path / "tilted.msh"
    meshio.write(path, meshio.Mesh(np.column_stack([mesh.p.T, 0.1 * mesh.p[0]]), [("triangle", mesh.t.T)]),
                 file_format="gmsh22")
    with pytest.raises(cc.SceneError, match="z from 0 to 0.1"):
        cc.solve(dataclasses.replace(BASE, body=cc.Body(cc.MeshFile(path), "P1")))


def test_a_mesh_too_large_for_the_machine_is_refused_before_it_is_built():
    with pytest.raises(cc.SceneError, match=r"GiB available — use fewer cells") as error:
        cc.prepare(dataclasses.replace(BASE, body=cc.Body(cc.Rectangle(nx=100000, ny=100000))))
    assert error.value.field == "body.nx"


def digest(folder: Path) -> dict:
    return {p.relative_to(folder): hashlib.sha1(p.read_bytes()).hexdigest() for p in folder.rglob("*") if p.is_file()}


SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "hertz.toml"


def test_an_existing_out_folder_is_not_overwritten_without_asking(tmp_path, capsys):
    """A second run into the same folder is refused before solving, the user's files byte for byte intact;
    --overwrite replaces our outputs and leaves the user's other files alone."""
    out = tmp_path / "out"
    assert cli.main(["run", str(SCENE), "--out", str(out)]) == 0
    (out / "notes.txt").write_text("mine")
    before = digest(out)
    assert cli.main(["run", str(SCENE), "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err and digest(out) == before
    assert cli.main(["run", str(SCENE), "--out", str(out), "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("arguments, message", [
    (["--out", "{file}"], "is a file"),
    (["--json", "{missing}/summary.json"], "does not exist"),
    (["--json", "{folder}"], "is a folder"),
    (["--json", "{file}"], "exists"),
])
def test_output_paths_are_checked_before_the_solve(tmp_path, capsys, arguments, message):
    (tmp_path / "file").write_text("the user's")
    paths = {"file": tmp_path / "file", "missing": tmp_path / "missing", "folder": tmp_path}
    before = digest(tmp_path)
    assert cli.main(["run", str(SCENE), *[a.format(**paths) for a in arguments]]) == 2
    printed = capsys.readouterr()
    assert message in printed.err and "closed nodes" not in printed.out  # refused before solving
    assert digest(tmp_path) == before


def test_ctrl_c_exits_quietly_and_leaves_no_partial_files(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"

    def interrupted_save(result, directory, formats=("json", "vtk", "png")):
        Path(directory).mkdir(parents=True, exist_ok=True)
        (Path(directory) / "summary.json").write_text("{")  # half written when Ctrl-C came
        raise KeyboardInterrupt

    monkeypatch.setattr(cc.ContactResult, "save", interrupted_save)
    assert cli.main(["run", str(SCENE), "--out", str(out)]) == 130
    assert capsys.readouterr().err.strip() == "interrupted"
    assert not (out / "summary.json").exists()


@pytest.mark.parametrize("arguments, code, text", [
    (["study", "--help"], 0, "each study has its own options"),
    (["study", "stability", "--cases", "nosuch"], 2, "no case named 'nosuch'"),
    (["bench", "--sizes", "-5"], 2, "at least 100 free DOFs"),
    (["run", str(SCENE), "--solver", "cvxpy:NOSUCH"], 2, "cvxpy has no solver"),
    (["run", str(SCENE), "--tol", "-1"], 2, "tol: expected a positive"),
])
def test_the_command_line_gives_a_clear_error_and_its_code(arguments, code, text, capsys):
    try:
        returned = cli.main(arguments)
    except SystemExit as exit_:  # argparse's own usage errors
        returned = exit_.code
    assert returned == code
    printed = capsys.readouterr()
    assert text in printed.out + printed.err and "Traceback" not in printed.err
