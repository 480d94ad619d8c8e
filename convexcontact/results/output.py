"""Writing a result: summary.json, solution.vtu (meshio) and PNG plots."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from skfem.io.meshio import to_meshio

from ..scene.bodies import Bodies
from .fields_out import vertex_contact, vertex_displacement

FORMATS = ("json", "vtk", "png")


def write_json(result, path: Path):
    path.write_text(json.dumps(result.summary(), indent=1))


def write_vtk(result, path: Path):
    """Mesh in user units with displacement, contact pressure (point data) and stresses (cell data)."""
    fem = result.fem
    point_data = {
        "displacement": vertex_displacement(result),
        "contact_pressure": vertex_contact(result, result.contact.pressure),
    }
    if result.contact.friction is not None:
        point_data["friction_traction"] = vertex_contact(result, result.contact.friction)
    cell_data = {name: [values] for name, values in result.cell_fields().items()}
    if result.error_estimate is not None:  # η_T per cell, user energy units (docs/estimate.md)
        cell_data["error_indicator"] = [np.sqrt(result.error_estimate.indicators * fem.scaling.energy)]
    if isinstance(fem.scene.body, Bodies):
        cell_data["body"] = [fem.scene.body.body_ids(fem.mesh)]
    if result.contact.master_forces is not None:  # on the slave nodes and, transferred, on the master's
        point_data["contact_force"] = vertex_contact(result, result.contact.forces) + vertex_contact(
            result, result.contact.master_forces, fem.contact.master_dofs)
    mesh = to_meshio(fem.mesh.scaled(fem.scaling.length), point_data=point_data, cell_data=cell_data)
    if mesh.points.shape[1] == 2:
        mesh.points = np.column_stack([mesh.points, np.zeros(len(mesh.points))])  # VTU wants 3-D points
    mesh.write(str(path))


def begin(result, directory, formats=FORMATS) -> tuple[Path, list[Path]]:
    """The output folder (created, once ``formats`` are known ones) and, if asked for, ``result``'s
    summary.json written into it: how every ``save`` starts."""
    one_string = isinstance(formats, str)  # set("json") would be its letters
    if one_string:  # a ValueError, as every bad input of the package
        raise ValueError(f"formats: a collection of formats, got the string {formats!r}; e.g. formats=('json',)")
    unknown = set(formats) - set(FORMATS)
    if unknown:
        raise ValueError(f"formats: unknown {sorted(unknown)}; choose from {FORMATS}")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    if "json" in formats:
        paths.append(directory / "summary.json")
        write_json(result, paths[-1])
    return directory, paths


def save(result, directory, formats=FORMATS) -> list[Path]:
    """Write the chosen outputs of ``result`` into ``directory`` and return the paths."""
    directory, paths = begin(result, directory, formats)
    if result.solved and "vtk" in formats:
        paths.append(directory / "solution.vtu")
        write_vtk(result, paths[-1])
    if result.solved and "png" in formats:
        from . import plots

        if result.fem.dim == 2:  # a 3-D deformed mesh is no picture: see solution.vtu
            paths.append(directory / "deformed.png")
            plots.deformed_mesh(result, paths[-1])
        paths.append(directory / "contact.png")
        plots.contact_tractions(result, paths[-1])
        if "history" in result.extra:
            paths.append(directory / "picard.png")
            plots.picard_convergence(result, paths[-1])
    return paths


def check_folder_target(folder: Path, option: str) -> None:
    """Refuse, before any work, an output folder that is a file."""
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{option}: {folder} is a file; give a folder (it is created if missing)")


def check_file_target(path: Path, option: str, example: str = "summary.json") -> None:
    """Refuse, before any work, an output file that is a folder or whose folder does not exist."""
    if path.is_dir():
        raise ValueError(f"{option}: {path} is a folder; give a file's name, e.g. {path / example}")
    if not path.parent.is_dir():
        raise ValueError(f"{option}: the folder {path.parent} does not exist; create it or choose another")


def check_new_file(path: Path, option: str, overwrite: bool, example: str = "summary.json") -> None:
    """:func:`check_file_target`, and refuse an existing file unless ``overwrite`` (the command's --overwrite)."""
    check_file_target(path, option, example)
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: {path} exists; choose another name, or --overwrite to replace it")


def check_new_files(folder: Path, patterns, option: str, overwrite: bool) -> None:
    """:func:`check_folder_target`, and refuse a folder holding files a run writes (``patterns``, globs) unless
    ``overwrite``: nothing else in the folder is touched either way."""
    check_folder_target(folder, option)
    ours = sorted({path.name for pattern in patterns for path in folder.glob(pattern)}) if folder.is_dir() else []
    if ours and not overwrite:
        raise ValueError(f"{option}: {folder} already holds {', '.join(ours[:5])}{' …' if len(ours) > 5 else ''}; "
                         "give another folder, or --overwrite to replace them (nothing else there is touched)")


def staged(directory, write: Callable[[Path], list]) -> list[Path]:
    """``write(folder)`` into a fresh folder beside ``directory``, its files moved in only once all are written:
    a run interrupted or failing on the way leaves ``directory`` as it was. Returns the paths in ``directory``."""
    directory = Path(directory).absolute()
    directory.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{directory.name}-unfinished-", dir=directory.parent))
    try:
        paths = write(staging)
        directory.mkdir(exist_ok=True)
        for path in sorted(staging.rglob("*")):  # a folder before what it holds
            target = directory / path.relative_to(staging)
            if path.is_dir():
                target.mkdir(exist_ok=True)
            else:
                os.replace(path, target)
        return [directory / Path(path).relative_to(staging) for path in paths]
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_text(path: Path, text: str) -> Path:
    """``text`` into ``path`` whole or not at all (written beside it, then renamed)."""
    staging = path.with_name(f".{path.name}.unfinished")
    try:
        staging.write_text(text)
        os.replace(staging, path)
    finally:
        staging.unlink(missing_ok=True)
    return path
