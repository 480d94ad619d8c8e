"""Safe formulas of scene files: gaps, loads and slip bounds as functions of x, y, z.

A formula is arithmetic on numbers, the coordinates ``x``, ``y``, ``z``, the
constants ``pi`` and ``e`` and a few numpy functions, e.g.
``"x**2/(2*0.5) - 0.01"`` or ``"0.1*sqrt(x**2 + y**2)"``. Anything else is refused
with a :class:`SceneError` naming the field, when the formula is compiled.
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Callable

import numpy as np

from .checks import SceneError, finite

VARIABLES = ("x", "y", "z")
CONSTANTS = {"pi": np.float64(math.pi), "e": np.float64(math.e)}
FUNCTIONS = {
    name: getattr(np, name)
    for name in (
        "sqrt", "exp", "log", "sin", "cos", "tan", "arctan", "arctan2",
        "abs", "minimum", "maximum", "tanh", "cosh", "sinh", "hypot",
    )
}
BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
ALLOWED = "numbers, x, y, z, pi, e, + - * / ** and the functions " + ", ".join(FUNCTIONS)

Node = Callable[[dict[str, np.ndarray]], np.ndarray]


def compile_expression(text: str, field_name: str) -> Callable[..., np.ndarray]:
    """Check the formula ``text`` and return it as a function of coordinate arrays.

    Parameters
    ----------
    text
        The formula, e.g. ``"x**2/(2*0.5) - 0.01"``.
    field_name
        Scene field the formula comes from; every error names it.

    Returns
    -------
    Callable
        ``f(x=..., y=...)`` taking coordinate arrays as keywords (the formula may
        use any subset of x, y, z) and returning a float array of their broadcast
        shape. It raises :class:`SceneError` where the value is NaN or infinite.
    """
    if not isinstance(text, str):
        raise SceneError(field_name, f"expected a formula string, got {text!r}", f"use {ALLOWED}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
        # Evaluated by walking the checked AST into closures: no eval/compile of user code.
        formula = _build(tree.body, text.strip(), field_name)
    except SceneError:
        raise
    except (SyntaxError, ValueError) as error:
        raise SceneError(
            field_name,
            f"{_short(text)!r} is not a formula ({str(getattr(error, 'msg', error))[:80]})",
            "write one arithmetic expression, e.g. 'x**2/(2*0.5) - 0.01'",
        ) from None
    except RecursionError:
        raise SceneError(field_name, "the formula is nested too deeply", "simplify it") from None
    used = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name) and node.id in VARIABLES}

    def evaluate(**coordinates: np.ndarray) -> np.ndarray:
        unknown = set(coordinates) - set(VARIABLES)
        if unknown or not coordinates:
            raise TypeError(f"give coordinates among {VARIABLES} as keywords, got {sorted(coordinates)}")
        missing = used - set(coordinates)
        if missing:
            raise SceneError(
                field_name,
                f"{text!r} uses {', '.join(sorted(missing))}, not defined here",
                f"write it in terms of {', '.join(sorted(coordinates))}",
            )
        values = {name: np.asarray(value, dtype=float) for name, value in coordinates.items()}
        shape = np.broadcast_shapes(*(value.shape for value in values.values()))
        with np.errstate(all="ignore"):
            result = np.broadcast_to(np.asarray(formula(values), dtype=float), shape).copy()
        _check_finite(result, values, text, field_name)
        return result

    return evaluate


def _short(text: str, length: int = 60) -> str:
    """The formula as quoted in an error: its start, when it is long."""
    return text if len(text) <= length else text[: length - 1] + "…"


def _build(node: ast.AST, text: str, field_name: str) -> Node:
    """Turn an allowed AST node into a closure over the coordinate values."""
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        value = np.float64(finite(node.value, field_name))  # refuses 400-digit integers and 1e400
        return lambda values: value
    if isinstance(node, ast.Name) and node.id in CONSTANTS:
        value = CONSTANTS[node.id]
        return lambda values: value
    if isinstance(node, ast.Name) and node.id in VARIABLES:
        name = node.id
        return lambda values: values[name]
    if isinstance(node, ast.UnaryOp) and type(node.op) in UNARY:
        unary, operand = UNARY[type(node.op)], _build(node.operand, text, field_name)
        return lambda values: unary(operand(values))
    if isinstance(node, ast.BinOp) and type(node.op) in BINARY:
        binary = BINARY[type(node.op)]
        left, right = _build(node.left, text, field_name), _build(node.right, text, field_name)
        return lambda values: binary(left(values), right(values))
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS:
        function = FUNCTIONS[node.func.id]
        if (
            node.keywords
            or len(node.args) != function.nin
            or any(isinstance(a, ast.Starred) for a in node.args)
        ):
            raise SceneError(
                field_name,
                f"{_source(node, text)!r}: {node.func.id} takes {function.nin} plain argument(s)",
                "pass positional arguments only, e.g. arctan2(y, x)",
            )
        arguments = [_build(argument, text, field_name) for argument in node.args]
        return lambda values: function(*(argument(values) for argument in arguments))
    raise SceneError(field_name, f"{_describe(node, text)} is not allowed in {text!r}", f"use {ALLOWED}")


def _describe(node: ast.AST, text: str) -> str:
    """Say what the refused node is, naming unknown names and functions."""
    if isinstance(node, ast.Name):
        kind = "function (call it)" if node.id in FUNCTIONS else "name"
        return f"{kind} {node.id!r}"
    if isinstance(node, ast.Call):
        return f"call {_source(node, text)!r}"
    return f"{type(node).__name__} {_source(node, text)!r}"


def _source(node: ast.AST, text: str) -> str:
    return ast.get_source_segment(text, node) or type(node).__name__


def _check_finite(result: np.ndarray, values: dict[str, np.ndarray], text: str, field_name: str) -> None:
    """Raise a SceneError listing the first points where ``result`` is NaN or infinite."""
    bad = np.argwhere(~np.isfinite(result))
    if len(bad) == 0:
        return
    points = "; ".join(
        ", ".join(
            f"{name}={np.broadcast_to(value, result.shape)[tuple(index)]:.6g}"
            for name, value in values.items()
        )
        for index in bad[:3]
    )
    more = f" and {len(bad) - 3} more points" if len(bad) > 3 else ""
    raise SceneError(
        field_name,
        f"{text!r} is not finite at {points}{more}",
        "keep the formula defined there (sqrt and log of negative numbers, division by zero)",
    )
