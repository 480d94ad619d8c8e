"""``convexcontact study grid``: a parameter grid of solves, run as Dask tasks (issue 14).

Every combination of the values given is one case: a scene path (``contact.friction``,
``contact.slip_bound``, ``contact.stiffness``, ``body.nx``, ``body.element``, or any path of a load
history: ``obstacle.depth``, ``traction[top].pressure``, …) set to one value. Cases that share a
mesh, its material and their law's kind form a group, which one worker assembles and factorizes
(condenses) once: each case then only changes the loads (:meth:`FEModel.at`) and the law.

Groups run as tasks of a Dask distributed cluster — a local one on all cores by default, any
scheduler with ``scheduler="tcp://…"``, or in this process with ``scheduler="serial"``. Progress is
printed as groups finish; a case that fails is a row with its error, never the loss of the others;
rows are appended to ``grid.csv`` as they come, keyed by a hash of the case's scene, and a rerun
skips the cases already there.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import hashlib
import itertools
import os
import socket
import time
from pathlib import Path

from ..scene.history import PATH
from ..scene.history import at as set_load
from ..scene.model import Scene, SceneError

LAW_FIELDS = ("friction", "slip_bound", "stiffness", "exponent", "regularization", "relaxation")
BODY_FIELDS = ("nx", "ny", "cells", "element")
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
"""The local workers' BLAS and PARDISO on one thread each: one worker per core, not two threads per worker
competing for it (2 workers on 2 cores ran each case 2× slower than the serial sweep with the defaults)."""
COLUMNS = ("key", "group", "status", "certificate", "normal_force", "tangential_force", "max_pressure",
           "contact_half_width", "formulation", "solve_time", "worker", "error")


def with_value(scene: Scene, path: str, value) -> Scene:
    """``scene`` with the grid parameter ``path`` set to ``value``; the dataclasses check the value."""
    head, _, name = path.partition(".")
    if head == "contact" and name in LAW_FIELDS:
        law = scene.contact.law
        if name == "stiffness" and not hasattr(law, "stiffness"):
            law = dataclasses.replace(law, compliance=dataclasses.replace(law.compliance, stiffness=value))
        elif not hasattr(law, name):
            raise SceneError(f"grid.{path}", f"the law {type(law).__name__} has no {name}",
                             f"vary one of its fields: {[f.name for f in dataclasses.fields(law)]}")
        else:
            law = dataclasses.replace(law, **{name: value})
        return scene.with_law(law)
    if head == "body" and name in BODY_FIELDS:
        if name == "element":
            return dataclasses.replace(scene, body=dataclasses.replace(scene.body, element=value))
        return dataclasses.replace(scene, body=dataclasses.replace(
            scene.body, geometry=dataclasses.replace(scene.body.geometry, **{name: value})))
    if PATH.match(path):
        return set_load(scene, path, value)
    raise SceneError(f"grid.{path}", "not a parameter a grid can vary",
                     f"use contact.{{{', '.join(LAW_FIELDS)}}}, body.{{{', '.join(BODY_FIELDS)}}} or a load path")


def cases(scene: Scene, grid: dict[str, list]) -> list[tuple[dict, Scene]]:
    """(parameters, scene) of every combination of the grid's values."""
    if not grid:
        raise SceneError("grid", "no parameter to vary", "give e.g. {'contact.friction': [0.1, 0.2]}")
    out = []
    for values in itertools.product(*grid.values()):
        case = scene
        for path, value in zip(grid, values):
            case = with_value(case, path, value)
        out.append((dict(zip(grid, values)), case))
    return out


def key(scene: Scene) -> str:
    """A stable hash of a case's scene: the rows a rerun may skip."""
    return hashlib.sha1(repr(scene).encode()).hexdigest()[:16]


def group_of(scene: Scene) -> str:
    """Cases with one mesh, material and kind of law share an assembly and a factorization."""
    return hashlib.sha1(repr((scene.body, scene.materials, type(scene.contact.law).__name__)).encode()).hexdigest()[:8]


def run_group(members: list[tuple[dict, Scene]], solver: str, formulation: str) -> list[dict]:
    """Solve the cases of one group on one worker: assemble and condense once, then each case's loads and law."""
    from ..drivers.model import formulate, prepare

    rows, model = [], None
    worker = f"{socket.gethostname()}:{os.getpid()}"
    for parameters, scene in members:
        row = {**parameters, "key": key(scene), "group": group_of(scene), "worker": worker}
        try:
            start = time.perf_counter()
            if model is None:
                model = case = prepare(scene, formulation)
            elif key(scene.with_law(model.law)) == key(model.fem.scene):  # only the law differs: share its cache
                case = model.with_law(scene.contact.law)
            else:  # other loads: the same K and condensation
                case = formulate(model.fem.at(scene), model.formulation, {}, model.condensation, model.reason)
            result = case.solve(solver)
            row.update(status=result.status, formulation=result.formulation, solve_time=time.perf_counter() - start)
            if result.solved:
                row.update(certificate=result.certificate.worst, normal_force=result.normal_force,
                           max_pressure=result.max_pressure, contact_half_width=result.contact_half_width,
                           tangential_force=result.tangential_force if result.contact.friction is not None else None)
        except Exception as error:  # noqa: BLE001 — a case that fails is a row that says why, not the loss of all
            row.update(status="error", error=f"{type(error).__name__}: {error}")
        rows.append(row)
    return rows


def finished(path: Path) -> set[str]:
    if not path.exists():
        return set()
    with open(path, newline="") as handle:
        return {row["key"] for row in csv.DictReader(handle) if row.get("status") not in (None, "", "error")}


def run_grid(scene: Scene, grid: dict[str, list], out="out/grid", solver: str = "clarabel",
             formulation: str = "auto", scheduler: str | None = None, workers: int | None = None,
             progress=print) -> list[dict]:
    """Solve every case of the grid (see the module docstring); return the rows of this run."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    table = out / "grid.csv"
    done = finished(table)
    groups: dict[str, list] = {}
    for parameters, case in cases(scene, grid):
        if key(case) not in done:
            groups.setdefault(group_of(case), []).append((parameters, case))
    todo = sum(map(len, groups.values()))
    progress(f"{todo} cases to solve in {len(groups)} groups ({len(done)} already in {table})")
    rows = []
    for finished_rows in _execute(list(groups.values()), solver, formulation, scheduler, workers):
        rows += finished_rows
        _append(table, list(grid), finished_rows)
        progress(f"{len(rows)}/{todo} cases solved; last group: "
                 + ", ".join(f"{r['status']}" for r in finished_rows))
    return rows


def _execute(groups, solver, formulation, scheduler, workers):
    """Yield the rows of each group as it finishes: in this process, or as Dask tasks."""
    if scheduler == "serial":
        for members in groups:
            yield run_group(members, solver, formulation)
        return
    from distributed import Client, LocalCluster, as_completed

    cluster = None if scheduler else LocalCluster(n_workers=workers or os.cpu_count(), threads_per_worker=1,
                                                  processes=True, dashboard_address=None, env=ONE_THREAD)
    with Client(scheduler or cluster) as client:
        futures = {client.submit(run_group, members, solver, formulation, pure=False): members for members in groups}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as error:  # noqa: BLE001 — the worker died: its cases are rows that say so
                yield [{**parameters, "key": key(case), "group": group_of(case), "status": "error",
                        "error": f"worker lost: {type(error).__name__}: {error}"} for parameters, case in futures[future]]
    if cluster is not None:
        cluster.close()


def _append(path: Path, parameters: list[str], rows: list[dict]):
    new = not path.exists()
    with open(path, "a", newline="") as handle:
        writer = csv.DictWriter(handle, [*parameters, *COLUMNS], extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerows(rows)


def parse_values(text: str) -> tuple[str, list]:
    """``path=v1,v2,…`` → (path, values); numbers where they parse, text otherwise (body.element=P1,P2)."""
    path, sep, values = text.partition("=")
    if not sep or not values:
        raise argparse.ArgumentTypeError(f"expected PATH=V1,V2,… got {text!r}")

    def value(item):
        for kind in (int, float):
            try:
                return kind(item)
            except ValueError:
                pass
        return item

    return path.strip(), [value(v.strip()) for v in values.split(",")]


def main(argv=None) -> list[dict]:
    """Solve a scene over a grid of parameters on a Dask cluster; rows in OUT/grid.csv."""
    from ..scene.toml import load_scene

    parser = argparse.ArgumentParser(prog="convexcontact study grid", description=main.__doc__)
    parser.add_argument("scene", type=Path, help="scene file")
    parser.add_argument("--param", type=parse_values, action="append", required=True, metavar="PATH=V1,V2,…",
                        help="a parameter and its values, e.g. contact.friction=0.1,0.2 (repeat for a grid)")
    parser.add_argument("--scheduler", default=None, help="tcp://host:port of a Dask scheduler, or 'serial'")
    parser.add_argument("--workers", type=int, default=None, help="workers of the local cluster (default: cores)")
    parser.add_argument("--solver", default="clarabel")
    parser.add_argument("--out", type=Path, default=Path("out/grid"))
    args = parser.parse_args(argv)
    if args.workers is not None and args.workers < 1:
        parser.error("--workers must be at least 1")
    try:
        return run_grid(load_scene(args.scene), dict(args.param), args.out, args.solver, scheduler=args.scheduler,
                        workers=args.workers)
    except SceneError as error:
        parser.error(str(error))
