"""Checks of user input where it enters: :class:`SceneError` names the field and the fix.

Shared by the scene's dataclasses (:mod:`.description`), its expressions and its load history
(:mod:`.load_history`), so that none of them imports another for its errors.
"""

from __future__ import annotations

import math

import numpy as np


class SceneError(ValueError):
    """A scene field is missing, malformed or physically meaningless."""

    def __init__(self, field_name: str, problem: str, fix: str = ""):
        self.field = field_name
        message = f"{field_name}: {problem}"
        super().__init__(message + (f" — {fix}" if fix else ""))


def finite(value, field_name: str, fix: str = "") -> float:
    """Return ``value`` as a float, refusing NaN, infinity, integers beyond the floats and non-numbers
    (strings, booleans)."""
    fix = fix or "give a finite number"
    if isinstance(value, (str, bool, np.bool_)):
        raise SceneError(field_name, f"expected a number, got {value!r:.60}", fix)
    try:
        number = float(value)
    except OverflowError:  # a 400-digit integer
        raise SceneError(field_name, f"{len(str(value))}-digit number, beyond the floats",
                         "write numbers below 1.8e308, in scientific notation if need be") from None
    except (TypeError, ValueError):
        raise SceneError(field_name, f"expected a number, got {value!r:.60}", fix) from None
    if not math.isfinite(number):
        raise SceneError(field_name, f"got {value!r}", fix)
    return number


def finite_vector(value, field_name: str, length: int | tuple[int, ...] = 2) -> tuple[float, ...]:
    """Return ``value`` as a tuple of ``length`` finite floats (``length`` may list the lengths allowed)."""
    lengths = (length,) if isinstance(length, int) else length
    if np.ndim(value) != 1 or len(value) not in lengths:
        expected = " or ".join(str(n) for n in lengths)
        raise SceneError(field_name, f"expected {expected} numbers, got {value!r:.60}",
                         f"give a list of {expected} finite numbers, e.g. {[0.0] * lengths[0]}")
    return tuple(finite(v, f"{field_name}[{i}]") for i, v in enumerate(value))


def positive_integer(value, field_name: str, fix: str = "") -> int:
    """Return ``value`` if it is an integer ≥ 1 (booleans refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise SceneError(field_name, f"expected a positive integer, got {value!r:.60}",
                         fix or "give a whole number ≥ 1")
    return int(value)


def of_type(value, kinds: type | tuple[type, ...], field_name: str, fix: str = ""):
    """Return ``value`` if it is one of ``kinds`` (booleans are not numbers), else a SceneError naming the field."""
    kinds = kinds if isinstance(kinds, tuple) else (kinds,)
    if not isinstance(value, kinds) or (isinstance(value, (bool, np.bool_)) and bool not in kinds):
        expected = " or ".join(kind.__name__ for kind in kinds)
        shown = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
        raise SceneError(field_name, f"expected {expected}, got {type(value).__name__} {shown}",
                         fix or f"give a {expected}")
    return value


def sequence_of(values, kind: type, field_name: str, fix: str = "") -> tuple:
    """``values`` as a tuple of ``kind`` items (a lone item or a string is refused, not split into characters)."""
    if isinstance(values, (str, bytes, kind)) or not hasattr(values, "__iter__"):
        raise SceneError(field_name, f"expected a list of {kind.__name__}, got {type(values).__name__} {values!r:.60}",
                         fix)
    return tuple(of_type(value, kind, f"{field_name}[{i}]", fix) for i, value in enumerate(values))
