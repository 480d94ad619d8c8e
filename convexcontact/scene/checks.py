"""Checks of user input where it enters: :class:`SceneError` names the field and the fix.

Shared by the scene's dataclasses (:mod:`.model`), its expressions and its history, so that
none of them imports another for its errors.
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


def finite(value, field_name: str) -> float:
    """Return ``value`` as a float, refusing NaN, infinity and non-numbers (strings, booleans)."""
    if isinstance(value, (str, bool, np.bool_)):
        raise SceneError(field_name, f"expected a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise SceneError(field_name, f"expected a number, got {value!r}") from None
    if not math.isfinite(number):
        raise SceneError(field_name, f"got {value!r}", "give a finite number")
    return number


def finite_vector(value, field_name: str, length: int | tuple[int, ...] = 2) -> tuple[float, ...]:
    """Return ``value`` as a tuple of ``length`` finite floats (``length`` may list the lengths allowed)."""
    lengths = (length,) if isinstance(length, int) else length
    if np.ndim(value) != 1 or len(value) not in lengths:
        expected = " or ".join(str(n) for n in lengths)
        raise SceneError(field_name, f"expected {expected} numbers, got {value!r}")
    return tuple(finite(v, f"{field_name}[{i}]") for i, v in enumerate(value))


def positive_integer(value, field_name: str) -> int:
    """Return ``value`` if it is an integer ≥ 1 (booleans refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 1:
        raise SceneError(field_name, f"expected a positive integer, got {value!r}")
    return int(value)
