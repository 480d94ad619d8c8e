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

Everything the user gives is checked before the first case (:func:`check_run`): every case's scene is
built, every mesh's size estimated, the solver named, the scheduler asked who it is, the resume table
read; a refusal is a ValueError (a :class:`SceneError` for a parameter) whose message starts with the
argument's name (``grid.PATH``, ``solver``, ``scheduler``, ``workers``, ``out``).
"""

from __future__ import annotations

import argparse
import asyncio
import csv
import dataclasses
import hashlib
import itertools
import math
import os
import socket
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ...results.output import check_folder_target
from ...scene.bodies import Bodies
from ...scene.checks import of_type
from ...scene.description import Box, MeshFile, Rectangle, Scene, SceneError
from ...scene.load_history import PATH
from ...scene.load_history import at as set_load
from ...scene.meshing import build_mesh, check_size
from ...solvers import check_name, check_options

LAW_FIELDS = ("friction", "slip_bound", "stiffness", "exponent", "regularization", "relaxation")
BODY_FIELDS = {Rectangle: ("nx", "ny", "element"), Box: ("cells", "element"), MeshFile: ("element",)}
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
"""The local workers' BLAS and PARDISO on one thread each: one worker per core, not two threads per worker
competing for it (2 workers on 2 cores ran each case 2× slower than the serial sweep with the defaults)."""
COLUMNS = ("key", "group", "status", "certificate", "normal_force", "tangential_force", "max_pressure",
           "contact_half_width", "formulation", "solve_time", "worker", "error")
MAX_CASES = 100_000
"""More cases are refused: a case takes at least ~0.05 s, so 10⁵ cases are hours (measured: 0.046 s for the fastest
case of a 3 × 3 Tresca patch where only the slip bound changes, 0.14–0.25 s a case over whole runs)."""
SCHEDULER_TIMEOUT = 10.0
"""Seconds a scheduler has to answer who it is (connecting and Dask's handshake)."""
SCHEDULER_FIX = ("give the address a running scheduler prints (`dask scheduler`: tcp://HOST:8786, not its dashboard's "
                 "port 8787), 'serial' to solve in this process, or none for a local cluster")


def parameters(scene: Scene) -> list[str]:
    """The paths a grid can vary on ``scene``: its law's fields, its built-in mesh's sizes and element, its loads."""
    law = scene.contact.law
    paths = [f"contact.{name}" for name in LAW_FIELDS
             if hasattr(law, name) or (name == "stiffness" and getattr(law, "compliance", None) is not None)]
    if not isinstance(scene.body, Bodies):
        paths += [f"body.{name}" for name in BODY_FIELDS.get(type(scene.body.geometry), ("element",))]
    paths += ["obstacle.depth", "obstacle.force", "obstacle.tangential_force", "obstacle.gap"]
    paths += [f"dirichlet[{d.boundary}].{c}" for d in scene.dirichlet for c in ("ux", "uy", "uz")
              if getattr(d, c) is not None]
    paths += [f"traction[{t.boundary}].{name}" for t in scene.tractions for name in ("pressure", "vector")
              if getattr(t, name) is not None]
    return [*paths, "body_force"]


def with_value(scene: Scene, path: str, value) -> Scene:
    """``scene`` with the grid parameter ``path`` set to ``value``; a refusal is a SceneError named ``grid.PATH``."""
    try:
        return _set(scene, path, value)
    except SceneError as error:
        if error.field.startswith("grid"):
            raise
        problem = str(error).removeprefix(f"{error.field}: ")
        same = error.field in (path, f"history.{path}")
        raise SceneError(f"grid.{path}", problem if same else f"{value!r:.60} ({error.field}): {problem}") from None


def _set(scene: Scene, path: str, value) -> Scene:
    """``scene`` with ``path`` set to ``value``: the dataclasses check the value."""
    head, _, name = path.partition(".")
    if path not in parameters(scene) and not PATH.match(path):  # a load path on another boundary: set_load says
        raise SceneError(f"grid.{path}", "not a parameter a grid can vary on this scene",
                         f"use one of {', '.join(parameters(scene))}")
    if head == "contact":
        law = scene.contact.law
        if name == "stiffness" and not hasattr(law, "stiffness"):
            law = dataclasses.replace(law, compliance=dataclasses.replace(law.compliance, stiffness=value))
        else:
            law = dataclasses.replace(law, **{name: value})
        return scene.with_law(law)
    if head == "body":
        if name == "element":
            return dataclasses.replace(scene, body=dataclasses.replace(scene.body, element=value))
        return dataclasses.replace(scene, body=dataclasses.replace(
            scene.body, geometry=dataclasses.replace(scene.body.geometry, **{name: value})))
    return set_load(scene, path, value)


def check_grid(grid) -> dict[str, list]:
    """``grid`` as {path: list of distinct values}, refused where a path or its values cannot be a grid's."""
    of_type(grid, Mapping, "grid", "give {'contact.friction': [0.1, 0.2], …}")
    if not grid:
        raise SceneError("grid", "no parameter to vary", "give e.g. {'contact.friction': [0.1, 0.2]}")
    checked = {}
    for path, values in grid.items():
        of_type(path, str, "grid", "name each parameter by its path, e.g. 'contact.friction'")
        if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)) or np.ndim(values) > 1:
            raise SceneError(f"grid.{path}", f"expected a list of values, got {values!r:.60}",
                             f"give e.g. [{values!r:.20}, …]")
        if len(values) == 0:
            raise SceneError(f"grid.{path}", "no values", "give at least one")
        repeated = [v for k, v in enumerate(values) if any(_same(v, w) for w in values[:k])]
        if repeated:
            raise SceneError(f"grid.{path}", f"{repeated[0]!r} given twice", "give each value once")
        checked[path] = list(values)
    count = math.prod(map(len, checked.values()))
    if count > MAX_CASES:
        raise SceneError("grid", f"{count:.3g} cases ({' × '.join(str(len(v)) for v in checked.values())}): at least "
                         f"~0.05 s each, that is {count * 0.05 / 3600:.3g} h or more",
                         f"give fewer values (at most {MAX_CASES} cases), or split the grid over several runs")
    return checked


def _same(a, b) -> bool:
    try:
        return bool(a == b)
    except ValueError:  # arrays compare elementwise
        return False


def cases(scene: Scene, grid: dict[str, list]) -> list[tuple[dict, Scene]]:
    """(parameters, scene) of every combination of the grid's values, each case's scene built (and so checked)."""
    grid = check_grid(grid)
    out = []
    for values in itertools.product(*grid.values()):
        case = scene
        for path, value in zip(grid, values):
            case = with_value(case, path, value)
        out.append((dict(zip(grid, values)), case))
    return out


def check_sizes(scenes: list[Scene]) -> None:
    """Refuse a mesh too large for this machine before any case runs: each distinct body once (a mesh file is read
    once per element; several bodies are checked when assembled)."""
    bodies = {scene.body for scene in scenes if not isinstance(scene.body, Bodies)}
    for body in bodies:
        try:
            if isinstance(body.geometry, MeshFile):
                build_mesh(body)
            elif isinstance(body.geometry, (Rectangle, Box)):
                check_size(body)
        except SceneError as error:
            raise SceneError(f"grid.{error.field}", str(error).removeprefix(f"{error.field}: ")) from None


def key(scene: Scene) -> str:
    """A stable hash of a case's scene: the rows a rerun may skip."""
    return hashlib.sha1(repr(scene).encode()).hexdigest()[:16]


def group_of(scene: Scene) -> str:
    """Cases with one mesh, material and kind of law share an assembly and a factorization."""
    return hashlib.sha1(repr((scene.body, scene.materials, type(scene.contact.law).__name__)).encode()).hexdigest()[:8]


def run_group(members: list[tuple[dict, Scene]], solver: str, formulation: str) -> list[dict]:
    """Solve the cases of one group on one worker: assemble and condense once, then each case's loads and law."""
    from ...drivers.prepared import formulate, prepare

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


def resume(table: Path, grid: list[str]) -> tuple[list[str], set[str]]:
    """The header to append under and the keys of the cases an earlier run of this grid solved, read from
    ``table`` (OUT/grid.csv); a file that is not such a table is refused and left as it is."""
    header = [*grid, *COLUMNS]
    if not table.exists():
        return header, set()
    leave = "give another folder (the file is left as it is)"
    try:
        with open(table, newline="", encoding="utf-8") as handle:
            rows = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise ValueError(f"out: {table} is not a grid table this study wrote ({type(error).__name__}: {error}); "
                         f"{leave}") from None
    found = rows[0] if rows else []
    if found[len(found) - len(COLUMNS):] != list(COLUMNS):
        raise ValueError(f"out: {table} is not a grid table this study wrote (its first line is "
                         f"{','.join(found)[:80]!r}); {leave}")
    if sorted(found[: len(found) - len(COLUMNS)]) != sorted(grid):
        raise ValueError(f"out: {table} holds a grid over {found[: len(found) - len(COLUMNS)]}, this one varies "
                         f"{grid} (a rerun resumes only a grid of the same parameters); {leave}")
    status, index = found.index("status"), found.index("key")
    return found, {row[index] for row in rows[1:] if len(row) == len(found) and row[status] not in ("", "error")}


def check_run(solver: str, formulation: str, scheduler: str | None, workers: int | None, out: Path) -> None:
    """Refuse, before any work, a solver, formulation, scheduler, number of workers or output folder that cannot
    serve (the scheduler is asked who it is)."""
    from ...drivers.rules import MATRIX_FREE
    from ...formulations import FORMULATIONS

    check_name(solver)
    if formulation not in (*FORMULATIONS, MATRIX_FREE, "auto"):
        raise ValueError(f"formulation: unknown {formulation!r}; use one of {sorted(FORMULATIONS)}, {MATRIX_FREE!r} "
                         "or 'auto'")
    if workers is not None:
        cores = os.cpu_count() or 1
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= cores:
            raise ValueError(f"workers: expected a number of local workers from 1 to this machine's {cores} cores, "
                             f"got {workers!r:.40}; for more, start a cluster and give its scheduler")
        if scheduler is not None:
            raise ValueError(f"workers: sizes the local cluster, but the scheduler is {scheduler!r}; leave the number of "
                             "workers out (a scheduler's cluster has its own)")
    if scheduler != "serial":
        require_distributed()
    if scheduler is not None and scheduler != "serial":
        check_scheduler(scheduler)
    check_folder_target(out, "out")


def require_distributed() -> None:
    """Refuse a cluster run where Dask's distributed is not installed."""
    try:
        import distributed  # noqa: F401
    except ModuleNotFoundError as error:
        if error.name != "distributed":
            raise
        raise ValueError("scheduler: Dask's distributed is not installed; pip install 'convexcontact[sweeps]', or "
                         "use 'serial'") from None


def check_scheduler(address) -> None:
    """Refuse an address that is not a running Dask scheduler's: malformed, nothing listening, something else
    listening (an HTTP server's answer read as Dask's frames asked numpy for exabytes), or a worker."""
    from distributed.comm import parse_address, parse_host_port

    of_type(address, str, "scheduler", SCHEDULER_FIX)
    try:
        scheme, location = parse_address(address, strict=True)
        host, port = parse_host_port(location) if scheme in ("tcp", "tls", "ws", "wss") else (None, None)
        if port is not None and not 0 < port < 2**16:
            raise ValueError(f"port {port} out of range")
    except (ValueError, TypeError) as error:
        raise ValueError(f"scheduler: {address!r} is not an address ({error}); {SCHEDULER_FIX}") from None
    if host is not None:
        try:
            socket.create_connection((host, port), timeout=SCHEDULER_TIMEOUT).close()
        except OSError as error:
            raise ValueError(f"scheduler: nothing answers at {address} ({error.strerror or error or 'timed out'}); "
                             f"{SCHEDULER_FIX}") from None
    try:
        identity = asyncio.run(asyncio.wait_for(_identity(address), SCHEDULER_TIMEOUT))
    except Exception as error:  # noqa: BLE001 — whatever the peer sent, it is not a scheduler's handshake
        reason = "no answer" if isinstance(error, asyncio.TimeoutError) else f"{type(error).__name__}: {error}"
        raise ValueError(f"scheduler: {address} answers, but not as a Dask scheduler ({reason:.120}); "
                         f"{SCHEDULER_FIX}") from None
    if not isinstance(identity, dict) or identity.get("type") != "Scheduler":
        kind = identity.get("type") if isinstance(identity, dict) else type(identity).__name__
        their = f" (its scheduler is {identity['scheduler']})" if isinstance(identity, dict) and "scheduler" in identity else ""
        raise ValueError(f"scheduler: {address} is a Dask {kind}, not a scheduler{their}; {SCHEDULER_FIX}")


async def _identity(address: str):
    """What the Dask server at ``address`` says it is (its ``identity`` handler)."""
    from distributed.comm import connect

    comm = await connect(address, timeout=SCHEDULER_TIMEOUT)
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


def run_grid(scene: Scene, grid: dict[str, list], out="out/grid", solver: str = "clarabel",
             formulation: str = "auto", scheduler: str | None = None, workers: int | None = None,
             progress=print) -> list[dict]:
    """Solve every case of the grid (see the module docstring); return the rows of this run.

    Everything is checked before the first case: a refusal is a ValueError (SceneError for the grid) naming
    the argument — ``grid.PATH``, ``solver``, ``formulation``, ``scheduler``, ``workers``, ``out``."""
    of_type(scene, Scene, "scene", "build cc.Scene(...) or read a file with cc.scene.load_scene(path)")
    if scene.history is not None:
        raise SceneError("scene.history", "a grid solves one static problem per case",
                         "drop the history and vary its quantities as grid parameters (e.g. 'obstacle.depth')")
    check_options({"progress": progress})
    all_cases = cases(scene, grid)
    check_sizes([case for _, case in all_cases])
    out = Path(of_type(out, (str, Path), "out", "give a folder's path, e.g. 'out/grid'"))
    check_run(solver, formulation, scheduler, workers, out)
    table = out / "grid.csv"
    header, done = resume(table, list(grid))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"out: cannot create {out} ({error.strerror or error}); give a folder you can write") from None
    if not os.access(out, os.W_OK):
        raise ValueError(f"out: {out} is not writable; give a folder you can write")
    groups: dict[str, list] = {}
    for parameters, case in all_cases:
        if key(case) not in done:
            groups.setdefault(group_of(case), []).append((parameters, case))
    todo = sum(map(len, groups.values()))
    progress = progress or _silent
    progress(f"{todo} cases to solve in {len(groups)} groups ({len(done)} already in {table})")
    rows = []
    for finished_rows in _execute(list(groups.values()), solver, formulation, scheduler, workers):
        rows += finished_rows
        _append(table, header, finished_rows)
        progress(f"{len(rows)}/{todo} cases solved; last group: "
                 + ", ".join(f"{r['status']}" for r in finished_rows))
    return rows


def _silent(message: str) -> None:
    """``progress=None``: say nothing."""


def _execute(groups, solver, formulation, scheduler, workers):
    """Yield the rows of each group as it finishes: in this process, or as Dask tasks."""
    if scheduler == "serial":
        for members in groups:
            yield run_group(members, solver, formulation)
        return
    from distributed import Client, LocalCluster, as_completed

    cluster = None if scheduler else LocalCluster(n_workers=workers or os.cpu_count(), threads_per_worker=1,
                                                  processes=True, dashboard_address=None, env=ONE_THREAD)
    with Client(scheduler or cluster, timeout=SCHEDULER_TIMEOUT) as client:
        futures = {client.submit(run_group, members, solver, formulation, pure=False): members for members in groups}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as error:  # noqa: BLE001 — the worker died: its cases are rows that say so
                yield [{**parameters, "key": key(case), "group": group_of(case), "status": "error",
                        "error": f"worker lost: {type(error).__name__}: {error}"} for parameters, case in futures[future]]
    if cluster is not None:
        cluster.close()


def _append(path: Path, header: list[str], rows: list[dict]):
    new = not path.exists()
    with open(path, "a", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, header, extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerows(rows)


def parse_values(text: str) -> tuple[str, list]:
    """``path=v1,v2,…`` → (path, values); numbers where they parse, text otherwise (body.element=P1,P2)."""
    path, sep, values = text.partition("=")
    items = [v.strip() for v in values.split(",")]
    if not sep or not path.strip() or not all(items):
        raise argparse.ArgumentTypeError(f"expected PATH=V1,V2,… (e.g. contact.friction=0.1,0.2), got {text!r}")

    def value(item):
        for kind in (int, float):
            try:
                return kind(item)
            except ValueError:
                pass
        return item

    return path.strip(), [value(v) for v in items]


OPTIONS = {"grid": "--param", "solver": "--solver", "formulation": "--formulation", "scheduler": "--scheduler",
           "workers": "--workers", "out": "--out"}
"""The command line's option for each argument of :func:`run_grid` a refusal names first."""


def as_option(message: str) -> str:
    """A refusal of :func:`run_grid` in the command line's words: ``grid.PATH: …`` → ``--param PATH: …``,
    ``out: …`` → ``--out: …``; any other message (the scene file's fields) as it is."""
    name, sep, rest = message.partition(":")
    head, dot, path = name.partition(".")
    if sep and head in OPTIONS and (not dot or head == "grid"):
        return f"{OPTIONS[head]}{' ' + path if dot else ''}:{rest}"
    return message


def main(argv=None) -> list[dict]:
    """Solve a scene over a grid of parameters on a Dask cluster; rows in OUT/grid.csv."""
    from ...scene.toml import load_scene

    parser = argparse.ArgumentParser(prog="convexcontact study grid", description=main.__doc__)
    parser.add_argument("scene", type=Path, help="scene file")
    parser.add_argument("--param", type=parse_values, action="append", required=True, metavar="PATH=V1,V2,…",
                        help="a parameter and its values, e.g. contact.friction=0.1,0.2 (repeat for a grid)")
    parser.add_argument("--scheduler", default=None, help="tcp://host:port of a Dask scheduler, or 'serial'")
    parser.add_argument("--workers", type=int, default=None, help="workers of the local cluster (default: cores)")
    parser.add_argument("--solver", default="clarabel",
                        help="clarabel (default) | osqp | cvxpy[:NAME] | newton-cg | auto")
    parser.add_argument("--formulation", default="auto", help="auto (default) | primal | dual | dual-matrix-free")
    parser.add_argument("--out", type=Path, default=Path("out/grid"),
                        help="folder of grid.csv (default out/grid); a rerun there skips the cases it holds")
    args = parser.parse_args(argv)
    paths = [path for path, _ in args.param]
    repeated = next((path for path in paths if paths.count(path) > 1), None)
    if repeated is not None:
        raise ValueError(f"--param: {repeated} given {paths.count(repeated)} times; give each parameter once with "
                         f"all its values, e.g. --param {repeated}=V1,V2")
    scene = load_scene(args.scene)
    try:
        return run_grid(scene, dict(args.param), args.out, args.solver, args.formulation, args.scheduler,
                        args.workers)
    except ValueError as error:
        raise ValueError(as_option(str(error))) from None
