"""Parameter grids on Dask (issue 14): every case solved once, failures kept as rows, reruns resumed."""

import csv
import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact import cli
from convexcontact.studies.parameters.grid import run_grid


def block(law) -> cc.Scene:
    return cc.Scene(name="block", body=cc.Body(cc.Rectangle(width=1.0, height=0.5, nx=8, ny=4)),
                    materials=cc.Material(1.0, 0.3), dirichlet=(cc.Dirichlet("top", ux=0.002, uy=-0.01),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat"), law))


GRID = {"contact.friction": [0.1, 0.3], "dirichlet[top].uy": [-0.01, -0.02], "body.nx": [8, 10]}


def independent(parameters) -> cc.ContactResult:
    scene = block(cc.Coulomb(friction=parameters["contact.friction"]))
    scene = dataclasses.replace(scene, dirichlet=(cc.Dirichlet("top", ux=0.002, uy=parameters["dirichlet[top].uy"]),),
                                body=cc.Body(cc.Rectangle(width=1.0, height=0.5, nx=parameters["body.nx"], ny=4)))
    return cc.solve(scene)


def test_every_case_is_the_independent_solve_and_a_rerun_skips_them(tmp_path):
    """8 cases in 2 groups (one per mesh: assembled and condensed once); each row is the answer of the same case
    solved on its own; the CSV holds them all, and a second run finds nothing left to do."""
    rows = run_grid(block(cc.Coulomb(friction=0.2)), GRID, tmp_path, scheduler="serial", progress=lambda _: None)
    assert len(rows) == 8 and {r["status"] for r in rows} == {"solved"} and len({r["group"] for r in rows}) == 2
    for row in rows[::3]:
        alone = independent(row)
        assert row["normal_force"] == pytest.approx(alone.normal_force, rel=1e-8)
        assert row["tangential_force"] == pytest.approx(alone.tangential_force, rel=1e-7, abs=1e-12)
    with open(tmp_path / "grid.csv", newline="") as handle:
        assert len(list(csv.DictReader(handle))) == 8
    assert run_grid(block(cc.Coulomb(friction=0.2)), GRID, tmp_path, scheduler="serial", progress=lambda _: None) == []


def test_a_failing_case_is_a_row_and_the_others_are_solved(tmp_path):
    """A friction formula that evaluates to infinity fails its case with the reason; the rest are solved."""
    rows = run_grid(block(cc.Coulomb(friction=0.2)), {"contact.friction": [0.2, "1/(x - x)"]}, tmp_path,
                    scheduler="serial", progress=lambda _: None)
    status = {row["contact.friction"]: row for row in rows}
    assert status[0.2]["status"] == "solved"
    assert status["1/(x - x)"]["status"] == "error" and "contact.friction" in status["1/(x - x)"]["error"]


def test_a_local_dask_cluster_gives_the_serial_rows(tmp_path):
    """Two worker processes, one task per mesh: the same numbers as in this process."""
    grid = {"contact.friction": [0.1, 0.3], "body.nx": [8, 10]}
    serial = run_grid(block(cc.Coulomb(friction=0.2)), grid, tmp_path / "serial", scheduler="serial",
                      progress=lambda _: None)
    parallel = run_grid(block(cc.Coulomb(friction=0.2)), grid, tmp_path / "dask", workers=2, progress=lambda _: None)
    by_key = {row["key"]: row for row in parallel}
    assert sorted(by_key) == sorted(row["key"] for row in serial)
    assert all(np.isclose(by_key[row["key"]]["normal_force"], row["normal_force"], rtol=1e-10) for row in serial)
    assert len({row["worker"] for row in parallel}) == 2


def test_the_command_line_runs_a_grid(tmp_path, capsys):
    scene = tmp_path / "block.toml"
    scene.write_text('[body]\nmesh = "rectangle"\nwidth = 1.0\nheight = 0.5\nnx = 6\nny = 3\n'
                     '[material]\nE = 1.0\nnu = 0.3\n[[dirichlet]]\nboundary = "top"\nux = 0.002\nuy = -0.01\n'
                     '[contact]\nboundary = "bottom"\nlaw = "tresca"\nslip_bound = 0.001\n[obstacle]\nshape = "flat"\n')
    assert cli.main(["study", "grid", str(scene), "--param", "contact.slip_bound=0.001,0.002",
                     "--scheduler", "serial", "--out", str(tmp_path / "out")]) == 0
    assert "2/2 cases solved" in capsys.readouterr().out
    assert cli.main(["study", "grid", str(scene), "--param", "contact.nosuch=1", "--scheduler", "serial"]) == 2
    assert capsys.readouterr().err.startswith("error: --param contact.nosuch: not a parameter")


def test_a_rerun_with_the_parameters_in_another_order_resumes_under_the_tables_header(tmp_path):
    """The table's columns stay as written; the rerun adds only the new case, under the same header."""
    scene = block(cc.Tresca(slip_bound=0.001))
    first = run_grid(scene, {"contact.slip_bound": [0.001], "body.nx": [6]}, tmp_path, scheduler="serial",
                     progress=None)
    rerun = run_grid(scene, {"body.nx": [6], "contact.slip_bound": [0.001, 0.002]}, tmp_path, scheduler="serial",
                     progress=None)
    assert [row["contact.slip_bound"] for row in first + rerun] == [0.001, 0.002]
    with open(tmp_path / "grid.csv", newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0][:3] == ["contact.slip_bound", "body.nx", "key"] and [r[0] for r in rows[1:]] == ["0.001", "0.002"]


def test_numpy_values_are_a_grid_and_arrays_of_two_dimensions_are_not(tmp_path):
    scene = block(cc.Tresca(slip_bound=0.001))
    rows = run_grid(scene, {"contact.slip_bound": np.array([0.001, 0.002])}, tmp_path, scheduler="serial",
                    progress=None)
    assert [row["status"] for row in rows] == ["solved", "solved"]
    assert abs(rows[0]["tangential_force"]) < abs(rows[1]["tangential_force"])  # a higher bound holds more shear
    with pytest.raises(ValueError, match=r"^grid.contact.slip_bound: expected a list of values"):
        run_grid(scene, {"contact.slip_bound": np.ones((2, 2))}, tmp_path / "b", scheduler="serial", progress=None)
