"""Cross-validating another code's output on its own mesh (issue 14): a penalty 'peer' written to VTU."""

from pathlib import Path

import meshio
import numpy as np
import pytest

import convexcontact as cc
from convexcontact import cli
from convexcontact.results.output import write_vtk
from convexcontact.studies.crossvalidation.peer import compare_peer


@pytest.fixture(scope="module")
def exact():
    return cc.solve(cc.library.tresca_punch(nx=24).with_law(cc.Signorini()))


def written(result, path: Path) -> Path:
    write_vtk(result, path)
    return path


def peer(tmp_path, nx: int, stiffness: float) -> Path:
    """A normal-compliance (penalty) answer of the same body on an nx mesh, as a VTU file."""
    result = cc.solve(cc.library.tresca_punch(nx=nx).with_law(cc.NormalCompliance(stiffness=stiffness)))
    return written(result, tmp_path / f"peer_{nx}_{stiffness:g}.vtu")


def test_our_own_answer_read_back_has_no_error(exact, tmp_path):
    report = compare_peer(exact, written(exact, tmp_path / "same.vtu"))
    assert report["fields"] == {"displacement": "displacement", "pressure": "contact_pressure"}
    for name in ("energy_error", "l2_displacement_error", "pressure_l2_error", "pressure_max_error"):
        assert report[name] < 1e-10, name  # boundary nodes are probed 1e-12 of the box inside the peer's mesh
    assert report["normal_force"]["peer"] == pytest.approx(report["normal_force"]["reference"], rel=1e-12)


def test_a_penalty_peer_converges_like_one_over_its_stiffness_until_the_meshes_differ(exact, tmp_path):
    """Same mesh: the error falls tenfold per decade of c_N. Another mesh: it stalls at the discretization
    difference, which the exact answer on that mesh shows as well."""
    same = [compare_peer(exact, peer(tmp_path, 24, c))["energy_error"] for c in (1e2, 1e3, 1e4)]
    assert same[0] / same[1] == pytest.approx(10, rel=0.2) and same[1] / same[2] == pytest.approx(10, rel=0.2)
    other = [compare_peer(exact, peer(tmp_path, 34, c))["energy_error"] for c in (1e2, 1e4, 1e5)]
    floor = compare_peer(exact, written(cc.solve(cc.library.tresca_punch(nx=34).with_law(cc.Signorini())),
                                        tmp_path / "exact_34.vtu"))["energy_error"]
    assert other[0] > other[1] and other[2] == pytest.approx(floor, rel=0.05) and floor > 10 * same[2]


def test_mismatched_files_are_clear_errors(exact, tmp_path):
    path = written(exact, tmp_path / "same.vtu")
    mesh = meshio.read(path)
    meshio.write(tmp_path / "mm.vtu", meshio.Mesh(mesh.points * 1000.0, mesh.cells, point_data=mesh.point_data))
    with pytest.raises(ValueError, match="same units"):
        compare_peer(exact, tmp_path / "mm.vtu")
    meshio.write(tmp_path / "bare.vtu", meshio.Mesh(mesh.points, mesh.cells, point_data={"T": mesh.points[:, 0]}))
    with pytest.raises(ValueError, match=r"no displacement or contact pressure.*'T' \(325,\)"):
        compare_peer(exact, tmp_path / "bare.vtu")
    with pytest.raises(ValueError, match="no point data 'U_peer'"):
        compare_peer(exact, path, displacement="U_peer")
    box = cc.solve(cc.library.punch_3d(3))
    with pytest.raises(ValueError, match="3-D mesh against a 2-D scene"):
        compare_peer(exact, written(box, tmp_path / "box.vtu"))


def test_the_command_line_compares_a_scene_with_a_peer_file(tmp_path, capsys):
    scene = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "hertz.toml"
    reference = cc.solve(cc.scene.toml.load_scene(scene))
    path = written(reference, tmp_path / "peer.vtu")
    assert cli.main(["compare", str(scene), str(path), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "energy_error" in printed and "fields: displacement 'displacement'" in printed
    assert (tmp_path / "pressures.png").exists()


def test_a_peer_with_a_hole_whose_edge_passes_through_our_nodes_reads_them_exactly(tmp_path):
    """A 6 × 6 peer without the cells of [1/3, 2/3]²: our 3 × 3 mesh's nodes at the hole's corners lie on the peer's
    boundary up to round-off; they are probed just inside, and the report is that of the whole peer mesh."""
    def sheared(n):  # a unit square pressed and sheared over a Tresca ground: a field that varies in x and y
        return cc.solve(cc.Scene(name="square", body=cc.Body(cc.Rectangle(nx=n, ny=n)), materials=cc.Material(1.0, 0.3),
                                 dirichlet=(cc.Dirichlet("top", ux=0.002, uy=-0.01),),
                                 contact=cc.Contact("bottom", cc.Obstacle("flat"), cc.Tresca(slip_bound=0.001))))

    ours, peer_result = sheared(3), sheared(6)
    whole = written(peer_result, tmp_path / "whole.vtu")
    mesh = meshio.read(whole)
    centres = mesh.points[mesh.cells[0].data].mean(axis=1)
    inside = (abs(centres[:, 0] - 0.5) < 1 / 6) & (abs(centres[:, 1] - 0.5) < 1 / 6)
    assert inside.sum() == 8
    meshio.write(tmp_path / "hole.vtu", meshio.Mesh(mesh.points, [("triangle", mesh.cells[0].data[~inside])],
                                                    point_data=mesh.point_data))
    expected, holed = compare_peer(ours, whole), compare_peer(ours, tmp_path / "hole.vtu")
    for name in ("energy_error", "l2_displacement_error", "pressure_l2_error"):
        assert holed[name] == pytest.approx(expected[name], rel=1e-9, abs=1e-12), name
    assert expected["energy_error"] > 1e-3  # the two meshes' answers differ: the comparison is not trivially zero


def test_vertices_no_cell_uses_are_read_and_left_out(exact, tmp_path):
    """A file with a point no cell uses (gmsh's geometry points, far away, with other values there): its box and
    interpolation are those of the cells' vertices, so the report is that of the file without it."""
    path = written(exact, tmp_path / "same.vtu")
    mesh = meshio.read(path)
    data = {name: np.concatenate([np.full((1, *values.shape[1:]), 7.0), values])
            for name, values in mesh.point_data.items()}
    meshio.write(tmp_path / "extra.vtu", meshio.Mesh(np.vstack([[[5.0, 5.0, 0.0]], mesh.points]),
                                                     [("triangle", mesh.cells[0].data + 1)], point_data=data))
    with_extra, without = compare_peer(exact, tmp_path / "extra.vtu"), compare_peer(exact, path)
    for name in ("energy_error", "pressure_l2_error"):
        assert with_extra[name] == without[name], name
