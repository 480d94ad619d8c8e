"""Load histories: the scene's loads, supports and obstacle motion as functions of time.

A :class:`History` holds the step times t₁ < t₂ < … (t₀ = 0 is the undeformed, unloaded
state) and, for each quantity that changes, its value at every step. A quantity is named by
its path in the scene:

- ``obstacle.depth``, ``obstacle.force``, ``obstacle.tangential_force``, ``obstacle.gap``
- ``dirichlet[BOUNDARY].ux`` (``uy``, ``uz``): a prescribed displacement component
- ``traction[BOUNDARY].pressure``, ``traction[BOUNDARY].vector`` (a vector per step)
- ``body_force`` (a vector per step)

Quantities not named keep the scene's value at every step. Inertia is neglected (the
quasistatic problem of seed 002, eq. 2.2.1): the times matter only to viscous bodies and to
the outputs.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from .checks import SceneError, finite, finite_vector

if TYPE_CHECKING:
    from .model import Scene

PATH = re.compile(r"^(?:(obstacle)\.(depth|force|tangential_force|gap)"
                  r"|(dirichlet)\[([^\]]+)\]\.(ux|uy|uz)"
                  r"|(traction)\[([^\]]+)\]\.(pressure|vector)"
                  r"|(body_force))$")
PATHS = ("obstacle.depth", "obstacle.force", "obstacle.tangential_force", "obstacle.gap",
         "dirichlet[BOUNDARY].ux|uy|uz", "traction[BOUNDARY].pressure|vector", "body_force")
VECTORS = ("vector", "body_force")


@dataclass(frozen=True)
class History:
    """Step times and the values each changing quantity takes at them (see the module docstring)."""

    times: Sequence[float]
    values: Mapping[str, Sequence]

    def __post_init__(self):
        if np.ndim(self.times) != 1 or len(self.times) == 0:
            raise SceneError("history.times", f"expected a list of step times, got {self.times!r}",
                             "give times = [t1, t2, …], increasing and positive")
        times = tuple(finite(t, f"history.times[{i}]") for i, t in enumerate(self.times))
        if times[0] <= 0 or any(b <= a for a, b in itertools.pairwise(times)):
            raise SceneError("history.times", f"must increase from above 0 (t0 = 0 is the unloaded state), got "
                             f"{list(times)}", "give strictly increasing positive times")
        if not isinstance(self.values, Mapping) or not self.values:
            raise SceneError("history", "no quantity changes", "name at least one, e.g. 'obstacle.depth' = [...]")
        values = {}
        for path, series in self.values.items():
            match = PATH.match(path) if isinstance(path, str) else None
            if match is None:
                raise SceneError(f"history.{path}", "unknown quantity", f"use one of {', '.join(PATHS)}")
            if np.ndim(series) == 0 or len(series) != len(times):
                raise SceneError(f"history.{path}", f"{np.size(series)} values for {len(times)} step times",
                                 "give one value per step time")
            vector = path.rsplit(".", 1)[-1] in VECTORS
            values[path] = tuple(finite_vector(v, f"history.{path}[{i}]", (2, 3)) if vector
                                 else finite(v, f"history.{path}[{i}]") for i, v in enumerate(series))
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    def __len__(self) -> int:
        return len(self.times)

    def check(self, scene: Scene) -> None:
        """Every named boundary exists in the scene, with the component or load the path changes."""
        for path in self.values:
            at(scene, path, self.values[path][0])

    def scene(self, scene: Scene, step: int) -> Scene:
        """The scene at step ``step`` (0-based) of this history."""
        for path, series in self.values.items():
            scene = at(scene, path, series[step])
        return scene

    def envelope(self, scene: Scene) -> Scene:
        """The scene with each quantity at its largest magnitude over the history: it sets the units."""
        for path, series in self.values.items():
            scene = at(scene, path, max(series, key=lambda v: float(np.max(np.abs(v)))))
        return scene


def at(scene: Scene, path: str, value) -> Scene:
    """``scene`` with the quantity ``path`` set to ``value``; the dataclasses validate the value."""
    obstacle, name, dirichlet, where, component, _, loaded, load, body_force = PATH.match(path).groups()
    if obstacle:
        contact = scene.contact
        return replace(scene, contact=replace(contact, obstacle=replace(contact.obstacle, **{name: value})))
    if body_force:
        return replace(scene, body_force=value)
    if dirichlet:
        return replace(scene, dirichlet=set_on(scene.dirichlet, where, component, value, path, "dirichlet"))
    return replace(scene, tractions=set_on(scene.tractions, loaded, load, value, path, "traction"))


def set_on(items: tuple, boundary: str, name: str, value, path: str, table: str) -> tuple:
    """``items`` (Dirichlet conditions or tractions) with ``name`` set on the one of ``boundary``, which must
    exist and have that field given (its value at t = 0 is then irrelevant)."""
    matching = [item for item in items if item.boundary == boundary]
    if not matching or getattr(matching[0], name) is None:
        raise SceneError(f"history.{path}", f"the scene has no [[{table}]] {name} on {boundary!r}",
                         f"add a [[{table}]] boundary = {boundary!r} with {name} (its value at t = 0)")
    return tuple(replace(item, **{name: value}) if item.boundary == boundary else item for item in items)
