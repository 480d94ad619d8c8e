"""Every public surface has its bad-input tests (issue 24): each command of the CLI and each option that takes
a value, each public name of the package, each file reader.

A bad-input module is a ``tests/test_bad_inputs*.py`` whose ``SURFACES`` names what it tries; the lists below
are read from the package itself (``--help`` texts, ``__all__``), so a new command, option or name without
bad-input tests fails here.
"""

import ast
import contextlib
import io
import re
from pathlib import Path

import pytest

import convexcontact as cc
from convexcontact import cli

MODULES = sorted(Path(__file__).parent.glob("test_bad_inputs*.py"))
READERS = ("reader toml", "reader mesh", "reader fclib", "reader peer", "reader grid resume")
OUTPUTS = {"ConicSolution", "ContactResult", "HistoryResult", "SolutionSet", "SceneError"}
"""Public names a user reads or catches but never builds from values of their own."""


def surfaces_of(path: Path) -> tuple[str, ...]:
    """The module's ``SURFACES`` (read, not imported: a module's own imports stay out of this test)."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["SURFACES"]:
            return ast.literal_eval(node.value)
    raise AssertionError(f"{path.name} names no SURFACES")


DECLARED = {path: surfaces_of(path) for path in MODULES}


def help_text(*argv: str) -> str:
    """What ``convexcontact ARGV --help`` prints."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.suppress(SystemExit):
        cli.main([*argv, "--help"])
    return printed.getvalue()


def choices(text: str) -> list[str]:
    """The first ``{a,b,…}`` of a usage line: a parser's subcommands."""
    return re.search(r"\{([\w,-]+)\}", text).group(1).split(",")


def commands() -> dict[str, str]:
    """``convexcontact …`` command → its help text (for ``bench``, with its ``--history`` mode's)."""
    found = {}
    for command in choices(help_text()):
        if command in ("study", "fclib"):
            found |= {f"{command} {sub}": help_text(command, sub) for sub in choices(help_text(command))}
        else:
            found[command] = help_text(command) + (help_text(command, "--history", "2") if command == "bench" else "")
    return {f"convexcontact {name}": text for name, text in found.items()}


COMMANDS = commands()


def value_options(text: str) -> set[str]:
    """The options of a help text that take a value (``--out OUT``), not the flags (``--overwrite``)."""
    return set(re.findall(r"^\s+(?:-\w \S+, )?(--[\w-]+) (?=\S)", text, flags=re.MULTILINE))


def public_names() -> list[str]:
    return [f"cc.{name}" for name in cc.__all__ if name not in OUTPUTS] + ["cc.scene.load_scene"]


def test_the_package_lists_its_commands():
    """The lists read from the package are the package's (a parser change that hid them would pass vacuously)."""
    assert {"convexcontact run", "convexcontact study grid", "convexcontact fclib solve"} <= set(COMMANDS)
    assert {"--merit-tol", "--max-iterations"} <= value_options(COMMANDS["convexcontact fclib solve"])
    assert "--overwrite" not in value_options(COMMANDS["convexcontact run"])


@pytest.mark.parametrize("surface", [*COMMANDS, *public_names(), *READERS])
def test_every_surface_has_bad_input_tests(surface):
    assert any(surface in names for names in DECLARED.values()), f"no tests/test_bad_inputs*.py names {surface!r}"


@pytest.mark.parametrize("command", COMMANDS)
def test_every_option_that_takes_a_value_is_tried_with_a_bad_one(command):
    """Each value-taking option appears in a bad-input module of its command."""
    sources = "".join(path.read_text() for path, names in DECLARED.items() if command in names)
    untried = sorted(option for option in value_options(COMMANDS[command]) if f'"{option}' not in sources)
    assert not untried, f"{command}: no bad-input test gives {untried}"


def test_every_named_surface_exists():
    """A module names only surfaces that exist (a renamed command or class would leave its tests behind)."""
    known = {*COMMANDS, *public_names(), *READERS, *(f"cc.{name}" for name in OUTPUTS)}
    stale = {path.name: sorted(set(names) - known) for path, names in DECLARED.items() if set(names) - known}
    assert not stale
