"""Issue 27, elasto-viscoplastic bodies: each bad input refused where it enters, the message starting with the
field's name and carrying a fix that works — through the Python API, scene files and the history driver — and no
plastic body solved as if it were elastic."""

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from refusals import raises

import convexcontact as cc
from convexcontact import cli
from convexcontact.drivers import plastic_history
from convexcontact.scene.toml import scene_from_dict
from convexcontact.studies.benchmarks import bench, plastic_bench

SURFACES = ("cc.Material", "reader toml", "cc.run_history", "cc.solve", "cc.prepare", "convexcontact bench")

STEEL = {"E": 1.0, "nu": 0.3}


def block(material: cc.Material, law=None, plane: str = "strain", history: bool = True) -> cc.Scene:
    """A 2×2 block pressed onto a flat plane by its top, in one step."""
    return cc.Scene(
        body=cc.Body(cc.Rectangle(1.0, 1.0, 2, 2), "Q1", plane=plane), materials=material,
        dirichlet=(cc.Dirichlet("left", ux=0.0), cc.Dirichlet("top", uy=-0.01)),
        contact=cc.Contact("bottom", cc.Obstacle("flat"), law or cc.Signorini()),
        history=cc.History([1.0], {"dirichlet[top].uy": [-0.01]}) if history else None)


PLASTIC = cc.Material(**STEEL, yield_stress=0.002)


@pytest.mark.parametrize("fields, field, fix", [
    ({"yield_stress": -1.0}, "material.yield_stress", "give σ_Y > 0"),
    ({"yield_stress": 0.0}, "material.yield_stress", "η_p > 0 for a viscous fluid"),
    ({"yield_stress": float("nan")}, "material.yield_stress", "finite number"),
    ({"yield_stress": "1e3"}, "material.yield_stress", "finite number"),
    ({"yield_stress": True}, "material.yield_stress", "finite number"),
    ({"yield_stress": 1.0, "plastic_viscosity": -0.5}, "material.plastic_viscosity", "give η_p ≥ 0"),
    ({"yield_stress": 1.0, "plastic_viscosity": math.inf}, "material.plastic_viscosity", "finite number"),
    ({"plastic_viscosity": 2.0}, "material.plastic_viscosity", "give yield_stress"),
    ({"yield_stress": 1.0, "viscosity": 2.0}, "material.viscosity", "drop viscosity"),
])
def test_a_bad_plastic_field_is_named(fields, field, fix):
    raises(lambda: cc.Material(**STEEL, **fields), field, fix)


def test_a_named_material_names_its_subdomain():
    raises(lambda: cc.Material(**STEEL, name="steel", yield_stress=-2.0), "steel.yield_stress", "give σ_Y > 0")


@settings(max_examples=25, deadline=None)
@given(st.floats(max_value=0.0, exclude_max=True) | st.just(math.nan) | st.just(-math.inf))
def test_any_negative_or_meaningless_yield_stress_is_refused(value):
    raises(lambda: cc.Material(**STEEL, yield_stress=value), "material.yield_stress", "give")


@settings(max_examples=25, deadline=None)
@given(st.floats(max_value=0.0, exclude_max=True) | st.just(math.nan))
def test_any_negative_plastic_viscosity_is_refused(value):
    raises(lambda: cc.Material(**STEEL, yield_stress=1.0, plastic_viscosity=value), "material.plastic_viscosity",
           "give")


TOML = {"body": {"mesh": "rectangle", "nx": 2, "ny": 2}, "dirichlet": [{"boundary": "left", "ux": 0.0}],
        "contact": {"boundary": "bottom", "law": "signorini"}}


@pytest.mark.parametrize("material, field, fix", [
    ({**STEEL, "yield_stress": "high"}, "material.yield_stress", "expected a number"),
    ({**STEEL, "yield_stress": -3.0}, "material.yield_stress", "give σ_Y > 0"),
    ({**STEEL, "plastic_viscosity": 1.0}, "material.plastic_viscosity", "give yield_stress"),
    ({**STEEL, "yield_strength": 1.0}, "material.yield_strength", "did you mean 'yield_stress'"),
])
def test_a_scene_file_names_the_bad_plastic_field(material, field, fix):
    raises(lambda: scene_from_dict({**TOML, "material": material}), field, fix)


def test_a_scene_file_reads_a_plastic_material():
    """The good case beside the bad ones: both fields land in the Material."""
    scene = scene_from_dict({**TOML, "material": {**STEEL, "yield_stress": 2.0, "plastic_viscosity": 0.5}})
    assert (scene.materials.yield_stress, scene.materials.plastic_viscosity) == (2.0, 0.5)


def never(*_, **__):
    raise AssertionError("work started before the input was refused")


@pytest.mark.parametrize("scene, options, field, fix", [
    (block(PLASTIC, plane="stress"), {}, "body.plane", "plane = 'strain'"),
    (block(PLASTIC), {"formulation": "dual"}, "formulation", "formulation='primal' or 'auto'"),
    (block(PLASTIC), {"solver": "osqp"}, "solver", "'clarabel'"),
    (block(PLASTIC), {"solver": "newton-cg"}, "solver", "'clarabel'"),
])
def test_a_plastic_history_refuses_what_it_is_not_built_for(monkeypatch, scene, options, field, fix):
    monkeypatch.setattr(plastic_history.PlasticProcess, "__init__", never)
    raises(lambda: cc.run_history(scene, **options), field, fix)


@pytest.mark.parametrize("eta, times", [(1e200, [1e-200, 1.0]), (1e3, [1e-10, 1.0])])
def test_a_step_far_below_the_plastic_relaxation_time_is_refused(monkeypatch, eta, times):
    """η_p/(E Δt) beyond 10¹²: the increment would be lost in round-off (beyond the floats: an overflow)."""
    monkeypatch.setattr(plastic_history.PlasticProcess, "__init__", never)
    scene = dataclasses.replace(block(cc.Material(**STEEL, yield_stress=0.002, plastic_viscosity=eta)),
                                history=cc.History(times, {"dirichlet[top].uy": [-0.01, -0.01]}))
    raises(lambda: cc.run_history(scene), "history.times[0]", "smaller plastic_viscosity")


def pair(upper: cc.Material, plane: str = "strain", law=None) -> cc.Scene:
    """A block on another, pressed together in one step."""
    parts = [cc.Part("upper", cc.Rectangle(1.0, 1.0, 2, 2, origin=(0.0, 1.0)), upper, plane=plane),
             cc.Part("lower", cc.Rectangle(1.0, 1.0, 2, 2), cc.Material(**STEEL), plane=plane)]
    return cc.bodies_scene(parts, [cc.Pair("upper.bottom", master="lower.top", law=law or cc.Signorini())],
                           [cc.Dirichlet("upper.top", ux=0.0, uy=-0.01), cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0)],
                           history=cc.History([1.0], {"dirichlet[upper.top].uy": [-0.01]}))


@pytest.mark.parametrize("scene, options, field, fix", [
    (pair(PLASTIC, plane="stress"), {}, "parts[upper].plane", "plane = 'strain'"),
    (pair(PLASTIC, law=cc.Coulomb(friction=0.3)), {"formulation": "dual"}, "formulation", "'primal' or 'auto'"),
    (pair(PLASTIC, law=cc.Coulomb(friction=0.3)), {"solver": "osqp"}, "solver", "'clarabel'"),
    (block(PLASTIC, cc.Coulomb(friction=0.3)), {"solver": "newton-cg"}, "solver", "'clarabel'"),
])
def test_a_plastic_part_or_a_plastic_coulomb_step_refuses_what_it_is_not_built_for(monkeypatch, scene, options,
                                                                                      field, fix):
    """Several bodies and Coulomb friction are built for plastic bodies; plane stress (named by the plastic part),
    the dual and the solvers without second-order cones still are not, refused before anything is assembled."""
    monkeypatch.setattr(plastic_history.PlasticProcess, "__init__", never)
    raises(lambda: cc.run_history(scene, **options), field, fix)


@pytest.mark.parametrize("entry", [cc.solve, cc.prepare])
def test_a_plastic_body_without_history_is_not_solved_as_elastic(entry):
    """The static program would be the elastic one: refused, naming the history that poses the plastic one."""
    raises(lambda: entry(block(PLASTIC, history=False)), "history", "cc.run_history")


def test_a_plastic_subdomain_without_history_is_refused_too():
    scene = dataclasses.replace(block(PLASTIC, history=False), materials={"a": PLASTIC})
    raises(lambda: cc.solve(scene), "history", "drop yield_stress")


@pytest.mark.parametrize(("options", "texts"), [
    (["--dim", "3"], ["--dim: the plastic bench's punch is 2-D", "drop --dim 3"]),
    (["--laws", "coulomb"], ["--laws: coulomb is not timed by the plastic bench", "--laws signorini tresca"]),
    (["--formulation", "dual"], ["--formulation: 'dual'", "--formulation primal"]),
    (["--solver", "osqp"], ["--solver: 'osqp' cannot take", "--solver clarabel"]),
    (["--solver", "bogus"], ["solver: unknown 'bogus'", "use one of"]),
    (["--sweep", "2"], ["--sweep: ", "drop --sweep"]),
    (["--sizes", "50"], ["--sizes: 50 DOFs", "at least 100"]),
    (["--sizes", "nan"], ["--sizes: ", "e.g."]),
    (["--nodes", "1e3"], ["--nodes: ", "with --scenario whole-face"]),
    (["--sizes", "1e9"], ["--sizes"]),
    (["--out", "earlier"], ["--out: ", "--overwrite"]),
])
def test_the_plastic_bench_refuses_what_its_punch_is_not_built_for(capsys, tmp_path, monkeypatch, options, texts):
    """``convexcontact bench --scenario plastic`` with an option its case cannot take: exit 2, ``error: --OPTION: …``
    with a fix, before any case runs and with the earlier run's CSV untouched."""
    monkeypatch.setattr(bench, "run", lambda *args, **kwargs: pytest.fail("the work started"))
    monkeypatch.setattr(plastic_bench, "measure", lambda *args, **kwargs: pytest.fail("the work started"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "earlier").mkdir()
    (tmp_path / "earlier" / "bench_2d_plastic.csv").write_text("an earlier run's")
    with pytest.raises(SystemExit) as exit_:
        cli.main(["bench", "--scenario", "plastic", *options])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "error: " in err and "Traceback" not in err, err
    for text in texts:
        assert text in err, err
    assert (tmp_path / "earlier" / "bench_2d_plastic.csv").read_text() == "an earlier run's"


def test_the_return_mapping_baseline_refuses_friction():
    """Its penalty contact is frictionless: a Tresca scene would be solved as a smooth one, so it is refused."""
    from convexcontact.baselines import return_mapping_history

    scene = block(PLASTIC, law=cc.Tresca(slip_bound=0.01))
    raises(lambda: return_mapping_history(scene, 1e3), "contact.law", "cc.Signorini()")
