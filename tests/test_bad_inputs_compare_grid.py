"""Issue 24, compare and study grid: every bad input is refused before any work, with a message that starts
with the argument (the file's path, ``--param PATH``, ``--scheduler`` …) and names a fix; no user file changes."""

import contextlib
import dataclasses
import hashlib
import json
import socket
import socketserver
import threading
import time
from pathlib import Path

import meshio
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact import cli
from convexcontact.results.output import write_vtk
from convexcontact.scene.toml import load_scene
from convexcontact.studies.crossvalidation.compare import compare_files
from convexcontact.studies.crossvalidation.peer import compare_peer, read_peer
from convexcontact.studies.parameters.grid import run_grid

SURFACES = ("convexcontact compare", "convexcontact study grid", "reader peer", "reader grid resume")

PATCH = ('[body]\nmesh = "rectangle"\nwidth = 1.0\nheight = 1.0\nnx = 3\nny = 3\n[material]\nE = 1.0\nnu = 0.3\n'
         '[[dirichlet]]\nboundary = "top"\nux = 0.002\nuy = -0.01\n[contact]\nboundary = "bottom"\nlaw = "tresca"\n'
         'slip_bound = 0.001\n[obstacle]\nshape = "flat"\n')


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A tiny Tresca scene file, its exact answer, that answer as a peer's VTU and as a summary.json."""
    folder = tmp_path_factory.mktemp("inputs")
    scene = folder / "patch.toml"
    scene.write_text(PATCH)
    result = cc.solve(load_scene(scene))
    assert result.status == "solved"
    write_vtk(result, folder / "peer.vtu")
    result.save(folder / "run", formats=("json",))
    return {"scene": scene, "result": result, "peer": folder / "peer.vtu", "summary": folder / "run" / "summary.json",
            "folder": folder}


def command(argv, capsys) -> tuple[int, str]:
    """The exit code and stderr of ``convexcontact ARGV`` (argparse's own refusals exit through SystemExit)."""
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exit_:
        code = exit_.code
    return code, capsys.readouterr().err


def refused(argv, capsys, start: str, fix: str) -> str:
    """``convexcontact ARGV`` exits 2 with ``error: START…`` naming ``fix``."""
    code, err = command(argv, capsys)
    assert code == 2, err
    message = err.strip().splitlines()[-1]
    assert start in message and fix in message, message
    assert "Traceback" not in err
    return message


def peer_with(files, path: Path, cells=None, points=None, **point_data) -> Path:
    """The peer file with its point data (and optionally cells or points) replaced."""
    mesh = meshio.read(files["peer"])
    meshio.write(path, meshio.Mesh(mesh.points if points is None else points,
                                   mesh.cells if cells is None else cells, point_data=point_data))
    return path


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# --- compare SCENE PEER: the peer's file -------------------------------------------------------------------------

def test_non_finite_peer_fields_name_the_field_and_the_points(files, tmp_path, capsys):
    good = meshio.read(files["peer"]).point_data
    displacement = good["displacement"].copy()
    displacement[2, 1] = np.nan
    path = peer_with(files, tmp_path / "nan.vtu", displacement=displacement, contact_pressure=good["contact_pressure"])
    refused(["compare", files["scene"], path], capsys, f"error: {path}: point data 'displacement' is NaN or infinite "
            "at 1 of 16 points (the first: point 2", "a run that converged")
    pressure = np.full_like(good["contact_pressure"], np.inf)
    path = peer_with(files, tmp_path / "inf.vtu", contact_pressure=pressure)
    with pytest.raises(ValueError, match=r"'contact_pressure' is NaN or infinite at 16 of 16 points"):
        compare_peer(files["result"], path)


def test_fields_of_the_wrong_shape_list_the_files_point_data_and_the_option(files, tmp_path, capsys):
    good = meshio.read(files["peer"]).point_data
    scalar = peer_with(files, tmp_path / "scalar.vtu", displacement=good["displacement"][:, 0])
    refused(["compare", files["scene"], scalar], capsys, "point data 'displacement' has shape (16,), a displacement "
            "of this 2-D mesh (16, 2); its point data: 'displacement' (16,)", "--displacement NAME")
    refused(["compare", files["scene"], files["peer"], "--displacement", "contact_pressure", "--pressure",
             "displacement"], capsys, "point data 'contact_pressure' has shape (16,)", "--displacement NAME")
    refused(["compare", files["scene"], files["peer"], "--pressure", "displacement"], capsys,
            "point data 'displacement' has shape (16, 2), a pressure", "--pressure NAME")
    lifted = np.column_stack([good["displacement"], np.full(16, 0.5)])
    with pytest.raises(ValueError, match="z component up to 0.5 on a 2-D mesh"):
        read_peer(peer_with(files, tmp_path / "lifted.vtu", displacement=lifted))


def test_names_not_in_the_file_name_the_option(files, capsys):
    for option in ("--displacement", "--pressure"):
        refused(["compare", files["scene"], files["peer"], option, "U_peer"], capsys,
                f"no point data 'U_peer' for the {option[2:]} ({option}); its point data: 'displacement' (16, 2)",
                "'contact_pressure' (16,)")
    with pytest.raises(ValueError, match="^displacement: expected str"):
        read_peer(files["peer"], displacement=3)


def test_files_that_are_not_meshes_say_what_meshio_reads(files, tmp_path, capsys):
    junk = tmp_path / "junk.vtu"
    junk.write_bytes(b"\x00garbage" * 10)
    message = refused(["compare", files["scene"], junk], capsys, f"error: {junk}: not a mesh meshio can read",
                      ".vtu, .vtk, .xdmf, .exo")
    assert "Couldn't read file" in message
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    refused(["compare", files["scene"], text], capsys, f"{text}: not a mesh meshio can read", ".vtu")
    refused(["compare", files["scene"], tmp_path / "missing.vtu"], capsys, "missing.vtu: no such file",
            "give the peer's output file")
    refused(["compare", files["scene"], files["summary"]], capsys, "a JSON file, not a mesh", "give both")


@given(st.binary(max_size=400), st.sampled_from([".vtu", ".vtk", ".xdmf", ".msh", ".exo", ".inp", ".stl", ".off"]))
def test_random_bytes_as_a_peer_file_are_refused_by_path(tmp_path_factory, data, suffix):
    path = tmp_path_factory.mktemp("fuzz") / f"peer{suffix}"
    path.write_bytes(data)
    with pytest.raises(ValueError) as error:
        read_peer(path)
    assert str(error.value).startswith(str(path))


def test_a_damaged_or_mixed_mesh_is_refused(files, tmp_path):
    mesh = meshio.read(files["peer"])
    triangles = mesh.cells[0].data
    with pytest.raises(ValueError, match="2-D cells of two kinds"):
        read_peer(peer_with(files, tmp_path / "mixed.vtu", cells=[("triangle", triangles),
                                                                  ("quad", np.array([[0, 1, 5, 4]]))],
                            displacement=mesh.point_data["displacement"]))
    with pytest.raises(ValueError, match="cells refer to point 99, the file has points 0 to 15"):
        read_peer(peer_with(files, tmp_path / "damaged.vtu", cells=[("triangle", np.vstack([triangles, [0, 1, 99]]))],
                            displacement=np.zeros((16, 2))))
    points = mesh.points.copy()
    points[3, 0] = np.nan
    with pytest.raises(ValueError, match="1 of 16 points have NaN or infinite coordinates"):
        read_peer(peer_with(files, tmp_path / "nanpoint.vtu", points=points, displacement=np.zeros((16, 2))))
    with pytest.raises(ValueError, match=r"no triangle, quad, tetra or hexahedron cells \(found \['line'\]\)"):
        read_peer(peer_with(files, tmp_path / "lines.vtu", cells=[("line", np.array([[0, 1]]))],
                            displacement=np.zeros((16, 2))))


def test_a_peer_of_another_dimension_is_refused_before_the_solve(files, tmp_path, capsys):
    box = meshio.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]), [("tetra", np.array([[0, 1, 2, 3]]))],
                      point_data={"displacement": np.zeros((4, 3))})
    box.write(tmp_path / "box.vtu")
    refused(["compare", files["scene"], tmp_path / "box.vtu"], capsys, "box.vtu: a 3-D mesh against a 2-D scene",
            "a scene of the peer's dimension")


def test_a_peer_mesh_that_does_not_cover_the_body_says_how_much_is_outside(files, tmp_path):
    """A 5 × 5 peer with the cells of [0.2, 0.4]² removed: our node (1/3, 1/3) is in the hole, 0.094 from the
    nearest peer vertex (0.4, 0.4); our nodes on the hole's edge would be found (none here)."""
    fine = cc.solve(dataclasses.replace(load_scene(files["scene"]), body=cc.Body(cc.Rectangle(nx=5, ny=5))))
    write_vtk(fine, tmp_path / "fine.vtu")
    mesh = meshio.read(tmp_path / "fine.vtu")
    centres = mesh.points[mesh.cells[0].data].mean(axis=1)
    kept = mesh.cells[0].data[~((np.abs(centres[:, 0] - 0.3) < 0.1) & (np.abs(centres[:, 1] - 0.3) < 0.1))]
    meshio.write(tmp_path / "hole.vtu", meshio.Mesh(mesh.points, [("triangle", kept)], point_data=mesh.point_data))
    distance = np.hypot(0.4 - 1 / 3, 0.4 - 1 / 3)
    with pytest.raises(ValueError, match=rf"1 of 16 of our points \(6.2 %\) lie outside the peer's mesh, the "
                                         rf"farthest {distance:.3g} from the peer's nearest vertex"):
        compare_peer(files["result"], tmp_path / "hole.vtu")
    shifted = meshio.Mesh(mesh.points * [2.0, 1.0, 1.0], mesh.cells, point_data=mesh.point_data)
    meshio.write(tmp_path / "wide.vtu", shifted)
    with pytest.raises(ValueError, match="the same units and placement"):
        compare_peer(files["result"], tmp_path / "wide.vtu")


# --- compare: outputs -------------------------------------------------------------------------------------------

def test_out_is_checked_before_the_solve_and_replaced_only_with_overwrite(files, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "pressures.png").write_bytes(b"the user's picture")
    refused(["compare", files["scene"], files["peer"], "--out", out], capsys,
            f"error: --out: {out} already holds pressures.png", "--overwrite")
    assert (out / "pressures.png").read_bytes() == b"the user's picture"
    assert command(["compare", files["scene"], files["peer"], "--out", out, "--overwrite"], capsys)[0] == 0
    assert (out / "pressures.png").read_bytes()[:4] == b"\x89PNG"
    refused(["compare", files["scene"], files["peer"], "--out", files["scene"]], capsys,
            f"--out: {files['scene']} is a file", "give a folder")
    no_pressure = peer_with(files, tmp_path / "u_only.vtu",
                            displacement=meshio.read(files["peer"]).point_data["displacement"])
    refused(["compare", files["scene"], no_pressure, "--out", tmp_path / "new"], capsys,
            "--out: ", "drop --out, or name the peer's pressure with --pressure NAME")
    assert not (tmp_path / "new").exists()


# --- compare A.json B.json ----------------------------------------------------------------------------------------

def summary_with(files, path: Path, change) -> Path:
    data = json.loads(files["summary"].read_text())
    change(data)
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("change, problem", [
    (lambda d: d["contact_nodes"].pop("lambda_N"), "contact_nodes: no lambda_N"),
    (lambda d: d["contact_nodes"].update(lambda_N=[float("nan")] * 4), "contact_nodes.lambda_N: NaN or infinite"),
    (lambda d: d["contact_nodes"].update(lambda_N=[1, 2]), "contact_nodes.lambda_N: expected a list of 4 numbers"),
    (lambda d: d["contact_nodes"].update(x=["a"] * 4), "contact_nodes.x: expected a list of 4 numbers"),
    (lambda d: d["contact_nodes"].update(status=["touching"] * 4), "contact_nodes.status: unknown values ['touching']"),
    (lambda d: d.update(certificate="fine"), "certificate: expected an object of numbers"),
    (lambda d: d.pop("contact_nodes"), "no contact_nodes (status 'solved')"),
])
def test_damaged_summaries_name_the_key(files, tmp_path, capsys, change, problem):
    path = summary_with(files, tmp_path / "other.json", change)
    refused(["compare", files["summary"], path], capsys, f"error: {path}: {problem}", "")


def test_files_that_are_not_summaries_or_of_another_mesh(files, tmp_path, capsys):
    for name, content in (("text.json", b"{"), ("binary.json", bytes(range(256))), ("list.json", b"[1, 2]")):
        (tmp_path / name).write_bytes(content)
        refused(["compare", files["summary"], tmp_path / name], capsys, f"{tmp_path / name}: not a summary.json",
                "give the scene's .toml first")
    refused(["compare", tmp_path / "missing.json", files["summary"]], capsys, "missing.json: cannot read it",
            "check the path")
    refused(["compare", tmp_path / "missing.toml", files["peer"]], capsys, "error: toml: cannot read", "missing.toml")
    refused(["compare", files["summary"], files["peer"]], capsys, "peer.vtu: not a summary.json", "summary.json")
    finer = cc.solve(dataclasses.replace(load_scene(files["scene"]), body=cc.Body(cc.Rectangle(nx=4, ny=3))))
    finer.save(tmp_path / "finer", formats=("json",))
    refused(["compare", files["summary"], tmp_path / "finer" / "summary.json"], capsys,
            "its 5 contact nodes are not those of", "the same mesh and contact boundary")
    for option, value in (("--displacement", "u"), ("--pressure", "p"), ("--out", tmp_path / "o")):
        refused(["compare", files["summary"], files["summary"], option, value], capsys, f"error: {option}: ",
                "drop it")


@given(st.recursive(st.none() | st.booleans() | st.floats() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
                        st.sampled_from(["contact_nodes", "x", "y", "lambda_N", "status", "weight", "certificate"]),
                        inner, max_size=5), max_leaves=12))
def test_random_json_as_a_summary_is_refused_by_path(tmp_path_factory, files, data):
    path = tmp_path_factory.mktemp("json") / "summary.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError) as error:
        compare_files(files["summary"], path)
    assert str(error.value).startswith(str(path))


# --- study grid -------------------------------------------------------------------------------------------------

def grid_refused(files, tmp_path, start: str, fix: str, grid=None, **options):
    """run_grid refuses with a message starting ``start``, naming ``fix``, before any case: its first progress
    message ("N cases to solve …") is never said."""
    said = []
    scene = options.pop("scene", None) or load_scene(files["scene"])
    out = options.pop("out", tmp_path / "grid")
    with pytest.raises(ValueError) as error:
        run_grid(scene, {"contact.slip_bound": [0.001, 0.002]} if grid is None else grid, out,
                 **{"scheduler": "serial", "progress": said.append, **options})
    message = str(error.value)
    assert message.startswith(start) and fix in message, message
    assert said == []


@pytest.mark.parametrize("grid, start, fix", [
    ({"contact.nosuch": [1]}, "grid.contact.nosuch: not a parameter a grid can vary on this scene",
     "use one of contact.slip_bound, contact.regularization, body.nx, body.ny, body.element, obstacle.depth"),
    ({"contact.friction": [0.1]}, "grid.contact.friction: not a parameter", "contact.slip_bound"),
    ({"body.cells": [3]}, "grid.body.cells: not a parameter", "body.nx, body.ny"),
    ({"contact.stiffness": [1.0]}, "grid.contact.stiffness: not a parameter", "contact.slip_bound"),
    ({"dirichlet[left].ux": [0.1]}, "grid.dirichlet[left].ux: the scene has no [[dirichlet]] ux on 'left'",
     "add a [[dirichlet]] boundary = 'left'"),
    ({3: [1]}, "grid: expected str", "name each parameter by its path"),
    ({"body.nx": [-1]}, "grid.body.nx: expected a positive integer, got -1", "positive integer"),
    ({"body.nx": ["abc"]}, "grid.body.nx: expected a positive integer", "'abc'"),
    ({"contact.slip_bound": [float("nan")]}, "grid.contact.slip_bound: ", "finite"),
    ({"body.element": ["P7"]}, "grid.body.element: unknown element 'P7'", "use one of"),
    ({"body.nx": [3, 3.0]}, "grid.body.nx: 3.0 given twice", "give each value once"),
    ({"body.nx": []}, "grid.body.nx: no values", "give at least one"),
    ({"body.nx": 3}, "grid.body.nx: expected a list of values", "give e.g."),
    ({}, "grid: no parameter to vary", "give e.g."),
    ([("body.nx", [3])], "grid: expected Mapping", "give {"),
    ({"body.nx": [10**5], "body.ny": [10**5]}, "grid.body.nx: nx, ny = [100000, 100000] make about 2e+10 DOFs",
     "use fewer cells"),
    ({"body.nx": list(range(1, 501)), "body.ny": list(range(1, 301))}, "grid: 1.5e+05 cases (500 × 300)",
     "give fewer values"),
])
def test_grid_parameters_are_refused_before_any_case(files, tmp_path, grid, start, fix):
    grid_refused(files, tmp_path, start, fix, grid)


@pytest.mark.parametrize("options, start, fix", [
    ({"solver": "bogus"}, "solver: unknown 'bogus'", "use one of"),
    ({"formulation": "both"}, "formulation: unknown 'both'", "'auto'"),
    ({"workers": 0, "scheduler": None}, "workers: expected a number of local workers from 1", "start a cluster"),
    ({"workers": True, "scheduler": None}, "workers: expected a number of local workers", "give its scheduler"),
    ({"workers": 10**6, "scheduler": None}, "workers: expected a number of local workers", "start a cluster"),
    ({"workers": 1}, "workers: sizes the local cluster, but the scheduler is 'serial'", "leave the number of workers"),
    ({"scheduler": "garbage"}, "scheduler: 'garbage' is not an address", "tcp://HOST:8786"),
    ({"scheduler": "tcp://127.0.0.1:99999"}, "scheduler: 'tcp://127.0.0.1:99999' is not an address (port 99999",
     "'serial'"),
    ({"scheduler": 8786}, "scheduler: expected str", "tcp://HOST:8786"),
    ({"progress": "print"}, "progress: expected a function", "progress=print"),
    ({"scene": "patch.toml"}, "scene: expected Scene", "cc.scene.load_scene(path)"),
    ({"out": None}, "out: expected str or Path", "give a folder's path"),
])
def test_run_options_are_refused_before_any_case(files, tmp_path, options, start, fix):
    grid_refused(files, tmp_path, start, fix, **options)


def test_a_scene_with_a_history_is_refused(files, tmp_path):
    scene = load_scene(files["scene"])
    scene = dataclasses.replace(scene, history=cc.History([1.0, 2.0], {"obstacle.depth": [0.0, 0.01]}))
    grid_refused(files, tmp_path, "scene.history: a grid solves one static problem per case",
                 "vary its quantities as grid parameters", scene=scene)


def free_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Http(socketserver.BaseRequestHandler):
    """An HTTP server's first words (a dashboard's port given for the scheduler's)."""

    def handle(self):
        self.request.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")


@contextlib.contextmanager
def http_server():
    """A tiny HTTP answerer on 127.0.0.1 only: it stops on exit, and by itself after 20 s whatever happens."""
    server = socketserver.TCPServer(("127.0.0.1", 0), Http)
    server.timeout = 0.05
    stop = threading.Event()

    def serve():
        deadline = time.monotonic() + 20
        while not stop.is_set() and time.monotonic() < deadline:
            server.handle_request()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.server_address[1]}"
    finally:
        stop.set()
        thread.join()
        server.server_close()


def test_schedulers_that_do_not_answer_or_are_not_dask_are_refused(files, tmp_path, capsys):
    port = free_port()
    grid_refused(files, tmp_path, f"scheduler: nothing answers at tcp://127.0.0.1:{port}", "`dask scheduler`",
                 scheduler=f"tcp://127.0.0.1:{port}")
    with http_server() as address:
        grid_refused(files, tmp_path, f"scheduler: {address} answers, but not as a Dask scheduler",
                     "not its dashboard's port 8787", scheduler=address)
        refused(["study", "grid", files["scene"], "--param", "contact.slip_bound=0.001", "--scheduler", address],
                capsys, f"error: --scheduler: {address} answers, but not as a Dask scheduler", "'serial'")


def test_a_dask_worker_is_not_a_scheduler_and_its_scheduler_is_named(files, tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster:
        worker = next(iter(cluster.scheduler.workers))
        grid_refused(files, tmp_path, f"scheduler: {worker} is a Dask Worker, not a scheduler (its scheduler is "
                     f"{cluster.scheduler_address})", "'serial'", scheduler=worker)


def test_the_resume_table_must_be_ours_and_is_never_changed(files, tmp_path):
    out = tmp_path / "resume"
    out.mkdir()
    table = out / "grid.csv"
    for content, start in ((b"name,age\nada,36\n", "out: " + str(table) + " is not a grid table this study wrote "
                                                    "(its first line is 'name,age')"),
                           (bytes(range(256)), f"out: {table} is not a grid table this study wrote (UnicodeDecodeError"),
                           (b"", f"out: {table} is not a grid table this study wrote (its first line is ''")):
        table.write_bytes(content)
        grid_refused(files, tmp_path, start, "give another folder (the file is left as it is)", out=out)
        assert table.read_bytes() == content
    run_grid(load_scene(files["scene"]), {"body.nx": [3]}, out / "other", scheduler="serial", progress=None)
    before = digest(out / "other" / "grid.csv")
    grid_refused(files, tmp_path, f"out: {out / 'other' / 'grid.csv'} holds a grid over ['body.nx'], this one varies "
                 "['contact.slip_bound']", "give another folder", out=out / "other")
    assert digest(out / "other" / "grid.csv") == before
    grid_refused(files, tmp_path, f"out: {files['scene']} is a file", "give a folder", out=files["scene"])


@given(st.binary(max_size=300))
def test_random_bytes_in_the_resume_table_are_refused_and_kept(tmp_path_factory, files, data):
    out = tmp_path_factory.mktemp("resume")
    (out / "grid.csv").write_bytes(data)
    with pytest.raises(ValueError, match=f"^out: {out / 'grid.csv'} is not a grid table this study wrote"):
        run_grid(load_scene(files["scene"]), {"contact.slip_bound": [0.001]}, out, scheduler="serial", progress=None)
    assert (out / "grid.csv").read_bytes() == data


@pytest.mark.parametrize("arguments, start, fix", [
    (["--param", "contact.nosuch=1"], "error: --param contact.nosuch: not a parameter", "use one of"),
    (["--param", "body.nx=3,3"], "error: --param body.nx: 3 given twice", "give each value once"),
    (["--param", "contact.slip_bound=0.1", "--param", "contact.slip_bound=0.2"],
     "error: --param: contact.slip_bound given 2 times", "--param contact.slip_bound=V1,V2"),
    (["--param", "contact.slip_bound"], "argument --param: expected PATH=V1,V2,…", "contact.friction=0.1,0.2"),
    (["--param", "contact.slip_bound=0.1,,0.2"], "argument --param: expected PATH=V1,V2,…", "PATH=V1,V2"),
    (["--param", "body.nx=100000", "--param", "body.ny=100000"], "error: --param body.nx: nx, ny", "fewer cells"),
    (["--param", "contact.slip_bound=0.1", "--solver", "bogus"], "error: --solver: unknown 'bogus'", "use one of"),
    (["--param", "contact.slip_bound=0.1", "--formulation", "both"], "error: --formulation: unknown 'both'",
     "'auto'"),
    (["--param", "contact.slip_bound=0.1", "--workers", "0"], "error: --workers: expected a number of local workers",
     "start a cluster"),
    (["--param", "contact.slip_bound=0.1", "--workers", "two"], "argument --workers: invalid int value", "'two'"),
    (["--param", "contact.slip_bound=0.1", "--scheduler", "garbage"], "error: --scheduler: 'garbage' is not",
     "tcp://HOST:8786"),
    (["--param", "contact.slip_bound=0.1", "--scheduler", "serial", "--workers", "1"],
     "error: --workers: sizes the local cluster", "leave the number of workers out"),
])
def test_every_option_of_study_grid_refuses_a_bad_value_with_exit_2(files, tmp_path, capsys, arguments, start, fix):
    refused(["study", "grid", files["scene"], *arguments, "--out", tmp_path / "grid"], capsys, start, fix)
    assert not (tmp_path / "grid").exists()


def test_study_grid_out_and_scene_arguments(files, tmp_path, capsys):
    refused(["study", "grid", files["scene"], "--param", "contact.slip_bound=0.1", "--out", files["scene"]], capsys,
            f"error: --out: {files['scene']} is a file", "give a folder")
    refused(["study", "grid", tmp_path / "missing.toml", "--param", "contact.slip_bound=0.1"], capsys,
            "error: toml: cannot read", "missing.toml")


def test_imported_arrays_name_the_argument(files):
    from convexcontact.studies.crossvalidation.compare import Fields

    with pytest.raises(ValueError, match=r"^pressure: expected an array of numbers"):
        Fields.from_arrays(files["result"], pressure=["high"] * 4)
    with pytest.raises(ValueError, match=r"^displacement: contains NaN or infinity \(\d+ of \d+ values\) — give the finite"):
        Fields.from_arrays(files["result"], pressure=np.ones(4), displacement=np.full(files["result"].fem.basis.N,
                                                                                        np.nan))
