"""Bad inputs of the adaptive run (``convexcontact run SCENE --adapt --target … --max-dofs …``; the Python
``adapt(…, growth=…)`` and ``refinement.compare(…, growth=…, adaptive_dofs=…)``): refused before any solve, exit code 2
or a ValueError, the message starting with the option's name and naming a fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from refusals import raises

import convexcontact as cc
from convexcontact import cli
from convexcontact.drivers.adapt import adapt
from convexcontact.scene.library import hertz_punch
from convexcontact.studies.precision import refinement

SURFACES = ("convexcontact run", "cc.adapt")

SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "patch.toml"


def exit_code(*arguments) -> int:
    """The exit code of ``convexcontact run SCENE ARGUMENTS`` (argparse's own refusals exit through SystemExit)."""
    try:
        return cli.main(["run", str(SCENE), *arguments])
    except SystemExit as exit_:
        return exit_.code


def refused(capsys, *arguments) -> str:
    """stderr of a run that must be refused as bad input, before solving."""
    assert exit_code(*arguments) == 2
    printed = capsys.readouterr()
    assert "closed nodes" not in printed.out and "level 0" not in printed.out
    return printed.err


@pytest.mark.parametrize("value", ["0", "-0.1", "1", "1.5", "nan", "inf", "abc", ""])
def test_target_outside_zero_one_is_refused(capsys, value):
    assert "--target" in refused(capsys, "--adapt", f"--target={value}")


@pytest.mark.parametrize("value", ["0", "-5", "1.5", "1e5", "many"])
def test_max_dofs_not_a_positive_integer_is_refused(capsys, value):
    assert "--max-dofs" in refused(capsys, "--adapt", f"--max-dofs={value}")


@settings(max_examples=20, deadline=None)
@given(st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.0), st.just(float("nan"))))
def test_any_target_that_is_no_fraction_is_refused(value):
    assert exit_code("--adapt", f"--target={value!r}") == 2


@pytest.mark.parametrize("option, value", [("--target", "0.1"), ("--max-dofs", "1000")])
def test_adaptive_options_without_adapt_are_refused_not_ignored(capsys, option, value):
    message = refused(capsys, option, value)
    assert f"{option}: only means something with --adapt" in message and "add --adapt" in message


def test_adapt_with_every_solution_is_refused(capsys):
    message = refused(capsys, "--adapt", "--solutions", "all")
    assert "--adapt:" in message and "--solutions all" in message


BAD_GROWTH = [1, 1.0, 0.5, 0, -2, float("nan"), float("inf"), "2", True, [2.0]]


@pytest.mark.parametrize("value", BAD_GROWTH)
def test_adapt_refuses_a_growth_that_is_no_factor_above_one(value, monkeypatch):
    """A growth ≤ 1 would not grow, NaN and inf no factor, a string or a bool no number: refused before any solve."""
    monkeypatch.setattr("convexcontact.drivers.adapt.solve", lambda *a, **k: pytest.fail("solved a bad input"))
    raises(lambda: adapt(hertz_punch(nx=2), growth=value), "growth", "e.g. 2")


@pytest.mark.parametrize("value", BAD_GROWTH)
def test_refinement_comparison_refuses_a_bad_growth_before_any_solve(value, monkeypatch):
    monkeypatch.setattr("convexcontact.studies.precision.refinement.solve", lambda *a, **k: pytest.fail("solved"))
    raises(lambda: refinement.compare(hertz_punch(nx=2), 2, growth=value), "growth", "e.g. 2")


@pytest.mark.parametrize("value", [0, -100, 2.5, float("nan"), "1e5", True])
def test_refinement_comparison_refuses_adaptive_dofs_that_are_no_count(value, monkeypatch):
    monkeypatch.setattr("convexcontact.studies.precision.refinement.solve", lambda *a, **k: pytest.fail("solved"))
    raises(lambda: refinement.compare(hertz_punch(nx=2), 2, adaptive_dofs=value), "adaptive_dofs", "e.g. 100000")


@settings(max_examples=25, deadline=None)
@given(st.one_of(st.floats(max_value=1.0), st.just(float("nan")), st.text(max_size=5)))
def test_any_growth_that_is_no_number_above_one_is_refused(value):
    raises(lambda: adapt(hertz_punch(nx=2), growth=value), "growth", "e.g. 2")


@pytest.mark.parametrize("field, value, fix", [
    ("scene", "patch.toml", "cc.load_scene"), ("fraction", 0.0, "0.5 is usual"), ("fraction", 1.5, "0.5 is usual"),
    ("fraction", float("nan"), "0.5 is usual"), ("max_dofs", 0, "e.g. 200000"), ("max_dofs", 1e5, "e.g. 200000"),
    ("max_dofs", True, "e.g. 200000"), ("max_dofs", "1e5", "e.g. 200000"), ("target", -1e-2, "1e-2 for 1 %"),
    ("target", float("nan"), "1e-2 for 1 %"), ("target", "1 %", "1e-2 for 1 %")])
def test_the_public_adapt_refuses_each_option_before_any_solve(field, value, fix, monkeypatch):
    """``cc.adapt``: a scene that is none, a fraction outside (0, 1], DOFs that are no positive integer, a target
    outside (0, 1): a ValueError naming the field and a fix, before any solve."""
    monkeypatch.setattr("convexcontact.drivers.adapt.solve", lambda *a, **k: pytest.fail("solved a bad input"))
    options = {} if field == "scene" else {field: value}
    raises(lambda: cc.adapt(value if field == "scene" else hertz_punch(nx=2), **options), field, fix)
