"""The layering of DESIGN.md, read from the source: no import cycles, and no layer reaching across."""

import ast
import collections
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "convexcontact"


def imports(typing: bool = False) -> dict[str, set[str]]:
    """Module → the package modules it imports (at the top or inside functions; with ``typing``, also those
    imported for annotations only, under ``if TYPE_CHECKING``)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = collections.defaultdict(set)
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        tree = ast.parse(path.read_text())
        typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
                       and getattr(block.test, "id", "") == "TYPE_CHECKING" for n in ast.walk(block)}
        for node in ast.walk(tree):
            if id(node) in typing_only and not typing:  # annotations only: no import at run time
                continue
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("convexcontact"):
                target = node.module
            else:
                continue
            for alias in node.names:
                module = f"{target}.{alias.name}"
                graph[name].add(module if module in modules else target)
    return {name: {m for m in graph[name] if m in modules and m != name} for name in modules}


def cycles_of(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import cycles of ``graph`` (each found once, as a path that returns to its start)."""
    state = dict.fromkeys(graph, "new")
    cycles = []

    def visit(node, path):
        state[node] = "open"
        for target in sorted(graph[node]):
            if state[target] == "open":
                cycles.append(path[path.index(target):] + [target])
            elif state[target] == "new":
                visit(target, path + [target])
        state[node] = "done"

    for module in sorted(graph):
        if state[module] == "new":
            visit(module, [module])
    return cycles


def test_no_module_imports_itself_through_others():
    """No import cycles, lazy imports included: each driver builds on the prepared model, none on another's back."""
    cycles = cycles_of(imports())
    assert not cycles, cycles[:3]


def layer(module: str) -> str:
    """The layer (top folder) of a package module: ``convexcontact.scene.bodies`` → ``convexcontact.scene``."""
    return ".".join(module.split(".")[:2])


def test_no_circle_inside_a_layer_not_even_for_annotations():
    """Inside one layer, no two modules import each other, imports for annotations included (the load history
    reads a scene's fields by name and does not import the Scene that holds it)."""
    graph = {name: {target for target in targets if layer(target) == layer(name)}
             for name, targets in imports(typing=True).items()}
    cycles = cycles_of(graph)
    assert not cycles, cycles[:3]


def test_the_scene_describes_and_imports_nothing_beneath_it():
    """The scene layer (what the user describes, meshes included) imports no other layer of the package: it is
    discretized by fem/, never the other way round."""
    reaching = {(name, target) for name, targets in imports(typing=True).items() if layer(name) == "convexcontact.scene"
                for target in targets if layer(target) != "convexcontact.scene"}
    assert not reaching


def test_no_two_modules_share_a_file_name():
    """One name per concept: a module's file name says which one it is (no two ``model.py`` or ``history.py``)."""
    names = collections.Counter(path.name for path in PACKAGE.rglob("*.py") if path.name != "__init__.py")
    assert not {name for name, count in names.items() if count > 1}


STUDY_FAMILIES = {"benchmarks", "crossvalidation", "precision", "verification", "parameters"}
"""What a user does with a study: measure costs, cross-validate another answer, measure precision and stability,
verify against the theory, run a grid of parameters (``convexcontact.studies``' docstring)."""


def test_studies_live_in_their_family_folder():
    """Each study sits in the folder of what a user does with it; the top of ``studies/`` keeps only what all of
    them share (the commands' argument checks)."""
    studies = PACKAGE / "studies"
    top = {path.name for path in studies.glob("*.py")}
    folders = {path.parent.name for path in studies.glob("*/*.py")}
    assert top == {"__init__.py", "arguments.py"}
    assert folders == STUDY_FAMILIES


def test_every_folder_of_modules_is_a_package():
    """setuptools' ``packages.find`` (pyproject.toml) ships only folders with an ``__init__.py``: a folder of
    modules without one would be missing from the installed package."""
    folders = {path.parent for path in PACKAGE.rglob("*.py")}
    assert not {folder for folder in folders if not (folder / "__init__.py").exists()}


@pytest.mark.parametrize("layer, forbidden", [
    ("convexcontact.formulations", ("convexcontact.solvers", "convexcontact.drivers")),
    ("convexcontact.solvers", ("convexcontact.fem", "convexcontact.scene", "convexcontact.formulations",
                               "convexcontact.drivers", "convexcontact.results")),
    ("convexcontact.fem", ("convexcontact.solvers", "convexcontact.drivers", "convexcontact.formulations")),
    ("convexcontact.scene", ("convexcontact.solvers", "convexcontact.drivers", "convexcontact.formulations")),
])
def test_a_layer_does_not_reach_across(layer, forbidden):
    """A formulation never imports a solver; a solver never knows mechanics (DESIGN.md, Layers)."""
    crossing = {(name, target) for name, targets in imports().items() if name.startswith(layer)
                for target in targets if target.startswith(forbidden)}
    assert not crossing
