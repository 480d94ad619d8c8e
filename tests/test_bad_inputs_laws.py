"""Issue 24, laws and options: every numeric field of the law, obstacle and material dataclasses, every string
option, the formulation's choice, the scene file's obstacle and mesh files — a bad value is a SceneError that starts
with the field's name and names a fix, raised before any work; values that only the assembled problem can judge
(beside the body's size, stiffness and load) are refused before a program is built."""

import dataclasses
import math

import meshio
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact.scene.description import SHAPE_FIELDS
from convexcontact.scene.library import hertz_punch, pressure_patch
from convexcontact.scene.toml import scene_from_dict

SURFACES = ("cc.Signorini", "cc.Tresca", "cc.Coulomb", "cc.NormalCompliance", "cc.Obstacle", "cc.Contact",
            "cc.Material", "cc.Body", "cc.MeshFile", "cc.Rectangle", "cc.Box", "cc.Dirichlet", "cc.Traction",
            "cc.Scene", "cc.solve", "cc.prepare", "cc.Model", "cc.library", "cc.load_scene", "cc.scene.load_scene",
            "reader mesh", "reader toml")

PATCH = pressure_patch(nx=3)


def refused(build, field: str, *words: str) -> str:
    """``build()`` raises a SceneError of ``field`` whose message starts with it and carries a fix and ``words``."""
    with pytest.raises(cc.SceneError) as error:
        build()
    message = str(error.value)
    assert error.value.field == field and message.startswith(field + ":"), message
    assert " — " in message and all(word in message for word in words), message
    return message


def punch(obstacle, law=None, nx=8):
    """The Hertz block [-2, 2] × [-2, 0] pressed on its top by ``obstacle``."""
    return dataclasses.replace(hertz_punch(nx=nx), contact=cc.Contact("top", obstacle, law or cc.Signorini()))


# (builder of the value's owner, field, whether a negative value is wrong)
NUMBERS = [
    (lambda v: cc.Material(v, 0.3), "material.E", True),
    (lambda v: cc.Material(1.0, v), "material.nu", True),
    (lambda v: cc.Material(1.0, 0.3, viscosity=v), "material.viscosity", True),
    (lambda v: cc.Obstacle("flat", gap=v), "obstacle.gap", False),
    (lambda v: cc.Obstacle("parabolic", radius=v), "obstacle.radius", True),
    (lambda v: cc.Obstacle("parabolic", radius=1.0, depth=v), "obstacle.depth", False),
    (lambda v: cc.Obstacle("parabolic", radius=1.0, force=v), "obstacle.force", True),
    (lambda v: cc.Obstacle("parabolic", radius=1.0, center=v), "obstacle.center", False),
    (lambda v: cc.Obstacle("flat", tangential_force=v), "obstacle.tangential_force", False),
    (lambda v: cc.Signorini("gauss", v), "contact.order", True),
    (lambda v: cc.NormalCompliance(1.0, non_penetration="gauss", order=v), "contact.order", True),
    (lambda v: cc.NormalCompliance(v), "contact.stiffness", True),
    (lambda v: cc.NormalCompliance(1.0, v), "contact.exponent", True),
    (lambda v: cc.Tresca(v), "contact.slip_bound", True),
    (lambda v: cc.Tresca(0.1, regularization=v), "contact.regularization", True),
    (lambda v: cc.Coulomb(v), "contact.friction", True),
    (lambda v: cc.Coulomb(0.3, smoothing_radius=v), "contact.smoothing_radius", True),
    (lambda v: cc.Coulomb(0.3, relaxation=v), "contact.relaxation", True),
    (lambda v: cc.Coulomb(0.3, tol=v), "contact.tol", True),
    (lambda v: cc.Coulomb(0.3, max_iterations=v), "contact.max_iterations", True),
    (lambda v: cc.Coulomb(0.3, acceleration=v), "contact.acceleration", True),
    (lambda v: cc.Coulomb(0.3, initial_pressure=v), "contact.initial_pressure", True),
]
CAPS = ("contact.max_iterations", "contact.acceleration")
"""Limits that a huge integer leaves as they are meant (the map stops on its own criteria first)."""
NOT_NUMBERS = [math.nan, math.inf, -math.inf, True, "high", [1.0, "a"], {"x": 1}, 10**400]


@pytest.mark.parametrize("build, field, negative", NUMBERS, ids=[field for _, field, _ in NUMBERS])
@given(value=st.one_of(st.sampled_from(NOT_NUMBERS), st.floats(allow_nan=True).filter(lambda x: not math.isfinite(x)),
                       st.floats(max_value=-1.5, allow_infinity=False)))
def test_every_numeric_field_refuses_what_is_no_value_of_it(build, field, negative, value):
    """NaN, infinity, booleans, strings, containers, integers beyond the floats — and negatives where the field is
    a size, a stiffness or a coefficient — are refused by the dataclass, under the field's name."""
    if isinstance(value, float) and math.isfinite(value) and not negative or value == 10**400 and field in CAPS:
        build(value)  # a negative depth, gap, centre or tangential force means something, a huge cap too: accepted
        return
    with pytest.raises(cc.SceneError) as error:
        build(value)
    assert error.value.field == field and str(error.value).startswith(field), str(error.value)


@pytest.mark.parametrize("build, field, listed", [
    (lambda: cc.Signorini("gaus"), "contact.non_penetration", "'nodal', 'weak', 'gauss'"),
    (lambda: cc.Signorini(["nodal"]), "contact.non_penetration", "'nodal', 'weak', 'gauss'"),
    (lambda: cc.NormalCompliance(1.0, non_penetration="weak"), "contact.non_penetration", "'nodal', 'gauss'"),
    (lambda: cc.Tresca(0.1, non_penetration="gauss"), "contact.non_penetration", "'nodal' or 'weak'"),
    (lambda: cc.Tresca(0.1, quadrature=None), "contact.quadrature", "'nodal', 'gauss'"),
    (lambda: cc.Coulomb(0.3, quadrature="lumped"), "contact.quadrature", "'nodal', 'gauss'"),
    (lambda: cc.Coulomb(0.3, newton="yes"), "contact.newton", "true or false"),
    (lambda: cc.Obstacle("cone"), "obstacle.shape", "'flat', 'parabolic', 'cylinder', 'sphere', 'flat_punch'"),
    (lambda: cc.Obstacle(normal="outward"), "obstacle.normal", "'body', 'obstacle'"),
    (lambda: cc.Body(cc.Rectangle(), "P3"), "body.element", "'P1', 'P2', 'Q1', 'Q2'"),
    (lambda: cc.Body(cc.Rectangle(), plane="axisymmetric"), "body.plane", "'strain', 'stress'"),
    (lambda: cc.Rectangle(refine_y="left"), "body.refine_y", "'top' or 'bottom'"),
    (lambda: cc.Material(1.0, 0.3, name=3), "material.name", "subdomain"),
    (lambda: cc.prepare(PATCH, "mixed"), "formulation", "use one of 'primal', 'dual', 'dual-matrix-free', 'auto'"),
    (lambda: cc.solve(PATCH, solutions="some"), "solutions", "'one'"),
])
def test_an_unknown_option_lists_the_valid_ones(build, field, listed):
    refused(build, field, listed)


@pytest.mark.parametrize("shape, needs", [("flat", {}), ("parabolic", {"radius": 1.0}), ("cylinder", {"radius": 1.0}),
                                          ("sphere", {"radius": 1.0}), ("flat_punch", {"radius": 0.5}),
                                          ("expression", {"expression": "x**2"})])
@pytest.mark.parametrize("name, value", [("gap", 0.1), ("radius", 0.5), ("center", 0.25), ("expression", "x")])
def test_a_field_the_shape_does_not_read_is_refused_alike_in_python_and_toml(shape, needs, name, value):
    """A gap given to a punch was ignored in Python (TOML refused it): one check now, one message for both."""
    if name in SHAPE_FIELDS[shape] or name in needs:
        return
    table = {"shape": shape, **needs, name: value}
    in_python = refused(lambda: cc.Obstacle(**table), f"obstacle.{name}", f"shape = {shape!r} reads")
    in_toml = refused(lambda: scene_from_dict({**TOML, "obstacle": table}), f"obstacle.{name}")
    assert in_python == in_toml


TOML = {"body": {"mesh": "rectangle", "nx": 3, "ny": 3}, "material": {"E": 1.0, "nu": 0.3},
        "dirichlet": [{"boundary": "bottom", "ux": 0.0, "uy": 0.0}], "contact": {"boundary": "top"}}


@pytest.mark.parametrize("table, field, words", [
    ({"contact": {"boundary": "top", "non_penetration": "gauss", "order": 10**6}}, "contact.order", ["1 to 24"]),
    ({"obstacle": {"shape": "flat_punch", "radius": 0.5, "gap": 0.0}}, "obstacle.gap", ["flat"]),
    ({"obstacle": {"shape": "cylinder", "radius": 1.0, "depth": 1.0, "normal": "obstacle"}}, "obstacle.depth",
     ["below the radius"]),
    ({"contact": {"boundary": "top", "law": "coulomb", "friction": 0.3, "tol": 2.0}}, "contact.tol", ["(0, 1)"]),
])
def test_the_scene_file_names_the_same_fields(table, field, words):
    refused(lambda: scene_from_dict({**TOML, **table}), field, *words)


def test_the_gauss_rule_is_bounded_by_what_the_element_can_mean():
    """Order 10⁶ asked for 1.8 TiB: refused by the law (no element means it), and beyond 4 × the element's degree
    on the assembled body, with the range of each element; the highest order allowed solves the patch exactly."""
    refused(lambda: cc.Signorini("gauss", 10**6), "contact.order", "1 to 24", "P1 1 to 4")
    refused(lambda: cc.prepare(pressure_patch(nx=3, law=cc.Signorini("gauss", 5))), "contact.order",
            "2-D TriP1 body: 1 to 4")
    highest = cc.solve(pressure_patch(nx=3, law=cc.Signorini("gauss", 4)))
    assert highest.status == "solved" and np.allclose(highest.contact.pressure, 0.1, rtol=1e-8)


@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
@pytest.mark.parametrize("depth", [1.0, 1.5, 2.5])
def test_a_closest_point_normal_behind_the_centre_is_refused(shape, depth):
    """depth ≥ R puts the centre on or behind Γ_C: NaN normals at the axis (scipy's 'must not contain infs or
    NaNs') or a 'solved' zero force. Refused, naming the point where the normal is undefined and the fix."""
    refused(lambda: cc.Obstacle(shape, radius=1.0, depth=depth, normal="obstacle"), "obstacle.depth",
            "obstacle.center", "depth below the radius", "normal = 'body'")


@pytest.mark.parametrize("scene, field, words", [
    (lambda: pressure_patch(nx=3, law=cc.NormalCompliance(1e300)), "contact.stiffness", ["give c_N between"]),
    (lambda: pressure_patch(nx=3, law=cc.NormalCompliance(1e-300)), "contact.stiffness", ["Signorini()"]),
    (lambda: pressure_patch(nx=3, law=cc.NormalCompliance(1.0, 1e300)), "contact.exponent", ["beyond the floats"]),
    (lambda: pressure_patch(nx=3, law=cc.Tresca(1e300)), "contact.slip_bound", ["bonded contact"]),
    (lambda: pressure_patch(nx=3, law=cc.Tresca(0.01, regularization=1e300)), "contact.regularization",
     ["body's size L = 1"]),
    (lambda: pressure_patch(nx=3, law=cc.Coulomb(1e9)), "contact.friction", ["at most 1e+06"]),
    (lambda: pressure_patch(nx=3, law=cc.Coulomb(lambda x, y: 1e9 + 0 * x)), "contact.friction", ["at most 1e+06"]),
    (lambda: pressure_patch(nx=3, law=cc.Coulomb(0.3, smoothing_radius=1e300)), "contact.smoothing_radius",
     ["give ρ ≤ L"]),
    (lambda: pressure_patch(nx=3, law=cc.Coulomb(0.3, initial_pressure=1e300)), "contact.initial_pressure",
     ["bonded contact"]),
    (lambda: punch(cc.Obstacle("parabolic", radius=1e-12, depth=0.01)), "obstacle.radius", ["the solvers lose it"]),
    (lambda: punch(cc.Obstacle("parabolic", radius=1e-300, depth=0.01)), "obstacle.radius", ["the solvers lose it"]),
    (lambda: punch(cc.Obstacle("parabolic", radius=1.0, depth=0.01, center=1e300)), "obstacle.center",
     ["beyond the floats"]),
    (lambda: punch(cc.Obstacle("parabolic", radius=1.0, force=1e-13)), "obstacle.force", ["or at least 4e-12"]),
    (lambda: dataclasses.replace(PATCH, contact=cc.Contact("bottom", cc.Obstacle("flat", gap=1e300))),
     "obstacle.gap", ["never touches"]),
])
def test_what_the_assembled_problem_cannot_resolve_is_refused_before_a_program(scene, field, words, monkeypatch):
    """Values that mean something alone but not beside the body and its loads (they were 'inaccurate' with a
    certificate of 1e269, 'failed', 'unbounded', 'infeasible', or an OverflowError): refused before any program."""
    monkeypatch.setattr("convexcontact.formulations.FORMULATIONS", {})  # building a program here fails the test
    refused(lambda: cc.prepare(scene(), "primal"), field, *words)


MAGNITUDES = st.integers(-300, 300).map(lambda k: 10.0**k)


@given(case=st.sampled_from(["stiffness", "slip_bound", "friction"]), value=MAGNITUDES)
def test_any_magnitude_is_refused_by_name_or_solved_and_certified(case, value):
    """A coefficient of any magnitude: a SceneError naming it, or an answer the certificate passes — never a NaN,
    an overflow, 'failed' or 'unbounded' on a scene that has an answer."""
    law = {"stiffness": lambda: cc.NormalCompliance(value), "slip_bound": lambda: cc.Tresca(value),
           "friction": lambda: cc.Coulomb(value)}[case]()
    try:
        result = cc.solve(pressure_patch(nx=3, law=law))
    except cc.SceneError as error:
        assert error.field == f"contact.{case}", str(error)
        return
    assert result.status == "solved" and result.certificate.passes(1e-6), (result.status, result.message)
    assert np.isfinite(result.displacement).all()


FORCED = punch(cc.Obstacle("parabolic", radius=1.0, force=0.001))
DEPTH = punch(cc.Obstacle("parabolic", radius=1.0, depth=0.01))


@pytest.mark.parametrize("scene, solver, words", [
    (FORCED, "auto", ["obstacle.force", "'dual', 'primal' or 'auto'"]),
    (punch(cc.Obstacle("parabolic", radius=1.0, depth=0.01, tangential_force=1e-4), cc.Tresca(0.01)), "auto",
     ["obstacle.tangential_force", "'dual', 'primal' or 'auto'"]),
    (punch(cc.Obstacle("parabolic", radius=1.0, depth=0.01), cc.Tresca(0.01, regularization=1e-3)), "auto",
     ["contact.regularization"]),
    (punch(cc.Obstacle("parabolic", radius=1.0, depth=0.01), cc.NormalCompliance(10.0)), "auto",
     ["primal only", "'primal' or 'auto'"]),
    (DEPTH, "clarabel", ["only newton-cg", "solver='newton-cg'"]),
    (DEPTH, "cvxpy:SCS", ["only newton-cg", "'dual', 'primal' or 'auto' with cvxpy:SCS"]),
])
def test_the_matrix_free_dual_where_it_cannot_apply_names_the_formulation(scene, solver, words, monkeypatch):
    """It sent the user from newton-cg ('use clarabel') to Clarabel ('needs P as a matrix'): now one refusal under
    'formulation', before any assembly, with the formulations that apply."""
    monkeypatch.setattr("convexcontact.drivers.prepared.assemble", lambda scene: pytest.fail("assembled"))
    refused(lambda: cc.solve(scene, solver, formulation="dual-matrix-free"), "formulation", *words)


def test_the_dual_with_compliance_is_refused_before_assembly(monkeypatch):
    monkeypatch.setattr("convexcontact.drivers.prepared.assemble", lambda scene: pytest.fail("assembled"))
    refused(lambda: cc.prepare(pressure_patch(nx=3, law=cc.NormalCompliance(10.0)), "dual"), "formulation",
            "'primal' or 'auto'")


def test_the_cvxpy_model_of_a_matrix_free_model_names_the_formulations_that_have_one():
    """prepare(scene, 'dual-matrix-free').cvxpy() was a TypeError; the fix it names works: the 'dual' model's
    cvxpy problem gives the matrix-free answer."""
    refused(lambda: cc.prepare(DEPTH, "dual-matrix-free").cvxpy(), "formulation", "prepare(scene, 'dual')")
    matrix_free = cc.prepare(DEPTH, "dual-matrix-free").solve()
    model = cc.prepare(DEPTH, "dual")
    edited = model.cvxpy()
    result = model.solve("cvxpy", cvxpy_model=edited)
    assert matrix_free.status == "solved" and result.solved
    assert np.abs(result.displacement - matrix_free.displacement).max() < 1e-6 * np.abs(matrix_free.displacement).max()


@pytest.mark.parametrize("path", [None, 3, b"scene.toml", ["scene.toml"]])
def test_load_scene_refuses_what_is_no_path(path):
    refused(lambda: cc.load_scene(path), "path", "load_scene('scene.toml')")


def test_what_the_messages_tell_the_user_to_call_exists():
    """cc.solve('x.toml') says to call cc.load_scene: the package exports it; the geometry and law classes are
    exported alike from cc and cc.scene (cc.Rectangle was, Box was in neither)."""
    message = refused(lambda: cc.solve("x.toml"), "scene", "cc.load_scene(path)")
    assert "cc.load_scene" in message and cc.load_scene is cc.scene.load_scene and "load_scene" in cc.__all__
    classes = {name for name in cc.scene.__all__ if name[0].isupper()}
    assert {"Box", "Rectangle", "MeshFile", "Signorini", "Tresca", "Coulomb", "NormalCompliance"} <= classes
    assert classes <= set(cc.__all__) and all(getattr(cc, name) is getattr(cc.scene, name) for name in classes)


@pytest.mark.parametrize("build, field, words", [
    (lambda: cc.library.hertz_punch(nx=1), "nx", ["nx ≥ 2"]),
    (lambda: cc.library.hertz_punch(nx="8"), "nx", ["positive integer"]),
    (lambda: cc.library.tresca_punch(nx=0), "nx", ["positive integer"]),
    (lambda: cc.library.frictional_punch(h=0.0), "h", ["positive"]),
    (lambda: cc.library.frictional_punch(h=math.nan), "h", ["finite"]),
    (lambda: cc.library.frictional_punch(h=1e-9), "h", ["GiB available"]),
    (lambda: cc.library.punch_mesh(0.2), "h", ["at most fine = 0.15"]),
    (lambda: cc.library.whole_face(dim=4), "dim", ["2 or 3"]),
    (lambda: cc.library.whole_face(nodes=-5), "nodes", ["positive integer"]),
    (lambda: cc.library.whole_face(dofs=math.nan), "dofs", ["finite"]),
])
def test_the_library_checks_its_sizes_where_they_enter(build, field, words):
    """h = 0 divided by zero, h = 1e-9 allocated 92 GiB, nodes = -5 was silently raised to 2."""
    refused(build, field, *words)


def write_msh(path, points, cells):
    meshio.Mesh(points, cells).write(path, file_format="gmsh22", binary=False)


@given(data=st.binary(min_size=0, max_size=200), suffix=st.sampled_from([".msh", ".vtk", ".xdmf", ".inp"]))
def test_a_mesh_file_of_garbage_is_named(tmp_path_factory, data, suffix):
    path = tmp_path_factory.mktemp("garbage") / f"body{suffix}"
    path.write_bytes(data)
    with pytest.raises(cc.SceneError) as error:
        cc.prepare(dataclasses.replace(PATCH, body=cc.Body(cc.MeshFile(path))))
    assert error.value.field == "body.mesh" and str(path) in str(error.value)


def test_a_mesh_file_of_lines_only_is_named(tmp_path):
    path = tmp_path / "wire.msh"
    write_msh(path, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), [("line", np.array([[0, 1]]))])
    refused(lambda: cc.prepare(dataclasses.replace(PATCH, body=cc.Body(cc.MeshFile(path)))), "body.mesh",
            "1-D", "tetrahedra")


@pytest.mark.parametrize("build, field, words", [
    (lambda: cc.Rectangle(width=math.nan), "body.width", ["finite"]),
    (lambda: cc.Rectangle(height=-1.0), "body.height", ["positive"]),
    (lambda: cc.Rectangle(origin=(0.0,)), "body.origin", ["2 finite numbers"]),
    (lambda: cc.Rectangle(grading=(0.5, 1.0)), "body.grading", ["uniform"]),
    (lambda: cc.Rectangle(nx=2.5), "body.nx", ["whole number"]),
    (lambda: cc.Box(size=(1.0, 1.0)), "body.size", ["3 finite numbers"]),
    (lambda: cc.Box(size=(1e200, 1e200, 1e200)), "body.size", ["length unit"]),
    (lambda: cc.Box(cells=3), "body.cells", ["[8, 8, 8]"]),
    (lambda: cc.Box(cells=(1, 1, True)), "body.cells[2]", ["whole number"]),
    (lambda: cc.Box(grading=(1.0, 1.0, math.nan)), "body.grading[2]", ["finite"]),
    (lambda: cc.Body(None), "body.geometry", ["cc.MeshFile(path)"]),
    (lambda: cc.MeshFile(3), "body.mesh", ["path"]),
    (lambda: cc.MeshFile("/nonexistent.msh"), "body.mesh", ["check the path"]),
    (lambda: cc.Dirichlet("bottom", ux="0"), "dirichlet[bottom].ux", ["finite number"]),
    (lambda: cc.Dirichlet("bottom"), "dirichlet[bottom]", ["ux, uy"]),
    (lambda: cc.Traction("top", vector=(1.0,)), "traction[top].vector", ["2 or 3 finite numbers"]),
    (lambda: cc.Traction("top", pressure=1.0, vector=(1.0, 0.0)), "traction[top]", ["exactly one"]),
    (lambda: cc.Contact(None), "contact.boundary", ["name a boundary"]),
    (lambda: cc.Contact("top", law=cc.Signorini(), obstacle=cc.Obstacle(tangential_force=1.0)),
     "obstacle.tangential_force", ["tresca"]),
    (lambda: dataclasses.replace(PATCH, body_force=(math.nan, 0.0)), "body_force[0]", ["finite"]),
    (lambda: dataclasses.replace(PATCH, name=3), "name", ["str"]),
    (lambda: dataclasses.replace(PATCH, materials={}), "materials", ["E and nu"]),
    (lambda: cc.prepare(PATCH).with_law("coulomb"), "contact.law", ["cc.Coulomb(F)"]),
    (lambda: cc.prepare(PATCH).with_law(cc.Coulomb(1e12)), "contact.friction", ["at most 1e+06"]),
])
def test_the_scenes_other_classes_name_the_field_and_a_fix(build, field, words):
    refused(build, field, *words)


def test_a_slip_bound_of_a_scene_whose_loads_are_below_resolution_is_not_refused():
    """The fuzz suite's scene: a punch that does not reach Γ_C and a Dirichlet value of 5e-118 set no load scale
    (the floor MIN_STRAIN), so a slip bound is 'large' only beside nothing; the answer is u = 0, certified."""
    scene = cc.Scene(body=cc.Body(cc.Rectangle(1.0, 0.5, 3, 1, origin=(-0.5, 0.0))), materials=cc.Material(1.0, 0.0),
                     dirichlet=(cc.Dirichlet("top", ux=5.255944530576004e-118, uy=0.0),),
                     contact=cc.Contact("bottom", cc.Obstacle("parabolic", radius=2.0, depth=0.00390625),
                                        cc.Tresca(slip_bound=0.00390625)))
    result = cc.solve(scene, "clarabel")
    assert result.status == "solved" and result.certificate.passes(1e-8)
    assert np.abs(result.contact.pressure).max() < 1e-12
