"""Writing a history: summary.json, a ParaView time series (solution.pvd + one .vtu per step), plots."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..scene.checks import of_type
from .output import FORMATS, begin, check_folder_target, write_vtk


def write_pvd(times, files, path: Path):
    """A ParaView collection of the step files at their times. Written by hand: meshio writes one mesh
    per file and has no PVD writer (its XDMF time series does not carry our per-step point data names
    as ParaView's VTU reader expects them)."""
    root = ET.Element("VTKFile", type="Collection", version="0.1")
    collection = ET.SubElement(root, "Collection")
    for time, file in zip(times, files):
        ET.SubElement(collection, "DataSet", timestep=repr(float(time)), part="0", file=Path(file).name)
    ET.ElementTree(root).write(path, xml_declaration=True, encoding="utf-8")


def output_folder(directory) -> Path:
    """``directory`` as a folder's path that is not a file (a history's or a solution set's outputs)."""
    of_type(directory, (str, os.PathLike), "directory", "give a folder's path, e.g. 'out'")
    check_folder_target(Path(directory), "directory")
    return Path(directory)


def save_history(history, directory, formats=FORMATS) -> list[Path]:
    """Write the chosen outputs of a :class:`~convexcontact.drivers.history_run.HistoryResult`; return the paths."""
    directory, paths = begin(history, output_folder(directory), formats)
    solved = [(t, s) for t, s in zip(history.times, history.steps) if s.solved]
    if "vtk" in formats and solved:
        files = []
        for k, (_, step) in enumerate(solved, start=1):
            files.append(directory / f"solution_{k:04d}.vtu")
            write_vtk(step, files[-1])
        paths += files
        paths.append(directory / "solution.pvd")
        write_pvd([t for t, _ in solved], files, paths[-1])
    if "png" in formats and solved:
        paths.append(directory / "history.png")
        plot_history(history, paths[-1])
    return paths


def loading_coordinate(history) -> tuple[np.ndarray, str]:
    """What the tangential force is plotted against: the obstacle's shift under a tangential force, else
    the first prescribed tangential displacement the history changes, else time."""
    series = history.series()
    if any(v is not None for v in series["obstacle_shift"]):
        return np.array(series["obstacle_shift"], dtype=float), "obstacle shift"
    for path, values in history.history.values.items():
        if path.startswith("dirichlet") and path.endswith(".ux"):
            return np.array(values[: len(history.steps)], dtype=float), path
    return np.array(series["time"], dtype=float), "time"


def indentation(history) -> tuple[np.ndarray, str]:
    """The obstacle's depth at each step where it moves (given, or its unknown advance under force control), else
    :func:`loading_coordinate`'s."""
    values = history.history.values
    if "obstacle.depth" in values:
        return np.array(values["obstacle.depth"][: len(history.steps)], dtype=float), "indentation"
    advance = history.series()["obstacle_advance"]
    if any(v is not None for v in advance):
        return np.array([np.nan if v is None else v for v in advance], dtype=float), "indentation"
    return loading_coordinate(history)


def plot_history(history, path):
    """Forces, contact zone and stick/slip counts against time, and the tangential force loop."""
    import matplotlib.pyplot as plt

    from .plots import save_figure

    series = history.series()
    time = np.array(series["time"], dtype=float)
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    panels = [
        (axes[0, 0], ("normal_force", "tangential_force"), "force"),
        (axes[0, 1], ("contact_half_width", "max_pressure"), "size, pressure"),
        (axes[1, 0], ("n_closed", "n_stick", "n_slip"), "contact nodes"),
    ]
    for ax, names, label in panels:
        for name in names:
            values = np.array([np.nan if v is None else v for v in series[name]], dtype=float)
            if np.isfinite(values).any():
                ax.plot(time, values, "o-", ms=3, label=name.replace("_", " "))
        ax.set_xlabel("time")
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    ax = axes[1, 1]
    force = np.array([np.nan if v is None else v for v in series["tangential_force"]], dtype=float)
    x, name = loading_coordinate(history)
    kind = "tangential"
    if not np.isfinite(force).any():  # frictionless: the force–indentation curve (a plastic punch's limit load)
        force = np.array([np.nan if v is None else v for v in series["normal_force"]], dtype=float)
        (x, name), kind = indentation(history), "normal"
    ax.plot(x, force, "o-", ms=3)
    ax.set_xlabel(name)
    ax.set_ylabel(f"{kind} force")
    ax.set_title("tangential force loop" if kind == "tangential" else f"normal force against {name}")
    fig.suptitle(f"{history.scene.name}: {len(history.steps)} steps, {history.status}")
    return save_figure(fig, path)
