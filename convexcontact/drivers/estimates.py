"""Estimates of a run's cost before it is paid: durations as people read them, and the memory a result holds."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..scene.description import Scene

LONG_RUN = 3600.0
"""Seconds a run (a history, a search for every solution, a bench or a study) may be estimated to take before it is
refused or, where the call takes ``confirm``, needs it: a 10⁶-step history of a small scene ran about 4 hours, and a
search over 1,001 contact nodes for hours, without a word."""


def duration(seconds: float) -> str:
    """``seconds`` in hours beyond an hour, else in minutes."""
    return f"{seconds / 3600:.3g} h" if seconds > 3600 else f"{seconds / 60:.3g} min"


def reachable(objects) -> set[int]:
    """Ids of everything :func:`footprint` walks from ``objects``."""
    seen: set[int] = set()
    footprint(objects, seen)
    return seen


def footprint(root, seen: set[int]) -> int:
    """Bytes of the arrays (dense and sparse) reachable from ``root`` through this package's objects, containers and
    arrays, leaving out what ``seen`` holds (updated): what a step's result adds to the ones before it (the mesh,
    the basis and K are shared). Written by hand: sys.getsizeof does not follow references, and tracemalloc slows
    the whole run."""
    total, stack = 0, [root]
    while stack:
        item = stack.pop()
        if id(item) in seen:
            continue
        seen.add(id(item))
        if isinstance(item, np.ndarray):
            total += item.nbytes if item.base is None else 0
            stack += [] if item.base is None else [item.base]
        elif sp.issparse(item):
            stack += [getattr(item, name) for name in ("data", "indices", "indptr", "row", "col", "coords")
                      if isinstance(getattr(item, name, None), np.ndarray)]
        elif isinstance(item, dict):
            stack += list(item.values())
        elif isinstance(item, (list, tuple)):
            stack += list(item)
        elif isinstance(item, Scene):  # the user's, its history shared by every step
            continue
        elif type(item).__module__.startswith("convexcontact") and hasattr(item, "__dict__"):
            stack += list(vars(item).values())
    return total
