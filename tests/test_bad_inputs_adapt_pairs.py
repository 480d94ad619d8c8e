"""Bad input to the adaptive loop now that it takes pairs and subdomains (``convexcontact run SCENE --adapt`` and the
Python ``convexcontact.drivers.adapt.adapt``, not in ``cc.__all__``): what is still refused is refused before any
solve, exit code 2 and ``error: FIELD: … fix`` (a SceneError from Python), every file as it was."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import skfem as fe
from hypothesis import given, settings
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact import cli
from convexcontact.drivers.adapt import adapt
from convexcontact.scene.bodies_library import two_spheres
from convexcontact.scene.description import SceneError

SURFACES = ("convexcontact run",)

PAIR = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "punch_on_foundation.toml"

DISC = """name = "disc"
[body]
mesh = "disc.msh"
element = "P2"
[material]
E = 1.0
nu = 0.3
[[dirichlet]]
boundary = "top"
ux = 0.0
uy = -0.01
[contact]
boundary = "bottom"
law = "signorini"
[obstacle]
shape = "flat"
gap = 0.0
"""


def curved_disc() -> fe.Mesh:
    """A disc of quadratic triangles whose edge nodes lie on the circle: curved cells."""
    return fe.MeshTri2.init_circle(2).with_boundaries({"bottom": lambda x: x[1] < -0.7, "top": lambda x: x[1] > 0.7})


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A working folder holding the curved disc's mesh and scene; no solve may start."""
    monkeypatch.setattr("convexcontact.drivers.adapt.solve", lambda *a, **k: pytest.fail("solved a bad input"))
    curved_disc().save(str(tmp_path / "disc.msh"))
    (tmp_path / "disc.toml").write_text(DISC)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def digest(folder: Path) -> dict:
    return {path.name: hashlib.sha1(path.read_bytes()).hexdigest() for path in folder.iterdir()}


def refused(capsys, folder: Path, arguments: list, *texts: str) -> None:
    """Exit code 2, ``error: …`` holding ``texts`` on stderr, no level solved, every file as it was."""
    before = digest(folder)
    try:
        code = cli.main(["run", *arguments])
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    printed = capsys.readouterr()
    assert code == 2 and "error: " in printed.err and "Traceback" not in printed.err, printed.err
    assert "level 0" not in printed.out
    for text in texts:
        assert text in printed.err, printed.err
    assert digest(folder) == before


def test_a_curved_quadratic_mesh_is_refused_naming_the_geometry(folder):
    """scikit-fem splits straight cells: refining a curved MeshTri2 would lose its curve (a straight one is taken as
    its linear mesh, the P2 element adding the middle nodes back)."""
    scene = cc.Scene(body=cc.Body(curved_disc(), "P2"), materials=cc.Material(1.0, 0.3),
                     dirichlet=[cc.Dirichlet("top", ux=0.0, uy=-0.01)],
                     contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0)))
    with pytest.raises(SceneError, match="^body.geometry: a MeshTri2 with curved edges.*give a mesh with straight edges"):
        adapt(scene)


def test_run_adapt_refuses_a_curved_quadratic_mesh_file(capsys, folder):
    refused(capsys, folder, ["disc.toml", "--adapt"], "error: body.geometry: a MeshTri2 with curved edges",
            "gmsh: element order 1")


@pytest.mark.parametrize("option, value", [("--target", "0"), ("--target", "1"), ("--target", "nan"),
                                           ("--target", "-1e-3"), ("--max-dofs", "0"), ("--max-dofs", "-10"),
                                           ("--max-dofs", "2.5"), ("--max-dofs", "many")])
def test_run_adapt_on_a_pair_refuses_bad_limits(capsys, folder, option, value):
    refused(capsys, folder, [str(PAIR), "--adapt", f"{option}={value}"], option)


@settings(max_examples=15, deadline=None)
@given(st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.0), st.just(float("nan"))))
def test_adapt_on_a_pair_refuses_any_target_that_is_no_fraction(value):
    with pytest.raises(ValueError, match="^target: a relative energy error in \\(0, 1\\).*e.g. 1e-2"):
        adapt(two_spheres(cells=2), target=value)
