"""Bad inputs of the adaptive run (``convexcontact run SCENE --adapt --target … --max-dofs …``): refused before any
solve, exit code 2, the message naming the option and a fix."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from convexcontact import cli

SURFACES = ("convexcontact run",)

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
