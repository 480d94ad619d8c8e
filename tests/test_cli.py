"""The command line: the demo's outputs, `run` on a scene file, exit codes."""

import json
from pathlib import Path

import meshio
import numpy as np
import pytest

from convexcontact.cli import main

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


def test_demo_writes_summary_vtk_and_plots(tmp_path, capsys):
    assert main(["demo", "--nx", "24", "--out", str(tmp_path)]) == 0
    assert "certificate (worst)" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in ("ndof", "n_contact_nodes", "contact_half_width", "max_pressure", "normal_force", "certificate",
                "solver", "status", "iterations", "timings", "contact_nodes"):
        assert key in summary
    nodes = summary["contact_nodes"]
    assert len(nodes["x"]) == len(nodes["lambda_N"]) == summary["n_contact_nodes"]
    assert abs(summary["normal_force"] / 0.0086307 - 1) < 1e-8  # the demo is force-controlled
    vtk = meshio.read(tmp_path / "solution.vtu")
    assert {"displacement", "contact_pressure"} <= set(vtk.point_data)
    assert {"sigma_xx", "sigma_yy", "sigma_xy", "von_mises"} <= set(vtk.cell_data)
    assert np.isclose(vtk.point_data["contact_pressure"].max(), summary["max_pressure"])
    assert (tmp_path / "deformed.png").stat().st_size > 0 and (tmp_path / "contact.png").stat().st_size > 0


def test_run_scene_file_with_json_and_solver(tmp_path):
    target = tmp_path / "patch.json"
    assert main(["run", str(SCENES / "patch.toml"), "--solver", "osqp", "--json", str(target)]) == 0
    summary = json.loads(target.read_text())
    assert summary["solver"] == "osqp" and summary["status"] == "solved"
    assert np.allclose(summary["contact_nodes"]["lambda_N"], 0.1, rtol=1e-7)


def test_bad_input_exits_2_and_names_the_field(tmp_path, capsys):
    broken = tmp_path / "broken.toml"
    broken.write_text((SCENES / "patch.toml").read_text().replace("nu = 0.3", "nu = 0.5"))
    assert main(["run", str(broken)]) == 2
    assert "material.nu" in capsys.readouterr().err
    assert main(["run", str(SCENES / "patch.toml"), "--solver", "gurobi-direct"]) == 2


def test_infeasible_scene_exits_1_with_the_solver_status(tmp_path, capsys):
    scene = (SCENES / "patch.toml").read_text()
    infeasible = tmp_path / "infeasible.toml"
    infeasible.write_text(scene.replace('boundary = "left"\nux = 0.0', 'boundary = "bottom"\nux = 0.0\nuy = 0.0')
                          .replace("gap = 0.0", "gap = -0.01"))
    assert main(["run", str(infeasible), "--out", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "infeasible" in out.lower()
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "infeasible"


def test_compare_two_summaries(tmp_path, capsys):
    exact, other = tmp_path / "exact.json", tmp_path / "osqp.json"
    assert main(["run", str(SCENES / "hertz.toml"), "--json", str(exact)]) == 0
    assert main(["run", str(SCENES / "hertz.toml"), "--solver", "osqp", "--json", str(other)]) == 0
    capsys.readouterr()
    assert main(["compare", str(exact), str(other)]) == 0
    report = capsys.readouterr().out
    assert "pressure" in report
    assert main(["compare", str(exact), str(tmp_path / "missing.json")]) == 2


def test_study_commands(tmp_path, capsys):
    assert main(["study", "sweep", "penalty", "--nx", "8", "--out", str(tmp_path / "sweep.png")]) == 0
    assert "fitted slope" in capsys.readouterr().out and (tmp_path / "sweep.png").exists()
    assert main(["study", "work-precision", "hertz", "--size", "8", "12", "--tol", "1e-8", "--solvers", "osqp",
                 "--formulations", "primal", "--out", str(tmp_path / "wp")]) == 0
    rows = (tmp_path / "wp" / "hertz.csv").read_text().splitlines()
    assert len({line.split(",")[1] for line in rows[1:]}) == 2  # two meshes (ndof column)
    assert list((tmp_path / "wp").glob("*.png"))
    assert main(["study", "stability", "--quick", "--cases", "zero load", "--out", str(tmp_path / "s.md")]) == 0
    assert "zero load" in (tmp_path / "s.md").read_text()


@pytest.mark.parametrize("arguments, command", [
    (["bench"], "convexcontact bench"), (["bench", "--history", "2"], "convexcontact bench --history"),
    *((["study", kind], f"convexcontact study {kind}") for kind in ("work-precision", "sweep", "stability",
                                                                    "uniqueness", "sfepy")),
])
def test_every_study_and_bench_names_its_command_in_its_help(capsys, arguments, command):
    """Each parser is built in its module's main; --help shows the command as typed and the main's docstring."""
    with pytest.raises(SystemExit) as exit_:
        main([*arguments, "--help"])
    shown = capsys.readouterr().out
    assert exit_.value.code == 0 and shown.startswith(f"usage: {command} ") and f"``{command}" in shown
