"""TOML scene files: the examples load into the expected dataclasses, bad input names its field."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from convexcontact.drivers.solve import solve
from convexcontact.scene import (
    Body,
    Contact,
    Dirichlet,
    Material,
    MeshFile,
    Obstacle,
    Rectangle,
    Scene,
    SceneError,
    Signorini,
    Traction,
    load_scene,
    scene_from_dict,
)
from convexcontact.scene.toml import tomllib

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


def hertz(nx: int = 80, ny: int = 40) -> Scene:
    """examples/scenes/hertz.toml built in Python."""
    return Scene(
        name="hertz",
        body=Body(
            Rectangle(
                width=4.0, height=2.0, origin=(-2.0, -2.0), nx=nx, ny=ny,
                grading=(10.0, 10.0), refine_x=0.0, refine_y="top",
            ),
            element="P1",
            plane="strain",
        ),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=[Dirichlet("bottom", ux=0.0, uy=0.0)],
        contact=Contact(
            boundary="top",
            obstacle=Obstacle(shape="parabolic", radius=1.0, center=0.0, force=0.0086307),
            law=Signorini(non_penetration="nodal"),
        ),
    )


EXPECTED = {
    "hertz": hertz(),
    "patch": Scene(
        name="patch",
        body=Body(Rectangle(width=2.0, height=1.0, nx=8, ny=4)),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=[Dirichlet("left", ux=0.0)],
        tractions=[Traction("top", pressure=0.1)],
        contact=Contact(boundary="bottom", obstacle=Obstacle(shape="flat", gap=0.0)),
    ),
    "flat_punch_weak": Scene(
        name="flat_punch_weak",
        body=Body(
            Rectangle(width=4.0, height=2.0, origin=(-2.0, -2.0), nx=40, ny=20, grading=(4.0, 4.0), refine_x=0.0)
        ),
        materials=Material(E=1.0, nu=0.3),
        dirichlet=[Dirichlet("bottom", ux=0.0, uy=0.0)],
        contact=Contact(
            boundary="top",
            obstacle=Obstacle(shape="expression", expression="maximum(abs(x) - 0.5, 0)**2 / (2*0.5) - 0.01"),
            law=Signorini(non_penetration="weak"),
        ),
    ),
}


def hertz_data() -> dict:
    return tomllib.loads((SCENES / "hertz.toml").read_text())


def load_text(tmp_path: Path, text: str) -> Scene:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return load_scene(path)


# --------------------------------------------------------------------------- examples


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_loads_into_expected_dataclasses(name):
    scene = load_scene(SCENES / f"{name}.toml")
    expected = EXPECTED[name]
    for field in ("name", "body", "materials", "dirichlet", "tractions", "body_force", "contact"):
        assert getattr(scene, field) == getattr(expected, field), field
    assert scene == expected


def test_patch_example_contact_pressure_equals_applied_pressure():
    result = solve(load_scene(SCENES / "patch.toml"))
    assert result.status == "solved"
    assert np.allclose(result.contact.pressure, 0.1, rtol=1e-6)


def test_hertz_toml_and_python_scenes_solve_identically():
    data = hertz_data()
    data["body"].update(nx=20, ny=10)
    from_toml = scene_from_dict(data, SCENES)
    from_python = hertz(nx=20, ny=10)
    assert from_toml == from_python
    u_toml, u_python = solve(from_toml).displacement, solve(from_python).displacement
    assert np.array_equal(u_toml, u_python)


def test_name_defaults_to_file_stem(tmp_path):
    text = (SCENES / "patch.toml").read_text().replace('name = "patch"', "")
    assert load_text(tmp_path, text).name == "scene"  # the file is scene.toml


def test_mesh_path_is_relative_to_the_toml_folder(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "part.msh").write_text("")  # only its existence is checked when loading
    text = (SCENES / "patch.toml").read_text()
    body = text[text.index("[body]") : text.index("[material]")]
    scene = load_text(tmp_path, text.replace(body, '[body]\nmesh = "meshes/part.msh"\nelement = "P2"\n\n'))
    assert scene.body == Body(MeshFile(tmp_path / "meshes" / "part.msh"), element="P2")


def test_materials_per_subdomain():
    data = hertz_data()
    del data["material"]
    data["materials"] = {"steel": {"E": 210.0, "nu": 0.3}, "rubber": {"E": 1.0, "nu": 0.45}}
    scene = scene_from_dict(data, SCENES)
    assert scene.materials == {"steel": Material(210.0, 0.3), "rubber": Material(1.0, 0.45)}


# --------------------------------------------------------------------------- bad input


def test_malformed_toml_names_file_line_and_column(tmp_path):
    with pytest.raises(SceneError) as error:
        load_text(tmp_path, 'name = "x"\n[body]\nnx = 10 10\n')
    assert error.value.field == "toml"
    assert "scene.toml" in str(error.value)
    assert "line 3, column 9" in str(error.value)


def test_missing_file(tmp_path):
    with pytest.raises(SceneError) as error:
        load_scene(tmp_path / "absent.toml")
    assert error.value.field == "toml"


def edit(path: str, value=None, delete: bool = False):
    """A change to the hertz data: set (or delete) the key at dotted ``path``."""

    def apply(data):
        *tables, key = path.split(".")
        for table in tables:
            data = data[table][0] if isinstance(data[table], list) else data[table]
        if delete:
            del data[key]
        else:
            data[key] = value

    return apply


BAD = [
    # unknown keys (typos are never ignored)
    (edit("body.nxx", 10), "body.nxx"),
    (edit("material.young", 1.0), "material.young"),
    (edit("dirichlet.uz", 0.0), "dirichlet[bottom].uz"),
    (edit("contact.friction", 0.3), "contact.friction"),
    (edit("obstacle.gap", 0.0), "obstacle.gap"),  # not a key of a parabolic punch
    (edit("dirichlet.body_force", [0.0, 0.0]), "dirichlet[bottom].body_force"),  # top-level key after a header
    (edit("body.mesh", "part.msh"), "body.width"),  # rectangle keys with a mesh file
    (edit("gravity", 9.81), "gravity"),
    # wrong types
    (edit("body.nx", "ten"), "body.nx"),
    (edit("body.nx", 10.5), "body.nx"),
    (edit("body.nx", True), "body.nx"),
    (edit("material.E", "1.0"), "material.E"),
    (edit("body.origin", [-2.0]), "body.origin"),
    (edit("body.origin", [-2.0, "0"]), "body.origin"),
    (edit("obstacle.shape", 1), "obstacle.shape"),
    (edit("contact.law", 1), "contact.law"),
    (edit("dirichlet", {"boundary": "bottom", "ux": 0.0}), "dirichlet"),  # [dirichlet] for [[dirichlet]]
    (edit("body", "rectangle"), "body"),
    # missing required keys
    (edit("body", delete=True), "body"),
    (edit("material", delete=True), "material"),
    (edit("dirichlet", delete=True), "dirichlet"),
    (edit("contact", delete=True), "contact"),
    (edit("contact.boundary", delete=True), "contact.boundary"),
    (edit("body.mesh", delete=True), "body.mesh"),
    (edit("material.nu", delete=True), "material.nu"),
    (edit("dirichlet.boundary", delete=True), "dirichlet[0].boundary"),
    (edit("materials", {"steel": {"E": 1.0, "nu": 0.3}}), "material"),  # both forms
    # values the model refuses
    (edit("material.nu", 0.5), "material.nu"),
    (edit("material.nu", -1.0), "material.nu"),
    (edit("material.E", 0.0), "material.E"),
    (edit("material.E", float("nan")), "material.E"),
    (edit("obstacle.force", float("nan")), "obstacle.force"),
    (edit("obstacle.radius", float("inf")), "obstacle.radius"),
    (edit("body.width", float("nan")), "body.width"),
    (edit("dirichlet.ux", float("nan")), "dirichlet[bottom].ux"),
    (edit("obstacle.shape", "cone"), "obstacle.shape"),
    (edit("body.element", "P3"), "body.element"),
    (edit("contact.non_penetration", "strong"), "contact.non_penetration"),
    # unknown law
    (edit("contact.law", "mohr-coulomb"), "contact.law"),
]


@pytest.mark.parametrize(("change", "field"), BAD, ids=[f"{i}-{field}" for i, (_, field) in enumerate(BAD)])
def test_bad_input_names_the_field(change, field):
    data = copy.deepcopy(hertz_data())
    change(data)
    with pytest.raises(SceneError) as error:
        scene_from_dict(data, SCENES)
    assert error.value.field == field


def test_nan_in_toml_text_is_refused(tmp_path):
    text = (SCENES / "hertz.toml").read_text().replace("nu = 0.3", "nu = nan")
    with pytest.raises(SceneError) as error:
        load_text(tmp_path, text)
    assert error.value.field == "material.nu"


def test_unknown_key_lists_allowed_keys_and_suggests():
    data = hertz_data()
    data["body"]["nxx"] = 10
    with pytest.raises(SceneError, match=r"did you mean 'nx'\?.*width, height, origin, nx, ny"):
        scene_from_dict(data, SCENES)


def test_unknown_law_lists_available_laws():
    data = hertz_data()
    data["contact"]["law"] = "mohr-coulomb"  # a typo or an unsupported law
    with pytest.raises(SceneError, match="available laws: signorini"):
        scene_from_dict(data, SCENES)


@pytest.mark.parametrize("key", ["body", "material", "dirichlet", "contact", "contact.boundary"])
def test_missing_key_shows_an_example(key):
    data = hertz_data()
    edit(key, delete=True)(data)
    with pytest.raises(SceneError, match="for example") as error:
        scene_from_dict(data, SCENES)
    assert error.value.field == key


def test_missing_mesh_file():
    data = hertz_data()
    data["body"] = {"mesh": "absent.msh"}
    with pytest.raises(SceneError) as error:
        scene_from_dict(data, SCENES)
    assert error.value.field == "body.mesh"
