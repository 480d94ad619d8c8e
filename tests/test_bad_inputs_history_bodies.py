"""Issue 24, load histories, several bodies and every solution: each bad input refused where it enters, the message
starting with the field's name and carrying a fix that works — through the Python API, scene files and
``convexcontact run`` — and no run that would take hours or more memory than the machine has starts unasked."""

import dataclasses

import numpy as np
import pytest
import skfem as fe
from hypothesis import given, settings
from hypothesis import strategies as st
from refusals import raises

import convexcontact as cc
from convexcontact import cli
from convexcontact.drivers import history_run as history_driver
from convexcontact.drivers import solutions as solutions_driver
from convexcontact.scene.description import Box

SURFACES = ("cc.History", "cc.run_history", "cc.HistoryResult", "cc.bodies_scene", "cc.Part", "cc.Pair",
            "cc.bodies_library", "cc.all_solutions", "cc.SolutionSet", "convexcontact run")

STEEL = cc.Material(1.0, 0.3)
PATCH = cc.library.pressure_patch(nx=3)
PUNCH = cc.library.hertz_punch(nx=8)  # force-controlled parabolic punch


def with_history(scene: cc.Scene, times, **values) -> cc.Scene:
    return dataclasses.replace(scene, history=cc.History(times, {path.replace("__", "."): v for path, v in values.items()}))


def patch_history(steps: int = 2) -> cc.Scene:
    """The pressure patch loaded in ``steps`` equal increments."""
    return dataclasses.replace(PATCH, history=cc.History(
        [float(k) for k in range(1, steps + 1)], {"traction[top].pressure": [0.1 * k for k in range(1, steps + 1)]}))


def two_blocks(*contacts, history=None, dim=2) -> cc.Scene:
    """An upper block on a lower one (their pair first, then ``contacts``), 2-D or 3-D."""
    if dim == 2:
        parts = [cc.Part("upper", cc.Rectangle(1.0, 1.0, 2, 2, origin=(0.0, 1.0)), STEEL),
                 cc.Part("lower", cc.Rectangle(1.0, 1.0, 2, 2), STEEL)]
    else:
        parts = [cc.Part("upper", Box(size=(1, 1, 1), cells=(1, 1, 1), origin=(0, 0, 1)), STEEL),
                 cc.Part("lower", Box(size=(1, 1, 1), cells=(1, 1, 1)), STEEL)]
    return cc.bodies_scene(parts, [cc.Pair("upper.bottom", master="lower.top"), *contacts],
                           [cc.Dirichlet("upper.top", ux=0.0, uy=0.0), cc.Dirichlet("lower.left", ux=0.0)],
                           history=history)


def never(*_, **__):
    raise AssertionError("work started before the input was refused")


# ---------------------------------------------------------------------------------------------- cc.History


@pytest.mark.parametrize("times, values, field, fix", [
    ([1.0, 2.0], {"obstacle.depth": [[0.1, 0.2], [0.3]]}, "history.obstacle.depth[0]", "expected a number"),
    ([[1.0], [2.0, 3.0]], {"obstacle.depth": [0.1, 0.2]}, "history.times", "increasing and positive"),
    ([True, 2.0], {"obstacle.depth": [0.1, 0.2]}, "history.times[0]", "expected a number"),
    ([1.0, 2.0], {"body_force": [[0.0, -1.0], [0.0, -1.0, 0.0]]}, "history.body_force[1]", "body's dimension"),
    ([1.0, 2.0], {"traction[top].vector": [[0.1, 0.0], [0.2, 0.0, 0.0]]}, "history.traction[top].vector[1]",
     "body's dimension"),
    ([1.0, 2.0], {"obstacle.depth": "0.1 0.2"}, "history.obstacle.depth", "one value per step"),
    ([1.0, 2.0], {"obstacle.depth": [0.1, True]}, "history.obstacle.depth[1]", "expected a number"),
    ([1.0, 2.0], {"obstacle.depth": [0.1, 10**400]}, "history.obstacle.depth[1]", "below 1.8e308"),
    ([1.0, 2.0], {"contact[x].obstacle.depth": [0.1, 0.2]}, "history.contact[x].obstacle.depth",
     "contact[INDEX].obstacle.depth"),
])
def test_a_malformed_history_names_the_value(times, values, field, fix):
    raises(lambda: cc.History(times, values), field, fix)


garbage = st.one_of(st.none(), st.booleans(), st.text(max_size=3), st.floats(), st.integers(),
                    st.lists(st.one_of(st.floats(), st.text(max_size=2), st.none()), max_size=3))


@settings(max_examples=60, deadline=None)
@given(times=st.one_of(garbage, st.lists(garbage, max_size=3)),
       path=st.sampled_from(["obstacle.depth", "body_force", "traction[top].vector", "obstacle.radius", "dirichlet[x]"]),
       series=st.one_of(garbage, st.lists(garbage, max_size=3)))
def test_random_garbage_in_a_history_is_a_scene_error_naming_history(times, path, series):
    """Whatever is given, a History is built or refused with a SceneError whose field starts with "history" —
    never a numpy message, a TypeError or a silent conversion of booleans and strings."""
    try:
        history = cc.History(times, {path: series})
    except cc.SceneError as error:
        assert error.field.startswith("history"), error
        return
    assert all(type(t) is float for t in history.times)
    for value in history.values[path]:
        components = value if isinstance(value, tuple) else (value,)  # a vector per step, or a number
        assert all(type(v) is float and np.isfinite(v) for v in components), value


# ----------------------------------------------------------------------- cc.run_history: what it is asked to do


@pytest.mark.parametrize("formulation", ["both", 3, "", None])
def test_a_history_refuses_a_formulation_that_is_none_and_lists_the_valid_ones(formulation, monkeypatch):
    monkeypatch.setattr(history_driver, "Process", never)
    for run in (lambda: cc.solve(patch_history(), formulation=formulation),
                lambda: cc.run_history(patch_history(), formulation=formulation)):
        raises(run, "formulation", "'primal', 'dual', 'dual-matrix-free', 'auto'")


@pytest.mark.parametrize("options, field, fix", [
    ({"confirm": "yes"}, "confirm", "confirm=True"),
    ({"progress": "print"}, "progress", "progress=print"),
    ({"solver": "bogus"}, "solver", "'clarabel'"),
    ({"tol": float("nan")}, "tol", "tol=1e-10"),
])
def test_run_history_checks_its_options_before_any_step(options, field, fix, monkeypatch):
    monkeypatch.setattr(history_driver, "Process", never)
    raises(lambda: cc.run_history(patch_history(), **options), field, fix)


def test_confirm_is_a_boolean_on_every_path():
    raises(lambda: cc.solve(PATCH, confirm="yes"), "confirm", "confirm=True")


def test_a_static_scene_is_no_history():
    raises(lambda: cc.run_history(PATCH), "history", "solve it statically")
    raises(lambda: cc.run_history("scene.toml"), "scene", "history=cc.History(...)")
    raises(lambda: cc.History([1.0], [("obstacle.depth", [0.1])]), "history.values", "{'obstacle.depth': [0.01, 0.02]}")


def test_solutions_all_with_a_history_suggests_a_valid_value():
    message = raises(lambda: cc.solve(patch_history(), solutions="all"), "solutions", "leave solutions to 'one'")
    assert "solutions='all'" not in message.split(" — ")[1]


# ---------------------------------------------------------------- history paths that would change nothing


@pytest.mark.parametrize("scene, path, fix", [
    (dataclasses.replace(PUNCH, contact=dataclasses.replace(PUNCH.contact, obstacle=cc.Obstacle(
        "parabolic", radius=1.0, depth=0.01))), "obstacle.gap", "move it by 'obstacle.depth'"),
    (PATCH.with_law(cc.Signorini()), "obstacle.gap", None),  # flat, depth-controlled: the gap moves it (accepted)
    (dataclasses.replace(PATCH, contact=dataclasses.replace(PATCH.contact, obstacle=cc.Obstacle(force=0.1))),
     "obstacle.gap", "change 'obstacle.force'"),  # force control: the gap only shifts the unknown depth
    (PUNCH, "obstacle.depth", "change 'obstacle.force'"),
    (dataclasses.replace(PATCH, contact=dataclasses.replace(PATCH.contact, obstacle=cc.Obstacle(depth=0.0))),
     "obstacle.force", "change 'obstacle.depth'"),
    (two_blocks(cc.Contact("lower.bottom", cc.Obstacle("flat"))), "obstacle.depth", "'contact[1].obstacle.depth'"),
    (two_blocks(cc.Contact("lower.bottom", cc.Obstacle("flat"))), "contact[0].obstacle.depth",
     "'contact[1].obstacle.depth'"),
    (two_blocks(cc.Contact("lower.bottom", cc.Obstacle("flat"))), "contact[1].obstacle.force",
     "'contact[1].obstacle.depth'"),
    (two_blocks(), "obstacle.depth", "'dirichlet[BODY.top].uy'"),
    (two_blocks(), "contact[0].obstacle.gap", "'dirichlet[BODY.top].uy'"),
])
def test_a_path_that_changes_nothing_is_refused_with_the_path_that_would(scene, path, fix, monkeypatch):
    """Refused before any step (a parabolic punch's gap, a force-controlled obstacle's depth, the obstacle of a
    scene of bodies: three identical steps before); a flat obstacle's gap does move it."""
    monkeypatch.setattr(history_driver, "Process", never)
    scene = dataclasses.replace(scene, history=cc.History([1.0, 2.0], {path: [0.001, 0.002]}))
    if fix is None:
        with pytest.raises(AssertionError, match="work started"):
            cc.run_history(scene)
        return
    raises(lambda: cc.run_history(scene), f"history.{path}", fix)


def test_both_depth_and_force_over_a_history_are_refused():
    scene = with_history(PATCH, [1.0], obstacle__depth=[0.0], obstacle__force=[0.1])
    raises(lambda: cc.run_history(scene), "history.obstacle.force", "keep one of the two paths")


def test_a_bad_value_at_a_late_step_is_refused_before_the_first(monkeypatch):
    """A negative force at the last step: refused by name and step before step 1 is solved."""
    monkeypatch.setattr(history_driver, "Process", never)
    scene = with_history(PUNCH, [1.0, 2.0, 3.0], obstacle__force=[0.01, 0.02, -0.01])
    raises(lambda: cc.run_history(scene), "history.obstacle.force[2]", "(the value -0.01 at t = 3)")


def test_a_boundary_without_the_component_suggests_those_with_it():
    scene = with_history(PATCH, [1.0], **{"dirichlet[right]__ux": [0.0]})
    raises(lambda: cc.run_history(scene), "history.dirichlet[right].ux", "name a boundary that has one: ['left']")


# ------------------------------------------------------------------------------------- viscous steps, sizes


def creep(viscosity: float, times) -> cc.Scene:
    return dataclasses.replace(patch_history(len(times)), materials=cc.Material(1.0, 0.3, viscosity=viscosity),
                               history=cc.History(times, {"traction[top].pressure": [0.1] * len(times)}))


@pytest.mark.parametrize("viscosity, times, shown", [
    (1e200, [1e-200, 2e-200], "1e+400 times K"),  # overflowed K + K_A/Δt: "inaccurate", certificate 0
    (1.0, [1.0, 1.0 + 1e-13], "1e+13 times K"),  # a tiny second step: the increment lost in round-off
])
def test_a_viscous_step_that_drowns_k_is_refused_with_the_step_it_needs(viscosity, times, shown, monkeypatch):
    monkeypatch.setattr(history_driver, "Process", never)
    step = int(np.argmin(np.diff([0.0, *times])))
    message = raises(lambda: cc.run_history(creep(viscosity, times)), f"history.times[{step}]", "take steps of at least")
    assert shown in message


def test_a_history_estimated_beyond_the_hour_needs_confirm(monkeypatch):
    """Estimated from step 2 (time and the memory a step holds), refused with the estimate and the keyword; the
    same history runs with confirm=True, and one beyond the memory available is refused even then."""
    monkeypatch.setattr(history_driver, "LONG_RUN", 1e-9)
    scene = patch_history(3)
    message = raises(lambda: cc.run_history(scene), "history.times", "confirm=True (convexcontact run --confirm)")
    assert "measured on step 2" in message and "kB held" in message
    assert cc.run_history(scene, confirm=True).status == "solved"
    monkeypatch.setattr(history_driver, "available_memory", lambda: 1.0)
    raises(lambda: cc.run_history(scene, confirm=True), "history.times", "give fewer steps")


def test_a_million_steps_are_refused_after_two(monkeypatch):
    """Issue 24: 10⁶ steps of a small scene ran about 4 hours, each step kept: now two steps, then the estimate."""
    solved = []
    scene = dataclasses.replace(PATCH, history=cc.History(np.arange(1.0, 1e6 + 1), {
        "traction[top].pressure": np.full(10**6, 0.1)}))
    raises(lambda: cc.run_history(scene, progress=lambda k, *_: solved.append(k)), "history.times", "give fewer steps")
    assert solved == [1, 2]


def test_a_history_result_refuses_a_file_as_its_folder(tmp_path):
    result = cc.run_history(patch_history(1))
    (tmp_path / "taken").write_text("mine")
    raises(lambda: result.save(tmp_path / "taken"), "directory", "give a folder")
    assert (tmp_path / "taken").read_text() == "mine"
    raises(lambda: result.save(None), "directory", "a folder's path")


# ------------------------------------------------------------------------------------------- several bodies


def upper(**change):
    return cc.Part(**({"name": "upper", "geometry": cc.Rectangle(1.0, 1.0, 2, 2, origin=(0.0, 1.0)),
                       "material": STEEL} | change))


LOWER = cc.Part("lower", cc.Rectangle(1.0, 1.0, 2, 2), STEEL)
HELD = [cc.Dirichlet("upper.top", ux=0.0, uy=0.0), cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0)]
PAIR = cc.Pair("upper.bottom", master="lower.top")


@pytest.mark.parametrize("arguments, field, fix", [
    ({"contact": []}, "contact", "cc.Pair('upper.bottom', master='lower.top')"),
    ({"parts": [upper()], "contact": []}, "contact", "cc.Contact('upper.bottom', cc.Obstacle('flat'))"),
    ({"parts": []}, "parts", "cc.Part(name, geometry, material)"),
    ({"parts": [upper(), upper()]}, "parts", "its own name"),
    ({"parts": [upper(), "lower"]}, "parts[1]", "cc.Part(name, geometry, material)"),
    ({"parts": [upper(), cc.Part("lower", Box(cells=(1, 1, 1)), STEEL)]}, "parts.geometry", "the same dimension"),
    ({"contact": cc.Pair("upper.bottom", master="lower.tp")}, "contact.master", "['lower.bottom', 'lower.left'"),
    ({"contact": cc.Pair("upper.bottm", master="lower.top")}, "contact.boundary", "['upper.bottom'"),
    ({"contact": cc.Pair("uper.bottom", master="lower.top")}, "contact.boundary", "the bodies are ['upper', 'lower']"),
    ({"contact": cc.Pair("upper.bottom", master="upper.top")}, "contact.master", "self-contact is not built"),
    ({"contact": [PAIR, cc.Pair("lower.left", master="lower.right")]}, "contact[1].master", "another"),
    ({"contact": [PAIR, "lower.top"]}, "contact[1]", "cc.Pair(slave, master=…"),
    ({"contact": [PAIR, cc.Contact("lower.bottom", cc.Obstacle("flat", force=0.1))]}, "contact[1].obstacle",
     "give depth instead of force"),
    ({"dirichlet": [HELD[0]]}, "dirichlet", "boundary = 'lower.top', ux = 0"),
    ({"dirichlet": [HELD[0], cc.Dirichlet("lower.bottm", uy=0.0)]}, "dirichlet[lower.bottm].boundary",
     "['lower.bottom'"),
    ({"tractions": [cc.Traction("upper.tpo", pressure=0.1)]}, "traction[upper.tpo].boundary", "['upper.bottom'"),
    ({"contact": "upper.bottom"}, "contact", "cc.Pair(slave, master=…"),
    ({"parts": upper()}, "parts", "give a list of cc.Part"),
    ({"parts": [upper(plane="stress"), LOWER]}, "parts.plane", "plane = 'stress' for all"),
    ({"parts": [upper(geometry=fe.MeshTri(fe.MeshTri().p * [[1.0], [np.nan]], fe.MeshTri().t)), LOWER]},
     "parts[upper].geometry", "finite coordinates"),  # scipy's "data must be finite" before
    ({"parts": [upper(offset=(0.0, 1e300)), LOWER]}, "parts[upper].offset", "near the origin"),  # overflows before
])
def test_bodies_scene_refuses_a_broken_assembly_of_bodies_by_name(arguments, field, fix):
    """No pair, no body, two of one name, a string for a part, 2-D with 3-D, unknown parts and boundaries, a body
    paired with itself, a force-controlled obstacle among pairs, a body held by contact alone: each refused where
    given, before any assembly."""
    raises(lambda: cc.bodies_scene(**({"parts": [upper(), LOWER], "contact": PAIR, "dirichlet": HELD} | arguments)),
           field, fix)


@pytest.mark.parametrize("build, field, fix", [
    (lambda: upper(name="up.per"), "parts.name", "a plain word"),
    (lambda: upper(name=3), "parts.name", "name each body"),
    (lambda: upper(material=(1.0, 0.3)), "parts[upper].material", "cc.Material(E, nu)"),
    (lambda: upper(offset=(0.0, float("nan"))), "parts[upper].offset[1]", "finite number"),
    (lambda: upper(offset=(0.0, 1.0, 2.0, 3.0)), "parts[upper].offset", "2 or 3 numbers"),
    (lambda: upper(element="P3"), "parts[upper].element", "'P1'"),
    (lambda: upper(geometry=cc.Rectangle(1.0, float("inf"), 2, 2)), "body.height", ""),
    (lambda: cc.Pair("upper.bottom"), "contact.master", "name the master boundary"),
    (lambda: cc.Pair("upper.bottom", master=3), "contact.master", "name the master boundary"),
    (lambda: cc.Pair("upper.bottom", master="lower.top", method="nitsche"), "contact.method", "'mortar'"),
    (lambda: cc.Pair("upper.bottom", master="lower.top", obstacle=cc.Obstacle(depth=0.1)), "contact.obstacle",
     "drop the obstacle"),
    (lambda: cc.Pair("upper.bottom", master="lower.top", law=cc.Coulomb(0.3, smoothing_radius=0.1)),
     "contact.smoothing_radius", "drop smoothing_radius"),
])
def test_part_and_pair_check_their_fields(build, field, fix):
    raises(build, field, fix)


@pytest.mark.parametrize("dim, shift", [(3, 1.0), (2, 1.0), (2, 5.0)])
def test_faces_that_do_not_face_each_other_are_named_in_2d_and_3d(dim, shift):
    """Two blocks side by side paired on their tops (3-D: numpy's "cannot reshape array of size 0" before), and an
    upper block beyond the lower one's end: no slave normal meets the master."""
    if dim == 3:
        parts = [cc.Part("left", Box(size=(1, 1, 1), cells=(1, 1, 1)), STEEL),
                 cc.Part("right", Box(size=(1, 1, 1), cells=(1, 1, 1), origin=(shift, 0, 0)), STEEL)]
        contact, held = cc.Pair("left.top", master="right.top"), ["left.bottom", "right.bottom"]
    else:
        parts = [cc.Part("left", cc.Rectangle(1.0, 1.0, 2, 2, origin=(shift, 1.0)), STEEL),
                 cc.Part("right", cc.Rectangle(1.0, 1.0, 2, 2), STEEL)]
        contact, held = cc.Pair("left.bottom", master="right.top"), ["left.top", "right.bottom"]
    scene = cc.bodies_scene(parts, contact, [cc.Dirichlet(name, ux=0.0, uy=0.0, **({"uz": 0.0} if dim == 3 else {}))
                                             for name in held])
    message = raises(lambda: cc.solve(scene), "contact.master", "pair boundaries that face each other")
    assert f"'{contact.master}' faces '{contact.boundary}'" in message


def test_an_error_of_one_pair_among_several_names_it():
    scene = cc.bodies_scene([upper(), LOWER], [PAIR, cc.Pair("lower.left", master="upper.right")], HELD)
    raises(lambda: cc.solve(scene), "contact[1].master", "face each other")


@pytest.mark.parametrize("build, field, fix", [
    (lambda: cc.bodies_library.patch_pair(slave_cells=0), "slave_cells", "e.g. 5"),
    (lambda: cc.bodies_library.patch_pair(master_cells=2.5), "master_cells", "e.g. 7"),
    (lambda: cc.bodies_library.patch_pair(pressure=float("nan")), "pressure", "e.g. 0.01"),
    (lambda: cc.bodies_library.patch_pair(law="coulomb"), "contact.law", "cc.Coulomb(F)"),
    (lambda: cc.bodies_library.two_cylinders(h=-0.01), "h", "e.g. 0.01"),
    (lambda: cc.bodies_library.two_cylinders(h=0.1), "h", "at most 0.0909"),  # numpy's geometric-sequence error
    (lambda: cc.bodies_library.two_cylinders(h=1e-7), "h", "use larger cells"),  # was killed for memory
    (lambda: cc.bodies_library.two_cylinders(h="0.01"), "h", "e.g. 0.01"),
    (lambda: cc.bodies_library.two_cylinders(h=0.05, radii=(0.1, 1.0)), "radii[0]", "above 0.6"),  # NaN nodes
    (lambda: cc.bodies_library.two_cylinders(h=0.05, radii=1.0), "radii", "radii=(1.0, 1.0)"),
    (lambda: cc.bodies_library.two_cylinders(h=0.05, width=0.2), "width", "width > 0.3"),
    (lambda: cc.bodies_library.two_cylinders(h=0.05, approach=float("inf")), "approach", "e.g. 0.01"),
    (lambda: cc.bodies_library.punch_on_foundation(h=0.0), "h", "e.g. 0.01"),
    (lambda: cc.bodies_library.two_spheres(cells=0), "cells", "e.g. 12"),
    (lambda: cc.bodies_library.two_spheres(cells=2, radii=(1.0, 2.0)), "radii[0]", "at least 1.57"),
    (lambda: cc.bodies_library.two_spheres(cells=2, radii=(2.0, 1.5)), "radii[1]", "at least 1.57"),  # folded corner
    (lambda: cc.bodies_library.two_spheres(cells=2, radii=(-8.0, 2.0)), "radii[0]", "at least 1.57"),
    (lambda: cc.bodies_library.two_cylinders(h=0.05, radii=(1.0, -5.0)), "radii[1]", "inf for a flat face"),
    (lambda: cc.bodies_library.two_spheres(cells=2, approach=float("nan")), "approach", "e.g. 0.012"),
    (lambda: cc.bodies_library.two_spheres(cells=2, element="Q1"), "element", "element='P1' or 'P2'"),
    (lambda: cc.bodies_library.two_spheres(cells=2, element="P3"), "element", "element='P1' or 'P2'"),
    (lambda: cc.bodies_library.two_spheres(cells=2, element=2), "element", "element='P1' or 'P2'"),
])
def test_the_bodies_library_checks_its_arguments_before_building_a_mesh(build, field, fix):
    raises(build, field, fix)


# --------------------------------------------------------------------------------------- solutions="all"


def coulomb_block(nx: int = 3) -> cc.Scene:
    return cc.Scene(name="block", body=cc.Body(cc.Rectangle(1.0, 0.5, nx, 2)), materials=STEEL,
                    dirichlet=(cc.Dirichlet("top", ux=0.004, uy=-0.01),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat"), cc.Coulomb(friction=0.2)))


@pytest.mark.parametrize("formulation", ["primal", "dual-matrix-free", "both", 3])
def test_every_solution_refuses_a_formulation_it_does_not_enumerate(formulation, monkeypatch):
    monkeypatch.setattr(solutions_driver, "assemble", never)
    for run in (lambda: cc.all_solutions(coulomb_block(), formulation=formulation),
                lambda: cc.solve(coulomb_block(), formulation=formulation, solutions="all")):
        raises(run, "formulation", "use one of 'auto', 'dual'")


@pytest.mark.parametrize("options, field, fix", [
    ({"confirm": 1}, "confirm", "confirm=True"), ({"progress": 3}, "progress", "progress=print"),
    ({"solver": "nosuch"}, "solver", "'clarabel'"), ({"tol": 0.0}, "tol", "tol=1e-10"),
])
def test_every_solution_checks_its_options_before_any_assembly(options, field, fix, monkeypatch):
    monkeypatch.setattr(solutions_driver, "assemble", never)
    raises(lambda: cc.all_solutions(coulomb_block(), **options), field, fix)


def test_twenty_thousand_contact_nodes_are_refused_before_w_is_formed():
    """Issue 24: 20,001 nodes allocated an 11.9 GB W before anything was said; 1,001 ran for hours."""
    raises(lambda: solutions_driver.check_size(20001, confirm=True), "solutions", "give fewer contact nodes")
    message = raises(lambda: solutions_driver.check_size(1001, confirm=False), "solutions",
                     "confirm=True (convexcontact run --solutions all --confirm)")
    assert "17 Picard runs" in message
    solutions_driver.check_size(1001, confirm=True)
    solutions_driver.check_size(100, confirm=False)


def test_a_search_estimated_too_long_is_refused_before_w_and_after_the_first_run(monkeypatch):
    """From the node count before the condensation; then from the first Picard run's measured time."""
    scene = coulomb_block(20)
    monkeypatch.setattr(solutions_driver, "PICARD_RUN", (1e4, 21))
    monkeypatch.setattr(solutions_driver, "formulate", never)
    raises(lambda: cc.all_solutions(scene), "solutions", "confirm=True")
    monkeypatch.undo()
    monkeypatch.setattr(solutions_driver, "PICARD_RUN", (1e-12, 21))  # passes the estimate from the size
    monkeypatch.setattr(solutions_driver, "LONG_RUN", 1e-9)
    reports = []
    message = raises(lambda: cc.all_solutions(scene, progress=lambda *report: reports.append(report)), "solutions",
                     "confirm=True")
    assert "measured on the first" in message and reports == [(1, 17, "Picard run: solved")]


def test_a_solution_set_refuses_a_file_as_its_folder(tmp_path):
    found = cc.all_solutions(coulomb_block())
    (tmp_path / "taken").write_text("mine")
    raises(lambda: found.save(tmp_path / "taken"), "directory", "give a folder")
    raises(lambda: cc.all_solutions(None), "scene", "cc.Coulomb law")


# ------------------------------------------------------------------------------------- convexcontact run

PATCH_TOML = ('[body]\nmesh = "rectangle"\nnx = 3\nny = 3\n[material]\nE = 1.0\nnu = 0.3\n'
              '[[dirichlet]]\nboundary = "left"\nux = 0.0\n[[traction]]\nboundary = "top"\npressure = 0.1\n'
              '[contact]\nboundary = "bottom"\n[obstacle]\nshape = "flat"\n')
HISTORY = '[history]\ntimes = [1.0, 2.0, 3.0]\n"traction[top].pressure" = [0.1, 0.2, 0.3]\n'
COULOMB = PATCH_TOML.replace('boundary = "bottom"\n', 'boundary = "bottom"\nlaw = "coulomb"\nfriction = 0.2\n')
BLOCKS = ('[[bodies]]\nname = "upper"\nmesh = "rectangle"\nnx = 2\nny = 2\norigin = [0.0, 1.0]\n'
          'material = { E = 1.0, nu = 0.3 }\n[[bodies]]\nname = "lower"\nmesh = "rectangle"\nnx = 2\nny = 2\n'
          'material = { E = 1.0, nu = 0.3 }\n[[dirichlet]]\nboundary = "upper.top"\nux = 0.0\nuy = 0.0\n'
          '[[dirichlet]]\nboundary = "lower.left"\nux = 0.0\n'
          '[[contact]]\nboundary = "upper.bottom"\nmaster = "lower.top"\n'
          '[[contact]]\nboundary = "lower.bottom"\nobstacle = { shape = "flat" }\n')


def command(tmp_path, text: str, *arguments) -> tuple[int, str]:
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    try:
        code = cli.main(["run", str(scene), *arguments])
    except SystemExit as exit_:  # argparse's own usage errors
        code = exit_.code
    return code, str(scene)


@pytest.mark.parametrize("text, arguments, shown", [
    (PATCH_TOML + HISTORY, ["--formulation", "both"], "--formulation: unknown 'both' for a history"),
    (PATCH_TOML + HISTORY, ["--solutions", "every"], "--solutions: invalid choice: 'every'"),
    (PATCH_TOML + HISTORY, ["--solutions", "all"], "--solutions: 'all' lists the solutions of one static problem"),
    (COULOMB, ["--solutions", "all", "--formulation", "primal"], "--formulation: 'primal' for solutions='all'"),
    (PATCH_TOML + HISTORY, ["--solver", "bogus"], "--solver: unknown 'bogus'"),
    (PATCH_TOML + HISTORY, ["--tol", "nan"], "--tol: expected a positive finite number"),
    (PATCH_TOML + HISTORY, ["--tol", "ten"], "--tol: expected a positive finite number, e.g. 1e-8; got 'ten'"),
    (PATCH_TOML + HISTORY, ["--out", "SCENE"], "--out: SCENE is a file"),
    (PATCH_TOML + HISTORY, ["--json", "FOLDER"], "--json: FOLDER is a folder"),
    (PATCH_TOML + HISTORY.replace("0.1, 0.2, 0.3", "0.1, [0.2], 0.3"), [], "history.traction[top].pressure[1]"),
    (PATCH_TOML + '[history]\ntimes = [1.0]\n"obstacle.radius" = [0.1]\n', [],
     "history.obstacle.radius: unknown quantity"),
    (BLOCKS + '[history]\ntimes = [1.0]\n"obstacle.depth" = [0.01]\n', [], "'contact[1].obstacle.depth'"),
    (BLOCKS.replace('master = "lower.top"', "master = 5"), [], "contact[0].master: expected a string"),
    (BLOCKS.replace('master = "lower.top"', 'master = "lower.top"\nmethod = 3'), [],
     "contact[0].method: expected a string"),
    (BLOCKS.replace('name = "lower"', 'name = "upper"'), [], "parts: two bodies named 'upper'"),
    ("contact = []\n" + BLOCKS.split("[[contact]]")[0], [], "contact: an empty list"),
])
def test_run_refuses_each_bad_option_and_table_with_exit_2(tmp_path, capsys, text, arguments, shown):
    """Every value-taking option of ``run`` (--solutions, --formulation, --solver, --tol, --out, --json) on a
    history or a search for every solution, and the [history], [[bodies]] and [[contact]] tables."""
    arguments = [str(tmp_path / "scene.toml") if a == "SCENE" else str(tmp_path) if a == "FOLDER" else a
                 for a in arguments]
    code, scene = command(tmp_path, text, *arguments)
    error = capsys.readouterr().err
    assert code == 2 and shown.replace("SCENE", scene).replace("FOLDER", str(tmp_path)) in error, error
    assert "Traceback" not in error


def test_run_asks_for_confirm_on_a_long_history_and_runs_it_with_confirm(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(history_driver, "LONG_RUN", 1e-9)
    assert command(tmp_path, PATCH_TOML + HISTORY)[0] == 2
    assert "--confirm" in capsys.readouterr().err
    assert command(tmp_path, PATCH_TOML + HISTORY, "--confirm")[0] == 0
    printed = capsys.readouterr().out
    assert "step 3/3: solved" in printed and "s left)" in printed
