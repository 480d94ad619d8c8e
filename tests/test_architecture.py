"""The layering of DESIGN.md, read from the source: no import cycles, and no layer reaching across."""

import ast
import collections
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "convexcontact"


def imports() -> dict[str, set[str]]:
    """Module → the package modules it imports (at the top or inside functions)."""
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
            if id(node) in typing_only:  # annotations only: no import at run time
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


def test_no_module_imports_itself_through_others():
    """No import cycles, lazy imports included: each driver builds on the model, none on another's back."""
    graph = imports()
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
    assert not cycles, cycles[:3]


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
