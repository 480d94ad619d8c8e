"""Work-precision study: error against wall time for every way of solving one scene.

Every applicable combination of formulation (primal, dual) × solver (clarabel, osqp,
cvxpy) × solver tolerance × method is run:

- ``exact``        the scene's own law, no smoothing;
- ``regularized``  Hild's ε-regularized friction (laws with friction only), ε = k·U for
                   k in :data:`EPSILON_FACTORS`, U the scene's displacement scale;
- ``penalty``      normal compliance σ_N = −c_N (u_N − g)_+ instead of non-penetration,
                   c_N = k·E/L for k in :data:`STIFFNESS_FACTORS` (E, L the stress and length scales).

The error of a row is the relative L² error of the contact tractions (λ_N, λ_T together,
weighted by the contact weights, ≈ ∫_Γc) against a reference, labelled in the ``reference``
column:

- ``closed form`` — the frictionless Hertz scene (``hertz_punch``): the Hertz pressure for
  the computed normal force (plane strain, :func:`convexcontact.analytic.hertz_pressure`);
- ``overkill …`` — otherwise an exact Clarabel solve at tol 1e-12 (1e-11, 1e-10 if Clarabel
  stops), on the last of ``meshes`` when given (then the error includes the discretization
  error), else on the scene's own mesh. Tractions are interpolated along the contact
  coordinate s when the meshes differ.

The time of a row is assembly + formulation + solve (the postprocess and certificate are
left out), as one user running that combination from scratch would pay. Combinations that
cannot run (OSQP with a 3-D or power cone, the dual with normal compliance) are rows with
status ``n/a`` and the reason in ``message``; failed solves are rows too. ::

    from convexcontact.scene.library import hertz_punch
    from convexcontact.studies.precision import work_precision as wp
    rows = wp.run(hertz_punch(nx=40))
    print(wp.table(rows)); wp.plot(rows, "wp.png"); wp.write_csv(rows, "wp.csv")
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from ...analytic import hertz_plane_strain, hertz_pressure
from ...drivers.prepared import prepare
from ...results.result import ContactResult
from ...scene.description import Coulomb, Material, NormalCompliance, Scene, SceneError, Signorini, has_friction
from ...solvers import ConeNotSupported
from ..arguments import SECONDS_PER_DOF, check_duration, integer, number

FORMULATIONS = ("primal", "dual")
SOLVERS = ("clarabel", "osqp", "cvxpy")
EPSILON_FACTORS = (1e-2, 1e-3, 1e-4, 1e-5)
"""ε / U over three decades (U the scene's displacement scale)."""
STIFFNESS_FACTORS = (1e2, 1e3, 1e4, 1e5)
"""c_N / (E/L) over three decades; Clarabel stops near 1e5 (docs/friction.md) — an outcome, recorded."""
REFERENCE_TOLS = (1e-12, 1e-11, 1e-10)
TOLS = (1e-4, 1e-6, 1e-8, 1e-10)
"""The solver tolerances of the command's rows by default."""
CLOSED_FORM = "closed form"
FIELDS = ("scene", "ndof", "method", "parameter", "formulation", "solver", "tol", "status", "time", "error",
          "pressure_error", "friction_error", "certificate", "iterations", "reference", "message")


@dataclasses.dataclass(frozen=True)
class Method:
    """A way to solve the scene: a name, its parameter (ε or c_N, user units; None when exact) and its law."""

    name: str
    parameter: float | None
    law: object


def methods(scene: Scene, scaling) -> list[Method]:
    """Exact, ε-regularized (with friction) and penalty variants of the scene's law."""
    law = scene.contact.law
    base = law.compliance if has_friction(law) else (law if isinstance(law, NormalCompliance) else None)
    if base is not None:  # the scene is a penalty model already: its exact limit has no compliance
        law = dataclasses.replace(law, compliance=None) if has_friction(law) else Signorini()
    found = [Method("exact", None, law)]
    if has_friction(law):
        for k in EPSILON_FACTORS:
            epsilon = float(k * scaling.displacement)
            found.append(Method("regularized", epsilon, dataclasses.replace(law, regularization=epsilon)))
    for k in STIFFNESS_FACTORS:
        stiffness = float(k * scaling.stress / scaling.length)
        penalty = NormalCompliance(stiffness)
        found.append(Method("penalty", stiffness, dataclasses.replace(law, compliance=penalty)
                            if has_friction(law) else penalty))
    return found


def wall_time(result: ContactResult) -> float:
    """Assembly + formulation + solve [s]."""
    return float(sum(result.timings.get(k, 0.0) for k in ("assembly", "formulation", "solve")))


# --- references -------------------------------------------------------------------------------


def has_closed_form(scene: Scene) -> bool:
    """The frictionless force-controlled Hertz scene of the library (or a penalty version of it)."""
    obstacle = scene.contact.obstacle
    return (scene.name == "hertz" and obstacle.shape == "parabolic" and obstacle.force_controlled
            and not has_friction(scene.contact.law) and isinstance(scene.materials, Material))


def weights(result: ContactResult) -> np.ndarray:
    return result.fem.contact.weights * result.fem.scaling.length


def relative_l2(w: np.ndarray, error: Sequence[np.ndarray], reference: Sequence[np.ndarray]) -> float:
    num = math.sqrt(sum(float(w @ e**2) for e in error))
    den = math.sqrt(sum(float(w @ r**2) for r in reference))
    return num / den if den > 0 else (0.0 if num == 0 else math.inf)


def closed_form_errors(result: ContactResult) -> dict:
    """L² pressure error against Hertz with the computed normal force."""
    scene = result.scene
    a, p0 = hertz_plane_strain(result.normal_force, scene.contact.obstacle.radius, scene.materials.E,
                               scene.materials.nu)
    exact = hertz_pressure(result.contact.coords[:, 0], a, p0)
    error = relative_l2(weights(result), [result.contact.pressure - exact], [exact])
    return {"error": error, "pressure_error": error, "friction_error": None}


def at(reference: ContactResult, values: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Nodal ``values`` of the reference interpolated at contact coordinates ``s``."""
    order = np.argsort(reference.contact.coordinate)
    return np.interp(s, reference.contact.coordinate[order], values[order])


def reference_errors(reference: ContactResult, result: ContactResult) -> dict:
    """Relative L² errors of λ_N, λ_T and both together against an overkill reference."""
    c, w = result.contact, weights(result)
    pressure = at(reference, reference.contact.pressure, c.coordinate)
    report = {"pressure_error": relative_l2(w, [c.pressure - pressure], [pressure]), "friction_error": None}
    errors, refs = [c.pressure - pressure], [pressure]
    if reference.contact.friction is not None and c.friction is not None:
        friction = at(reference, reference.contact.friction, c.coordinate)
        report["friction_error"] = relative_l2(w, [c.friction - friction], [friction])
        errors.append(c.friction - friction)
        refs.append(friction)
    report["error"] = relative_l2(w, errors, refs)
    return report


def overkill(scene: Scene, law) -> tuple[ContactResult, str]:
    """Exact primal Clarabel solve at the tightest tolerance it reaches; the result and its label."""
    for tol in REFERENCE_TOLS:
        exact = law if not isinstance(law, Coulomb) else dataclasses.replace(law, tol=min(law.tol, 1e-10))
        result = prepare(scene.with_law(exact)).solve("clarabel", tol=tol)
        if result.status == "solved":
            return result, f"overkill (exact, clarabel, tol {tol:g}, {result.ndof} dofs)"
    raise RuntimeError(f"overkill reference: Clarabel returned {result.status!r}: {result.message}")


# --- the study --------------------------------------------------------------------------------


def run(
    scene: Scene,
    meshes: Sequence[Scene] | None = None,
    tolerances: Iterable[float] = (1e-4, 1e-6, 1e-8, 1e-10),
    progress: Callable[[str], None] | None = print,
    reference: ContactResult | None = None,
    formulations: Sequence[str] = FORMULATIONS,
    solvers: Sequence[str] = SOLVERS,
) -> list[dict]:
    """Rows (dicts, keys :data:`FIELDS`) of every formulation × solver × tolerance × method on ``scene``.

    ``meshes``: finer versions of the scene; the overkill reference is solved on the last one.
    ``reference``: a result to measure against instead (an overkill solve made elsewhere).
    ``progress(line)`` is called after each combination with a ``k/N`` counter.
    """
    tolerances = tuple(tolerances)
    first = prepare(scene)
    variants = methods(scene, first.fem.scaling)
    label = CLOSED_FORM if reference is None and has_closed_form(scene) else None
    if label is None and reference is None:
        reference, label = overkill(meshes[-1] if meshes else scene, variants[0].law)
    elif label is None:
        label = f"given ({reference.solver}, {reference.ndof} dofs)"
    total = len(formulations) * len(solvers) * len(tolerances) * len(variants)
    rows, k = [], 0
    for formulation in formulations:
        for method in variants:
            for tol in tolerances:
                law = method.law
                if isinstance(law, Coulomb):  # the Picard loop stops no tighter than its inner solves
                    law = dataclasses.replace(law, tol=max(law.tol, tol))
                model, why = None, ""
                try:
                    model = prepare(scene.with_law(law), formulation)
                except SceneError as error:
                    why = str(error)
                for solver in solvers:
                    k += 1
                    row = {"scene": scene.name, "ndof": first.fem.n_free, "method": method.name,
                           "parameter": method.parameter, "formulation": formulation, "solver": solver, "tol": tol,
                           "status": "n/a", "time": None, "error": None, "pressure_error": None,
                           "friction_error": None, "certificate": None, "iterations": None, "reference": label,
                           "message": why}
                    if model is not None:
                        row.update(attempt(model, solver, tol, reference))
                    rows.append(row)
                    if progress is not None:
                        progress(f"[{k}/{total}] {describe(row)}")
    return rows


def attempt(model, solver: str, tol: float, reference: ContactResult | None) -> dict:
    """One solve as row entries; a refused cone is ``n/a``, an error of the solver a ``failed`` row."""
    try:
        result = model.solve(solver, tol=tol)
    except ConeNotSupported as error:
        return {"status": "n/a", "message": str(error)}
    except (ValueError, RuntimeError, ArithmeticError) as error:  # a study records failures, never stops on them
        return {"status": "failed", "message": f"{type(error).__name__}: {error}"}
    row = {"status": result.status, "time": wall_time(result), "message": result.message,
           "iterations": result.iterations,
           "certificate": None if result.certificate is None else float(result.certificate.worst)}
    if result.solved:
        row.update(closed_form_errors(result) if reference is None else reference_errors(reference, result))
    return row


def describe(row: dict) -> str:
    parameter = "" if row["parameter"] is None else f" {row['parameter']:.1e}"
    text = f"{row['method']}{parameter} {row['formulation']}/{row['solver']} tol {row['tol']:.0e}: {row['status']}"
    if row["time"] is not None:
        text += f", {row['time']:.3f} s"
    if row["error"] is not None:
        text += f", error {row['error']:.2e}"
    return text


# --- output -----------------------------------------------------------------------------------


def measured(rows: Iterable[dict]) -> list[dict]:
    """Rows with a time and a finite error."""
    return [r for r in rows if r.get("time") is not None and r.get("error") is not None
            and math.isfinite(r["error"])]


def pareto(rows: Iterable[dict]) -> list[dict]:
    """The non-dominated rows in (time, error), fastest first: no other row is both faster and more accurate."""
    front, best = [], math.inf
    for row in sorted(measured(rows), key=lambda r: (r["time"], r["error"])):
        if row["error"] < best:
            front.append(row)
            best = row["error"]
    return front


def write_csv(rows: Iterable[dict], path) -> Path:
    """Rows as CSV (columns :data:`FIELDS`; a missing number as an empty cell)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=FIELDS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else row[k] for k in FIELDS})
    return path


NUMBERS = {"ndof": int, "iterations": int, "parameter": float, "tol": float, "time": float, "error": float,
           "pressure_error": float, "friction_error": float, "certificate": float}


def read_csv(path) -> list[dict]:
    """Rows written by :func:`write_csv`, numbers as numbers and empty cells as None."""
    with Path(path).open(newline="") as stream:
        return [{k: (v if k not in NUMBERS else None if v == "" else NUMBERS[k](v)) for k, v in row.items()}
                for row in csv.DictReader(stream)]


def table(rows: Sequence[dict]) -> str:
    """Aligned text table; ``*`` marks the Pareto front."""
    front = {id(r) for r in pareto(rows)}
    header = f"{'':2}{'method':<12}{'param':>9}  {'form':<7}{'solver':<9}{'tol':>7}  {'status':<14}{'time [s]':>9}  " \
             f"{'error':>9}  reference"
    lines = [header]
    for r in rows:
        parameter = "" if r["parameter"] is None else f"{r['parameter']:.1e}"
        time = "" if r["time"] is None else f"{r['time']:.3f}"
        error = "" if r["error"] is None else f"{r['error']:.2e}"
        status = r["status"] if r["status"] != "n/a" else "n/a"
        lines.append(f"{'*' if id(r) in front else '':2}{r['method']:<12}{parameter:>9}  {r['formulation']:<7}"
                     f"{r['solver']:<9}{r['tol']:>7.0e}  {status:<14}{time:>9}  {error:>9}  {r['reference']}")
    lines += [f"n/a: {reason}" for reason in sorted({r["message"] for r in rows if r["status"] == "n/a"})]
    return "\n".join(lines)


MARKERS = {"exact": "o", "regularized": "^", "penalty": "s"}
COLORS = {"clarabel": "tab:blue", "osqp": "tab:orange", "cvxpy": "tab:green"}


def plot(rows: Sequence[dict], path, title: str | None = None) -> Path:
    """Log-log error against wall time: marker = method, colour = solver, hollow = dual; the Pareto front as a line."""
    from ...results.plots import plt, save_figure

    data = measured(rows)
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    groups: dict[tuple, list] = {}
    for r in data:
        groups.setdefault((r["method"], r["solver"], r["formulation"]), []).append(r)
    for (method, solver, formulation), group in sorted(groups.items()):
        color = COLORS.get(solver, "tab:gray")
        ax.loglog([r["time"] for r in group], [max(r["error"], 1e-16) for r in group], MARKERS.get(method, "x"),
                  color=color, mfc=color if formulation == "primal" else "none", alpha=0.8, linestyle="none",
                  label=f"{method} / {solver} / {formulation}")
    front = pareto(rows)
    if front:
        ax.step([r["time"] for r in front], [max(r["error"], 1e-16) for r in front], "k-", where="post", lw=1.2,
                label="Pareto front")
    reference = data[0]["reference"] if data else ""
    ax.set_xlabel("wall time: assembly + formulation + solve [s]")
    ax.set_ylabel(f"relative L² contact traction error ({reference.split(' (')[0]})")
    ax.set_title(title or (f"work-precision: {data[0]['scene']}, {data[0]['ndof']} dofs" if data else ""))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, path)


# --- command line -----------------------------------------------------------------------------

SCENES = ("hertz", "punch", "flat-punch")
PUNCH_H = 0.2
"""The punch mesh's h must leave room for its 10 fine rows in the block's depth 2
(:func:`~convexcontact.scene.library.punch_mesh`)."""


def library_scene(name: str, size: float | None = None) -> Scene:
    """``hertz``: hertz_punch(nx) (closed form); ``punch``: the depth-controlled frictional punch, Tresca s = 0.005;
    ``flat-punch``: hertz_punch's block under a flat rigid punch of half-width 0.5 (pressure singular at its edges)."""
    from ...scene.description import Contact, Obstacle, Tresca
    from ...scene.library import frictional_punch, hertz_punch

    if name == "hertz":
        return hertz_punch(nx=int(size or 40))
    if name == "flat-punch":
        scene = hertz_punch(nx=int(size or 40))
        return dataclasses.replace(scene, name="flat_punch",
                                   contact=Contact("top", Obstacle("flat_punch", radius=0.5, depth=0.01)))
    if name == "punch":
        return frictional_punch(h=size or 0.02, law=Tresca(slip_bound=0.005))
    raise ValueError(f"scene: unknown {name!r}; use one of {SCENES}")


def library_dofs(name: str, size: float | None, option: str) -> float:
    """The DOFs of :func:`library_scene` (about, for the punch), refusing a size that makes no mesh or one too
    large for this machine's memory, before anything is built."""
    from ...scene.meshing import check_memory

    if name in ("hertz", "flat-punch"):
        nx = 40 if size is None else size
        if nx != int(nx) or nx < 2:
            raise ValueError(f"{option}: {name}'s size is nx, an integer ≥ 2 (elements across the block); got {nx:g}")
        dofs = 2.0 * (nx + 1) * (nx // 2 + 1)
    else:
        h = 0.02 if size is None else size
        if h >= PUNCH_H:
            raise ValueError(f"{option}: punch's size is the cell size h at the contact, below {PUNCH_H:g} (the "
                             f"mesh's 10 fine rows must fit in its depth 2), e.g. 0.02; got {h:g}")
        dofs = 2.0 * (2 * 0.15 / h + 50) * 41  # 0.3/h fine columns and 48 growing ones, 41 rows of nodes
    check_memory(dofs, 2, option, f"{name} at size {size:g}" if size else name, "give a coarser size")
    return dofs


def main(argv=None) -> list[dict]:
    """``convexcontact study work-precision hertz|punch [--size S …]``: error against wall time of every
    formulation × solver × tolerance × method; NAME.csv, NAME.png and NAME.txt in --out."""
    import argparse

    from ... import solvers as solver_paths
    from ...results.output import check_new_files

    parser = argparse.ArgumentParser(prog="convexcontact study work-precision", description=main.__doc__)
    parser.add_argument("scene", choices=SCENES)
    parser.add_argument("--size", type=number("40"), nargs="+", default=[None],
                        help="mesh sizes, one study each against one reference — hertz: nx (40); punch: h (0.02)")
    parser.add_argument("--reference-size", type=number("80"), default=None,
                        help="finer mesh for the overkill reference")
    parser.add_argument("--tol", type=number("1e-8"), nargs="+", default=list(TOLS))
    parser.add_argument("--solvers", nargs="+", default=list(SOLVERS), help=f"default: {' '.join(SOLVERS)}")
    parser.add_argument("--formulations", nargs="+", choices=("primal", "dual", "dual-matrix-free"),
                        default=list(FORMULATIONS))
    parser.add_argument("--out", type=Path, default=Path("out/work_precision"),
                        help="writes NAME.csv, NAME.png, NAME.txt here")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an earlier study in --out")
    parser.add_argument("--refinement", type=integer(2, 4), default=None, metavar="LEVELS",
                        help="instead: uniform against adaptive refinement from the first --size (default nx 8), "
                             "LEVELS uniform levels; writes NAME_refinement.csv/png/txt")
    parser.add_argument("--element", choices=tuple(OPTIMAL_RATE), default=None,
                        help="with --refinement: the elements of both families (default: the scene's, P1)")
    args = parser.parse_args(argv)
    if args.refinement is not None:
        return refinement_main(args)
    if args.element is not None:
        raise ValueError("--element: the elements are chosen for the refinement comparison only (the other studies "
                         "compare solvers on the scene's own mesh); drop --element or add --refinement LEVELS")
    for solver in args.solvers:
        try:
            solver_paths.check_name(solver)
        except ValueError as error:
            raise ValueError(f"--solvers: {str(error).removeprefix('solver: ')}") from None
    dofs = sum(library_dofs(args.scene, size, "--size") for size in args.size)
    if args.reference_size is not None:
        library_dofs(args.scene, args.reference_size, "--reference-size")
    combinations = len(args.formulations) * len(args.solvers) * len(args.tol) * (1 + len(EPSILON_FACTORS)
                                                                                  + len(STIFFNESS_FACTORS))
    check_duration("--size", combinations * len(args.size), SECONDS_PER_DOF * dofs / len(args.size),
                   "contact solves", "give fewer or coarser --size, or fewer --tol, --solvers or --formulations")
    extensions = ("csv", "png", "txt")
    check_new_files(args.out, [f"{args.scene}.{extension}" for extension in extensions], "--out", args.overwrite)
    scenes = [library_scene(args.scene, size) for size in args.size]
    finest = library_scene(args.scene, args.reference_size) if args.reference_size is not None else scenes[-1]
    reference, label = (None, CLOSED_FORM) if has_closed_form(finest) else overkill(finest, finest.contact.law)
    rows = []
    for scene in scenes:  # the mesh axis: every combination on every mesh, against the one reference
        found = run(scene, None, args.tol, print, reference, formulations=args.formulations, solvers=args.solvers)
        rows += [{**row, "reference": label} for row in found]
    write_csv(rows, args.out / f"{args.scene}.csv")
    plot(rows, args.out / f"{args.scene}.png")
    text = table(rows)
    (args.out / f"{args.scene}.txt").write_text(text + "\n")
    print(text)
    return rows


REFINEMENT_BASE = 8
"""The coarsest mesh (nx) of the refinement comparison when no --size is given."""
OPTIMAL_RATE = {"P1": 0.5, "P2": 1.0}
"""The refinement comparison's elements, each with its optimal rate in DOFs in 2-D (N^−1/2, N^−1): the plot's line."""


def refinement_main(args) -> list[dict]:
    """``study work-precision SCENE --refinement LEVELS``: :func:`.refinement.compare` on the first --size, its
    reference :data:`~.refinement.REFERENCE_LEVELS` finer, checked for memory and time before any work."""
    from ...results.output import check_new_files
    from ...scene.meshing import check_memory
    from . import refinement

    solver_grid = {"--reference-size": (args.reference_size, None), "--tol": (args.tol, list(TOLS)),
                   "--solvers": (args.solvers, list(SOLVERS)), "--formulations": (args.formulations, list(FORMULATIONS))}
    for option, (value, default) in solver_grid.items():
        if value != default:
            raise ValueError(f"{option}: the refinement comparison solves every level exactly with the default solver "
                             f"against its own reference; drop {option} or --refinement")
    if len(args.size) > 1:
        raise ValueError("--size: --refinement starts from one mesh and refines it; give one --size")
    size = args.size[0] if args.size[0] is not None else (REFINEMENT_BASE if args.scene != "punch" else None)
    scene = library_scene(args.scene, size)
    element = args.element or scene.body.element
    if element != scene.body.element:
        scene = dataclasses.replace(scene, body=dataclasses.replace(scene.body, element=element))
    dofs = library_dofs(args.scene, size, "--size") * (4.0 if element == "P2" else 1.0)  # P2: ~4× P1's on one mesh
    finest = dofs * 4.0 ** (args.refinement - 1 + refinement.REFERENCE_LEVELS)
    check_memory(finest, 2, "--refinement", f"{args.scene}'s reference mesh", "give fewer levels or a coarser --size")
    check_duration("--refinement", 3, SECONDS_PER_DOF * finest, "reference and finest solves",
                   "give fewer --refinement levels or a coarser --size")
    extensions = ("csv", "png", "txt")
    check_new_files(args.out, [f"{args.scene}_refinement.{extension}" for extension in extensions], "--out",
                    args.overwrite)
    rows = refinement.compare(scene, args.refinement, progress=print)
    path = args.out / f"{args.scene}_refinement.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=refinement.FIELDS)
        writer.writeheader()
        writer.writerows({k: "" if row.get(k) is None else row[k] for k in refinement.FIELDS} for row in rows)
    front = pareto(rows)
    refinement.plot(rows, args.out / f"{args.scene}_refinement.png", front, optimal=OPTIMAL_RATE.get(element, 0.5))
    text = refinement.table(rows, front)
    (args.out / f"{args.scene}_refinement.txt").write_text(text + "\n")
    print(text)
    return rows


if __name__ == "__main__":
    main()
