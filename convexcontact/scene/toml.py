"""Scene files: TOML → the dataclasses of :mod:`convexcontact.scene.description`.

This module only maps keys to fields and checks TOML types; every value is
validated by the model. Unknown keys are errors, never ignored. The schema is
described in docs/scenes.md.
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .bodies import Pair, Part, bodies_scene
from .description import (
    Body,
    Box,
    Contact,
    Coulomb,
    Dirichlet,
    Material,
    MeshFile,
    NormalCompliance,
    Obstacle,
    Rectangle,
    Scene,
    SceneError,
    Signorini,
    Traction,
    Tresca,
    check_shape_fields,
    of_type,
)
from .load_history import History

NUMBER, INTEGER, TEXT, PAIR = "a number", "an integer", "a string", "two numbers [a, b]"
BOOLEAN = "true or false"
TRIPLE, INTEGERS3 = "three numbers [a, b, c]", "three integers [nx, ny, nz]"
VECTOR, POINT = "two or three numbers (2-D or 3-D)", "a number (2-D) or a point [x, y, z] (3-D)"
FIELD = "a number or a formula in x and y"
TABLE, TABLES = "a table [name]", "an array of tables [[name]]"
TABLE_OR_TABLES = "a table [name] or an array of tables [[name]]"

TOP = {
    "name": TEXT, "body_force": VECTOR, "body": TABLE, "material": TABLE, "materials": TABLE,
    "dirichlet": TABLES, "traction": TABLES, "contact": TABLE, "obstacle": TABLE, "history": TABLE,
}
BODY = {"mesh": TEXT, "element": TEXT, "plane": TEXT}
BODIES_TOP = {"name": TEXT, "body_force": VECTOR, "bodies": TABLES, "dirichlet": TABLES, "traction": TABLES,
              "contact": TABLE_OR_TABLES, "obstacle": TABLE, "history": TABLE}
PART = {"name": TEXT, "material": TABLE, "offset": VECTOR}
PAIR_KEYS = {"master": TEXT, "method": TEXT}
RECTANGLE = {
    **BODY, "width": NUMBER, "height": NUMBER, "origin": PAIR, "nx": INTEGER, "ny": INTEGER,
    "grading": PAIR, "refine_x": NUMBER, "refine_y": TEXT,
}
BOX = {**BODY, "size": TRIPLE, "cells": INTEGERS3, "origin": TRIPLE, "grading": TRIPLE, "refine": TRIPLE}
MATERIAL = {"E": NUMBER, "nu": NUMBER, "viscosity": NUMBER, "yield_stress": NUMBER, "plastic_viscosity": NUMBER}
DIRICHLET = {"boundary": TEXT, "ux": NUMBER, "uy": NUMBER, "uz": NUMBER}
TRACTION = {"boundary": TEXT, "pressure": NUMBER, "vector": VECTOR}
CONTACT = {"boundary": TEXT, "law": TEXT}
OBSTACLE = {"shape": TEXT, "gap": NUMBER, "radius": NUMBER, "center": POINT, "expression": TEXT, "depth": NUMBER,
            "force": NUMBER, "tangential_force": NUMBER, "normal": TEXT}
"""The keys of [obstacle]; which of them a shape reads is the model's check (:func:`check_shape_fields`)."""

COMPLIANCE = {"stiffness": NUMBER, "exponent": NUMBER}
FRICTION_OPTIONS = {"non_penetration": TEXT, "quadrature": TEXT, "regularization": NUMBER, **COMPLIANCE}
LAWS = {
    # law name → (model class, its keys in [contact] besides boundary and law); with friction,
    # stiffness (and exponent) switch the normal law to normal compliance
    "signorini": (Signorini, {"non_penetration": TEXT, "order": INTEGER}),
    "normal_compliance": (NormalCompliance, {**COMPLIANCE, "non_penetration": TEXT, "order": INTEGER}),
    "tresca": (Tresca, {"slip_bound": FIELD, **FRICTION_OPTIONS}),
    "coulomb": (Coulomb, {
        "friction": FIELD, "smoothing_radius": NUMBER, "relaxation": NUMBER, "tol": NUMBER,
        "max_iterations": INTEGER, "initial_pressure": FIELD, "acceleration": INTEGER, "newton": BOOLEAN,
        **FRICTION_OPTIONS,
    }),
}

EXAMPLES = {
    "body": '[body]\nmesh = "rectangle"\nwidth = 1.0\nheight = 1.0\nnx = 16\nny = 16',
    "body.mesh": 'mesh = "rectangle" (built-in, boundaries left/right/bottom/top), mesh = "box" (3-D, '
                 'left/right/front/back/bottom/top) or mesh = "part.msh"',
    "material": "[material]\nE = 1.0\nnu = 0.3\n(or one [materials.NAME] table per mesh subdomain)",
    "history.times": '[history]\ntimes = [1.0, 2.0]\n"obstacle.depth" = [0.01, 0.02]',
    "E": "E = 1.0",
    "nu": "nu = 0.3",
    "dirichlet": '[[dirichlet]]\nboundary = "bottom"\nux = 0.0\nuy = 0.0',
    "contact": '[contact]\nboundary = "top"\nlaw = "signorini"',
    "boundary": 'boundary = "top"',
}


def load_scene(path) -> Scene:
    """Read the TOML scene file at ``path``; mesh paths are relative to its folder."""
    path = Path(of_type(path, (str, os.PathLike), "path", "give the scene file's path, e.g. load_scene('scene.toml')"))
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise SceneError("toml", f"cannot read {path}: {error.strerror or error}",
                         "give the path of a scene file (examples/scenes/*.toml; docs/scenes.md)") from None
    except UnicodeDecodeError as error:
        raise SceneError("toml", f"{path.name} is not UTF-8 text ({error.reason})",
                         "a scene file is TOML text (docs/scenes.md)") from None
    except tomllib.TOMLDecodeError as error:
        raise SceneError("toml", f"{path.name}: {_decode_message(error)}", "fix the TOML syntax there") from None
    data.setdefault("name", path.stem)
    return scene_from_dict(data, path.parent)


def scene_from_dict(data: dict, base_dir: Path | str = ".") -> Scene:
    """Build a :class:`Scene` from parsed TOML ``data``; mesh paths are relative to ``base_dir``."""
    if isinstance(data, dict) and "bodies" in data:
        return _bodies(data, Path(base_dir))
    data = _table(data, "", TOP, required=("body", "dirichlet", "contact"))
    if "material" in data and "materials" in data:
        raise SceneError("material", "both [material] and [materials.NAME] given", "keep one of them")
    if "material" not in data and "materials" not in data:
        raise SceneError("material", "missing", "add, for example:\n" + EXAMPLES["material"])
    if "material" in data:
        materials = Material(**_table(data["material"], "material", MATERIAL, required=("E", "nu")))
    else:
        materials = {
            name: Material(**_table(entry, f"materials.{name}", MATERIAL, required=("E", "nu")), name=f"materials.{name}")
            for name, entry in _table(data["materials"], "materials", None).items()
        }
    scene = Scene(
        body=_body(data["body"], Path(base_dir)),
        materials=materials,
        dirichlet=[Dirichlet(**entry) for entry in _entries(data, "dirichlet", DIRICHLET)],
        tractions=[Traction(**entry) for entry in _entries(data, "traction", TRACTION)],
        contact=_contact(data["contact"], data.get("obstacle", {})),
        **{key: data[key] for key in ("name", "body_force") if key in data},
        history=_history(data["history"]) if "history" in data else None,
    )
    if scene.history is not None:
        scene.history.check(scene)
    return scene


def _history(table) -> History:
    """``[history]``: ``times = [...]`` and one array per quantity that changes, keyed by its quoted path."""
    table = _table(table, "history", None, required=("times",))
    for key, series in table.items():
        if not isinstance(series, list):
            raise SceneError(f"history.{key}", f"expected an array with a value per step, got {series!r}",
                             f'write "{key}" = [v1, v2, …] (quote paths such as "obstacle.depth")')
    times = table.pop("times")
    return History(times=times, values=table)


def _bodies(data: dict, base_dir: Path) -> Scene:
    """Several bodies: ``[[bodies]]`` tables (a body's keys, its ``name``, ``material`` and ``offset``), boundaries
    named ``body.boundary``, and a ``[contact]`` pair (``master``, ``method``) or a rigid obstacle."""
    data = _table(data, "", BODIES_TOP, required=("bodies", "dirichlet", "contact"))
    parts = []
    for i, entry in enumerate(data["bodies"]):
        path = f"bodies[{_label(entry, i, 'name')}]"
        table = _table(entry, path, None, required=("name", "material"))
        part = {key: table.pop(key) for key in PART if key in table}
        _table(part, path, PART)
        body = _body(table, base_dir, path, PART)
        material = Material(**_table(part.pop("material"), f"{path}.material", MATERIAL, required=("E", "nu")),
                            name=f"{path}.material")
        parts.append(Part(geometry=body.geometry, element=body.element, plane=body.plane, material=material, **part))
    scene = bodies_scene(
        parts,
        contact=_contact(data["contact"], data.get("obstacle", {}), PAIR_KEYS) if isinstance(data["contact"], dict)
        else [_pair(table, i) for i, table in enumerate(data["contact"])],
        dirichlet=[Dirichlet(**entry) for entry in _entries(data, "dirichlet", DIRICHLET)],
        tractions=[Traction(**entry) for entry in _entries(data, "traction", TRACTION)],
        **{key: data[key] for key in ("name", "body_force") if key in data},
        history=_history(data["history"]) if "history" in data else None,
    )
    if scene.history is not None:
        scene.history.check(scene)
    return scene


def _pair(table, index: int) -> Contact:
    """One ``[[contact]]`` table of several: a pair (``master``) or a rigid obstacle (``obstacle = {shape = …}``)."""
    table = dict(_table(table, f"contact[{index}]", None))  # a copy: the user's table keeps its obstacle
    obstacle = table.pop("obstacle", None)
    if "master" in table:
        _check_type(table["master"], TEXT, f"contact[{index}].master")
    if obstacle is None and "master" not in table:
        raise SceneError(f"contact[{index}].master", "missing: each [[contact]] table of several is a pair of bodies "
                         "or a rigid obstacle", "name the master boundary, e.g. master = 'foundation.top', or give "
                         "obstacle = { shape = 'flat', gap = 0.0 }")
    return _contact(table, obstacle or {}, PAIR_KEYS, f"contact[{index}]")


def _body(table, base_dir: Path, path: str = "body", extra: dict | None = None) -> Body:
    """A body's table at ``path``; ``extra``: further keys its table may hold (checked by the caller)."""
    mesh = _table(table, path, None, required=("mesh",))["mesh"]
    _check_type(mesh, TEXT, f"{path}.mesh")
    built_in = {"rectangle": (Rectangle, RECTANGLE), "box": (Box, BOX)}
    if mesh in built_in:
        keys = _table(table, path, built_in[mesh][1] | (extra or {}), context=f' with mesh = "{mesh}"')
    else:
        keys = _table(table, path, BODY | (extra or {}), context=" with a mesh file")
    del keys["mesh"]
    options = {key: keys.pop(key) for key in ("element", "plane") if key in keys}
    geometry = built_in[mesh][0](**keys) if mesh in built_in else MeshFile(base_dir / mesh)
    return Body(geometry, **options)


def _contact(table, obstacle, pair: dict | None = None, path: str = "contact") -> Contact:
    """``[contact]`` and ``[obstacle]``; with ``pair`` (several bodies) a ``master`` makes it a :class:`Pair`.
    ``path``: the table's name in errors (``contact[1]`` of several)."""
    law_name = _table(table, path, None).get("law", "signorini")
    _check_type(law_name, TEXT, f"{path}.law")
    if law_name not in LAWS:
        raise SceneError(f"{path}.law", f"unknown law {law_name!r}", f"available laws: {', '.join(LAWS)}")
    law, law_keys = LAWS[law_name]
    keys = _table(table, path, CONTACT | law_keys | (pair or {}), required=("boundary",))
    obstacle = _table(obstacle, "obstacle", OBSTACLE)
    _check_type(obstacle.get("shape", "flat"), TEXT, "obstacle.shape")
    check_shape_fields(obstacle.get("shape", "flat"), obstacle)
    options = {key: keys[key] for key in law_keys if key in keys}
    if law is NormalCompliance and "stiffness" not in options:
        raise SceneError("contact.stiffness", "missing: law = 'normal_compliance' needs its stiffness c_N",
                         "add stiffness = c_N (a pressure per length^p), e.g. stiffness = 1e4")
    if law is not NormalCompliance and "stiffness" in options:
        options["compliance"] = NormalCompliance(options.pop("stiffness"), options.pop("exponent", 1.0))
    elif law is not NormalCompliance and "exponent" in options:
        raise SceneError("contact.exponent", "an exponent without a stiffness", "add stiffness = c_N (normal compliance)")
    if "master" in keys:
        if obstacle:
            raise SceneError("obstacle", "a pair of bodies has no rigid obstacle", "drop the [obstacle] table")
        return Pair(boundary=keys["boundary"], law=law(**options),
                    **{key: keys[key] for key in PAIR_KEYS if key in keys})
    return Contact(
        boundary=keys["boundary"],
        obstacle=Obstacle(**obstacle),
        law=law(**options),
    )


def _entries(data: dict, name: str, spec: dict) -> list[dict]:
    """The tables of the array ``[[name]]``, each checked against ``spec``."""
    return [
        _table(entry, f"{name}[{_label(entry, i)}]", spec, required=("boundary",))
        for i, entry in enumerate(data.get(name, []))
    ]


def _label(entry, index: int, key: str = "boundary"):
    label = entry.get(key) if isinstance(entry, dict) else None
    return label if isinstance(label, str) else index


def _table(value, path: str, spec: dict | None, required: tuple = (), context: str = "") -> dict:
    """Check that ``value`` is a table with only ``spec``'s keys, of ``spec``'s types (None: any keys)."""
    if not isinstance(value, dict):
        raise SceneError(path, f"expected {TABLE.replace('name', path)}, got {value!r}")
    prefix = f"{path}." if path else ""
    if spec is not None:
        for key in value:
            if key not in spec:
                raise SceneError(prefix + key, "unknown key", _allowed(key, path, spec, context))
            _check_type(value[key], spec[key], prefix + key)
    for key in required:
        if key not in value:
            example = EXAMPLES.get(key if key in ("E", "nu", "boundary") else prefix + key)
            raise SceneError(prefix + key, "missing", f"add, for example:\n{example}" if example else "")
    return dict(value)


def _allowed(key: str, path: str, spec: dict, context: str) -> str:
    where = f"in [{path}]{context}" if path else "at the top level"
    hint = f"allowed keys {where}: {', '.join(spec)}"
    close = difflib.get_close_matches(key, spec, n=1)
    if close:
        hint = f"did you mean {close[0]!r}? " + hint
    if path and key in TOP:
        hint += f"; top-level keys such as {key!r} must come before the first [table] header"
    return hint


def _check_type(value, kind: str, path: str) -> None:
    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    ok = {
        NUMBER: number(value),
        INTEGER: isinstance(value, int) and not isinstance(value, bool),
        BOOLEAN: isinstance(value, bool),
        TEXT: isinstance(value, str),
        PAIR: isinstance(value, list) and len(value) == 2 and all(number(x) for x in value),
        TRIPLE: isinstance(value, list) and len(value) == 3 and all(number(x) for x in value),
        INTEGERS3: isinstance(value, list) and len(value) == 3
        and all(isinstance(x, int) and not isinstance(x, bool) for x in value),
        VECTOR: isinstance(value, list) and len(value) in (2, 3) and all(number(x) for x in value),
        POINT: number(value) or (isinstance(value, list) and len(value) == 3 and all(number(x) for x in value)),
        FIELD: number(value) or isinstance(value, str),
        TABLE: isinstance(value, dict),
        TABLES: isinstance(value, list) and all(isinstance(x, dict) for x in value),
        TABLE_OR_TABLES: isinstance(value, dict) or (isinstance(value, list) and all(isinstance(x, dict) for x in value)),
    }[kind]
    if not ok:
        raise SceneError(path, f"expected {kind.replace('name', path)}, got {value!r}")


def _decode_message(error: Exception) -> str:
    """'line L, column C: problem' from a TOMLDecodeError (its message on Python < 3.14)."""
    message = str(error)
    if getattr(error, "lineno", None):
        return f"line {error.lineno}, column {error.colno}: {getattr(error, 'msg', message)}"
    found = re.fullmatch(r"(.*) \(at line (\d+), column (\d+)\)", message, flags=re.DOTALL)
    return f"line {found[2]}, column {found[3]}: {found[1]}" if found else message
