"""Bad inputs to the sensitivities (issue 28): each refused where it enters, the message starting with the field's
name and saying what to do."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact.results.certificate import Certificate

SURFACES = ("cc.sensitivity", "cc.gradient", "cc.with_parameter")


def block(law=None, **scene):
    return cc.Scene(name="block", body=cc.Body(cc.Rectangle(width=2.0, height=1.0, nx=4, ny=2)),
                    materials=cc.Material(E=1.0, nu=0.3), dirichlet=(cc.Dirichlet("top", ux=0.01, uy=-0.01),),
                    tractions=(cc.Traction("right", pressure=0.001),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), law or cc.Tresca(slip_bound=0.004)),
                    **scene)


def stack():
    """A block on a block on a rigid foundation: two contacts."""
    from convexcontact.scene.bodies import Pair, Part, bodies_scene

    material = cc.Material(E=1.0, nu=0.3)
    parts = [Part("upper", cc.Rectangle(1.0, 0.5, 2, 1, origin=(0.0, 1.0)), material, "P1"),
             Part("lower", cc.Rectangle(1.0, 1.0, 2, 2), material, "P1")]
    return bodies_scene(parts, [Pair("upper.bottom", master="lower.top"), cc.Contact("lower.bottom", cc.Obstacle())],
                        dirichlet=[cc.Dirichlet("lower.left", ux=0.0), cc.Dirichlet("upper.left", ux=0.0)],
                        tractions=[cc.Traction("upper.top", pressure=0.01)], name="stack")


@pytest.fixture(scope="module")
def result():
    return cc.solve(block())


@pytest.mark.parametrize("parameter, message", [
    ("foo", r"^parameter: 'foo': unknown parameter — use one of E, nu"),
    (3, r"^parameter: expected a name or a list of names, got 3 — name one of E, nu"),
    ([], r"^parameter: expected a name or a list of names"),
    ("friction", r"^parameter: 'friction': the scene's law is Tresca, which has no friction — use 'slip_bound'$"),
    ("stiffness", (r"^parameter: 'stiffness': the scene's law \(Tresca\) has no normal compliance — give the law a "
                  r"NormalCompliance")),
    ("traction[left].pressure", (r"^parameter: 'traction\[left\].pressure': the scene has no \[\[traction\]\] "
                                r"pressure on 'left' — add a \[\[traction\]\]")),
    ("dirichlet[top].uz", r"^parameter: 'dirichlet\[top\].uz': the scene has no \[\[dirichlet\]\] uz on 'top'"),
    ("body_force", r"^parameter: 'body_force': a vector: name one of its components — use 'body_force\[0\]'"),
    ("body_force[5]", r"^parameter: 'body_force\[5\]': component 5 of a 2-vector — use body_force\[0\] … "),
    ("materials[steel].E", r"^parameter: 'materials\[steel\].E': no material 'steel' — use 'E'"),
    ("obstacle.force", (r"^parameter: 'obstacle.force': the obstacle is not pressed by a force .* — give the scene's "
                       r"obstacle a force")),
    ("contact[0].obstacle.depth", (r"^parameter: 'contact\[0\].obstacle.depth': not differentiated here \(contacts of "
                                  r"several bodies\)")),
    (["E", "bar"], r"^parameter\[1\]: 'bar': unknown parameter"),
])
def test_bad_parameters_are_refused(result, parameter, message):
    with pytest.raises(cc.SceneError, match=message):
        cc.sensitivity(result, parameter)


def test_a_parameter_the_shape_does_not_read_is_refused():
    scene = cc.library.tresca_punch(nx=8)
    with pytest.raises(cc.SceneError, match=r"^parameter: 'obstacle.gap': a parabolic obstacle's gap comes from its "
                                            r"shape.*move it by 'obstacle.depth'"):
        cc.with_parameter(scene, "obstacle.gap", 0.1)


def test_a_field_is_no_one_number():
    scene = block(cc.Coulomb(friction="0.3 + 0.1*x"))
    with pytest.raises(cc.SceneError, match=r"^parameter: 'friction': the law's friction is a field, not one number"
                                            r" — give contact.friction as a number"):
        cc.with_parameter(scene, "friction", 0.2)


def test_not_a_result_is_refused():
    with pytest.raises(cc.SceneError, match=r"^result: expected ContactResult, got Scene"):
        cc.sensitivity(block(), "E")


@pytest.mark.parametrize("status", ["inaccurate", "not converged", "failed"])
def test_an_uncertified_answer_is_refused(result, status):
    spoiled = dataclasses.replace(result, status=status, message="")
    with pytest.raises(ValueError, match=rf"^result: status '{status}': only a solved and certified answer has a "
                                         r"derivative — solve it again more tightly"):
        cc.sensitivity(spoiled, "E")


def test_a_failing_certificate_is_refused(result):
    spoiled = dataclasses.replace(result, certificate=Certificate({"equilibrium": 1e-3}))
    with pytest.raises(ValueError, match=r"^result: certificate 1.0e-03 > 1e-06: not an answer of the discrete "
                                         r"problem.*solve more tightly"):
        cc.gradient(spoiled, ["E"], normal_force=1.0)


@pytest.mark.parametrize("scene, message", [
    (block(cc.NormalCompliance(stiffness=100.0, non_penetration="gauss")),
     r"^contact.non_penetration: contact or friction at Gauss points"),
    (block(cc.Signorini(non_penetration="gauss")), r"^contact.non_penetration: contact or friction at Gauss points"),
    (stack(), r"^result: several contacts in one scene: not implemented — differentiate one pair of bodies"),
])
def test_scenes_not_differentiated_are_refused(scene, message):
    answer = cc.solve(scene)
    assert answer.status == "solved"
    with pytest.raises(cc.SceneError, match=message):
        cc.sensitivity(answer, "E")


@pytest.fixture(scope="module")
def steps():
    history = cc.History(times=[1.0, 2.0], values={"dirichlet[top].ux": [0.005, 0.01]})
    return cc.solve(block(history=history))


def test_a_history_step_alone_is_refused(steps):
    with pytest.raises(cc.SceneError, match=r"^result: a step of a load history: its derivative depends on the "
                                            r"earlier steps — give the whole HistoryResult to cc.sensitivity"):
        cc.sensitivity(steps.steps[-1], "E")


def test_a_parameter_the_history_sets_is_refused(steps):
    with pytest.raises(cc.SceneError, match=r"^parameter: 'dirichlet\[top\].ux': the history sets it at every step "
                                            r"\(history.dirichlet\[top\].ux\) — differentiate by a parameter"):
        cc.sensitivity(steps, "dirichlet[top].ux")


def test_an_unfinished_history_is_refused(steps):
    spoiled = dataclasses.replace(steps, steps=steps.steps[:1])
    with pytest.raises(ValueError, match=r"^result: the history's status is 'failed'.*solve it again more tightly"):
        cc.sensitivity(spoiled, "E")


def test_the_gradient_of_a_history_is_refused(steps):
    with pytest.raises(cc.SceneError, match=r"^result: a load history: the adjoint through its steps is not "
                                            r"implemented — contract the forward derivatives"):
        cc.gradient(steps, ["E"], normal_force=1.0)


@pytest.mark.parametrize("weights, message", [
    ({"pressure": np.ones(3)}, (r"^pressure: expected \(5,\) finite numbers \(dJ/dpressure at the answer, user "
                               r"units\), got .* — give an array of shape \(5,\)")),
    ({"displacement": np.full(30, np.nan)}, r"^displacement: expected \(30,\) finite numbers"),
    ({"contact_force": "up"}, r"^contact_force: expected \(2,\) finite numbers"),
    ({"normal_force": float("nan")}, r"^normal_force: got nan — give dJ/dnormal_force at the answer as a number"),
    ({"tangential_force": "1"}, r"^tangential_force: expected a number"),
])
def test_bad_objective_weights_are_refused(result, weights, message):
    with pytest.raises(ValueError, match=message):
        cc.gradient(result, ["E"], **weights)


def test_obstacle_motion_weights_need_force_control(result):
    with pytest.raises(ValueError, match=r"^obstacle_advance: the obstacle's motion is given \(no force control\), "
                                         r"not an unknown of the answer — drop it"):
        cc.gradient(result, ["E"], obstacle_advance=1.0)


def test_friction_weights_need_friction():
    answer = cc.solve(block(cc.Signorini()))
    with pytest.raises(ValueError, match=r"^friction: the result has no friction traction \(a frictionless law\) — "
                                         r"drop it"):
        cc.gradient(answer, ["E"], friction=np.ones(5))


@pytest.mark.parametrize("parameters, message", [
    ("E", r"^parameters: expected a list of names, got 'E' — give e.g. \['friction', 'E'\]"),
    ([], r"^parameters: expected a list of names"),
    (["E", "slip_bound", "G"], r"^parameters\[2\]: 'G': unknown parameter"),
])
def test_bad_parameter_lists_are_refused(result, parameters, message):
    with pytest.raises(cc.SceneError, match=message):
        cc.gradient(result, parameters, normal_force=1.0)


@pytest.mark.parametrize("value", [float("nan"), float("inf"), "0.3", None])
def test_with_parameter_refuses_values_that_are_not_numbers(value):
    with pytest.raises(cc.SceneError, match=r"^value: .* — give slip_bound's new value as a number"):
        cc.with_parameter(block(), "slip_bound", value)


def test_with_parameter_refuses_what_is_not_a_scene():
    with pytest.raises(cc.SceneError, match=r"^scene: expected Scene, got dict"):
        cc.with_parameter({}, "E", 1.0)


@settings(max_examples=30, deadline=None)
@given(st.text(max_size=30))
def test_random_parameter_names_are_refused_or_understood(name):
    """Any string is either one of the scene's parameters (its value read back) or refused by name."""
    scene = block()
    try:
        value = cc.with_parameter(scene, name, 0.5)
    except cc.SceneError as error:
        assert str(error).startswith(("parameter: ", "value: "))
    else:
        assert isinstance(value, cc.Scene)
