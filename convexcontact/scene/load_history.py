"""Load histories: the scene's loads, supports and obstacle motion as functions of time.

A :class:`History` holds the step times t₁ < t₂ < … (t₀ = 0 is the undeformed, unloaded
state) and, for each quantity that changes, its value at every step. A quantity is named by
its path in the scene:

- ``obstacle.depth``, ``obstacle.force``, ``obstacle.tangential_force``, ``obstacle.gap`` (the scene's one
  rigid obstacle)
- ``contact[INDEX].obstacle.depth`` (``gap``): the rigid obstacle ``contact[INDEX]`` among several contacts
- ``dirichlet[BOUNDARY].ux`` (``uy``, ``uz``): a prescribed displacement component
- ``traction[BOUNDARY].pressure``, ``traction[BOUNDARY].vector`` (a vector per step)
- ``body_force`` (a vector per step)

Quantities not named keep the scene's value at every step. Inertia is neglected (the
quasistatic problem of seed 002, eq. 2.2.1): the times matter only to viscous bodies and to
the outputs. A path that would change nothing in the scene it is given (a parabolic punch's
``gap``, the ``obstacle`` of a scene whose contacts are pairs of bodies) is refused by
:meth:`History.check`, with the path that does what was meant.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from .checks import SceneError, finite, finite_vector

PATH = re.compile(r"^(?:(?:contact\[(\d+)\]\.)?(obstacle)\.(depth|force|tangential_force|gap)"
                  r"|(dirichlet)\[([^\]]+)\]\.(ux|uy|uz)"
                  r"|(traction)\[([^\]]+)\]\.(pressure|vector)"
                  r"|(body_force))$")
PATHS = ("obstacle.depth", "obstacle.force", "obstacle.tangential_force", "obstacle.gap",
         "contact[INDEX].obstacle.depth|gap", "dirichlet[BOUNDARY].ux|uy|uz", "traction[BOUNDARY].pressure|vector",
         "body_force")
VECTORS = ("vector", "body_force")
SceneT = TypeVar("SceneT")
"""A scene (:class:`~convexcontact.scene.description.Scene`), which holds its History: this module reads and replaces
the scene's fields by name and never imports the dataclass, so that the two modules do not import each other."""


@dataclass(frozen=True)
class History:
    """Step times and the values each changing quantity takes at them (see the module docstring)."""

    times: Sequence[float]
    values: Mapping[str, Sequence]

    def __post_init__(self):
        if not listed(self.times) or len(self.times) == 0 or any(listed(t) for t in self.times):
            raise SceneError("history.times", f"expected a list of step times, got {self.times!r}",
                             "give times = [t1, t2, …], increasing and positive")
        times = numbers(self.times, "history.times")
        if times[0] <= 0 or any(b <= a for a, b in itertools.pairwise(times)):
            raise SceneError("history.times", f"must increase from above 0 (t0 = 0 is the unloaded state), got "
                             f"{list(times)}", "give strictly increasing positive times")
        if not isinstance(self.values, Mapping):
            raise SceneError("history.values", f"expected a mapping {{path: values}}, got {type(self.values).__name__}",
                             "give e.g. {'obstacle.depth': [0.01, 0.02]}")
        if not self.values:
            raise SceneError("history", "no quantity changes", "name at least one, e.g. 'obstacle.depth' = [...]")
        values = {}
        for path, series in self.values.items():
            match = PATH.match(path) if isinstance(path, str) else None
            if match is None:
                raise SceneError(f"history.{path}", "unknown quantity", f"use one of {', '.join(PATHS)}")
            if not listed(series) or len(series) != len(times):
                raise SceneError(f"history.{path}", f"{np.size(series)} values for {len(times)} step times",
                                 "give one value per step time")
            vector = path.rsplit(".", 1)[-1] in VECTORS
            values[path] = tuple(finite_vector(v, f"history.{path}[{i}]", (2, 3)) for i, v in enumerate(series)) \
                if vector else numbers(series, f"history.{path}")
            lengths = [len(v) for v in values[path]] if vector else [0]
            other = next((k for k, n in enumerate(lengths) if n != lengths[0]), None)
            if other is not None:
                raise SceneError(f"history.{path}[{other}]", f"{lengths[other]} components after {lengths[0]} at the "
                                 "first step", "give every step's vector the body's dimension")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    def __len__(self) -> int:
        return len(self.times)

    def check(self, scene: SceneT) -> None:
        """Every path changes something in ``scene`` (:func:`check_effect`), and every step's value is one the scene
        takes: the fields' own checks are bounds (finite, ≥ 0), so each series' smallest and largest value are
        tried, an error named ``history.PATH[k]``; viscous steps are long enough (:func:`check_steps`)."""
        if {"obstacle.depth", "obstacle.force"} <= set(self.values):
            raise SceneError("history.obstacle.force", "given with 'obstacle.depth': an obstacle is moved by its "
                             "depth or pressed by a force, not both", "keep one of the two paths")
        for path, series in self.values.items():
            check_effect(scene, path)
            tried = (0,) if np.ndim(series[0]) else (int(np.argmin(series)), int(np.argmax(series)))
            for k in dict.fromkeys(tried):
                try:
                    at(scene, path, series[k])
                except SceneError as error:
                    if error.field.startswith("history."):
                        raise
                    raise SceneError(f"history.{path}[{k}]", f"{error} (the value {series[k]!r} at t = "
                                     f"{self.times[k]:g})") from None
        check_steps(scene, self.times)

    def scene(self, scene: SceneT, step: int) -> SceneT:
        """The scene at step ``step`` (0-based) of this history."""
        for path, series in self.values.items():
            scene = at(scene, path, series[step])
        return scene

    def envelope(self, scene: SceneT) -> SceneT:
        """The scene with each quantity at its largest magnitude over the history: it sets the units."""
        for path, series in self.values.items():
            magnitudes = np.abs(np.asarray(series, dtype=float)).reshape(len(series), -1).max(axis=1)
            scene = at(scene, path, series[int(np.argmax(magnitudes))])
        return scene


def listed(value) -> bool:
    """Whether ``value`` is a list of values (a string is not; ragged lists are, unlike for np.ndim)."""
    return isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes))


def numbers(series, field_name: str) -> tuple[float, ...]:
    """``series`` as finite floats, each checked by :func:`finite` (a million steps at once where all are plain
    numbers: one check per value took seconds)."""
    plain = isinstance(series, np.ndarray) or all(type(v) in (float, int) for v in series)  # no bool, no string
    array = np.asarray(series) if plain else None
    if array is not None and array.ndim == 1 and array.dtype.kind in "fi" and np.isfinite(array).all():
        return tuple(array.astype(float).tolist())
    return tuple(finite(v, f"{field_name}[{i}]") for i, v in enumerate(series))


def at(scene: SceneT, path: str, value) -> SceneT:
    """``scene`` with the quantity ``path`` set to ``value``; the dataclasses validate the value."""
    index, obstacle, name, dirichlet, where, component, _, loaded, load, body_force = PATH.match(path).groups()
    if index is not None:
        pairs = list(scene.contact.pairs)
        pairs[int(index)] = replace(pairs[int(index)], obstacle=replace(pairs[int(index)].obstacle, **{name: value}))
        return replace(scene, contact=replace(scene.contact, pairs=tuple(pairs)))
    if obstacle:
        contact = scene.contact
        return replace(scene, contact=replace(contact, obstacle=replace(contact.obstacle, **{name: value})))
    if body_force:
        return replace(scene, body_force=value)
    if dirichlet:
        return replace(scene, dirichlet=set_on(scene.dirichlet, where, component, value, path, "dirichlet"))
    return replace(scene, tractions=set_on(scene.tractions, loaded, load, value, path, "traction"))


def check_effect(scene: SceneT, path: str) -> None:
    """Refuse an obstacle path that would change nothing in ``scene`` (three identical steps, solved without a
    word), saying why and which path moves what was meant."""
    index, obstacle, name = PATH.match(path).groups()[:3]
    if not obstacle:
        return
    field_name, contact = f"history.{path}", scene.contact
    pairs = getattr(contact, "pairs", None)  # several contacts (scene/bodies.py, which imports this module)
    rigid = [i for i, pair in enumerate(pairs or ()) if not hasattr(pair, "master")]
    moving = "move a body through a Dirichlet value instead, e.g. 'dirichlet[BODY.top].uy'"
    if index is None and pairs is not None:
        raise SceneError(field_name, "the scene has several contacts, so no one obstacle: the path changes nothing",
                         f"name the obstacle among them: 'contact[{rigid[0]}].obstacle.{name}'" if rigid else moving)
    if index is None and hasattr(contact, "master"):
        raise SceneError(field_name, f"the scene's contact is a pair of bodies ({contact.boundary!r} on "
                         f"{contact.master!r}), which has no rigid obstacle: the path changes nothing", moving)
    if index is not None:
        if int(index) not in rigid:
            raise SceneError(field_name, f"contact[{index}] is not a rigid obstacle of the scene (those are "
                             f"contact{rigid})" if rigid else "the scene has no rigid obstacle among its contacts",
                             f"use one of {[f'contact[{i}].obstacle.depth' for i in rigid]}" if rigid else moving)
        if name not in ("depth", "gap"):
            raise SceneError(field_name, "an obstacle among several contacts is moved by its depth, not pressed by "
                             "a force", f"use 'contact[{index}].obstacle.depth'")
        contact = pairs[int(index)]
    prefix = "" if index is None else f"contact[{index}]."
    shape, force = contact.obstacle.shape, contact.obstacle.force
    if name == "gap" and shape != "flat":
        raise SceneError(field_name, f"a {shape} obstacle's gap comes from its shape (the gap is read only for a "
                         "flat one): the path changes nothing", f"move it by '{prefix}obstacle.depth'")
    if name in ("gap", "depth") and force is not None:
        why = "the gap only shifts that unknown: the path changes nothing" if name == "gap" else "it cannot be given"
        raise SceneError(field_name, f"the obstacle is pressed by a force (force = {force:g}), its depth an unknown of "
                         f"each step: {why}", "change 'obstacle.force' over the history, or give the scene's obstacle "
                         "a depth instead of its force")
    if name == "force" and contact.obstacle.depth is not None:
        raise SceneError(field_name, f"the obstacle is moved by its depth (depth = {contact.obstacle.depth:g}): it "
                         "cannot be pressed by a force too", "change 'obstacle.depth' over the history, or drop the "
                         "scene obstacle's depth (force control)")


VISCOUS_RATIO = 1e12
"""Most τ/Δt of a viscous step. K + K_A/Δt = (1 + τ/Δt) K where A = τ B: the step's displacement increment is then
known only to about ε·τ/Δt of the displacement (2e-4 at the bound), and beyond 1e308 the matrix overflows
(η = 1e200 with Δt = 1e-200 ended "inaccurate" with a certificate of 0)."""


def check_steps(scene: SceneT, times: tuple[float, ...]) -> None:
    """Refuse a viscous step Δt so short against a material's retardation time τ = η/E that K drowns in K_A/Δt
    (:data:`VISCOUS_RATIO`); compared by logarithms, since τ/Δt may be beyond the floats."""
    materials = scene.materials if isinstance(scene.materials, Mapping) else {"material": scene.materials}
    viscous = {name: m for name, m in materials.items() if m.viscosity > 0}
    if not viscous:
        return
    steps = np.diff((0.0, *times))
    k = int(np.argmin(steps))
    name, material = max(viscous.items(), key=lambda item: math.log10(item[1].viscosity) - math.log10(item[1].E))
    log_tau = math.log10(material.viscosity) - math.log10(material.E)
    if log_tau - math.log10(steps[k]) > math.log10(VISCOUS_RATIO):
        raise SceneError(f"history.times[{k}]", f"a step of Δt = {steps[k]:.3g} against the retardation time τ = η/E "
                         f"= {power(log_tau)} of {name}: K_A/Δt is {power(log_tau - math.log10(steps[k]))} times K, "
                         "and the step's increment is lost in round-off (beyond 1e308 the matrix overflows)",
                         f"take steps of at least τ/{VISCOUS_RATIO:.0e} = {power(log_tau - 12)}, or a smaller "
                         f"viscosity for {name}")


def power(log10: float) -> str:
    """10**log10 written out, also beyond the floats."""
    exponent = math.floor(log10)
    return f"{10 ** (log10 - exponent):.3g}e{exponent:+d}"


def set_on(items: tuple, boundary: str, name: str, value, path: str, table: str) -> tuple:
    """``items`` (Dirichlet conditions or tractions) with ``name`` set on the one of ``boundary``, which must
    exist and have that field given (its value at t = 0 is then irrelevant)."""
    matching = [item for item in items if item.boundary == boundary]
    if not matching or getattr(matching[0], name) is None:
        given = [item.boundary for item in items if getattr(item, name) is not None]
        raise SceneError(f"history.{path}", f"the scene has no [[{table}]] {name} on {boundary!r}",
                         f"add a [[{table}]] boundary = {boundary!r} with {name} (its value at t = 0)"
                         + (f", or name a boundary that has one: {given}" if given else ""))
    return tuple(replace(item, **{name: value}) if item.boundary == boundary else item for item in items)
