"""Command line: ``convexcontact demo``, ``run SCENE.toml``, ``compare``, ``study …``, ``fclib …`` and ``bench``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import solvers
from .drivers.solve import solve
from .results.output import check_new_file, check_new_files, staged, write_text
from .scene.description import SceneError
from .scene.library import hertz_punch
from .studies import arguments


def table(result) -> str:
    """A short human-readable summary of a result."""
    s = result.summary()
    rows = [
        ("scene", s["scene"]),
        ("free DOFs", s["ndof"]),
        ("contact nodes", s["n_contact_nodes"]),
        ("formulation", f'{s["formulation"]} ({s["formulation_reason"]})'),
        ("solver", f'{s["solver"]} ({s["solver_status"]}, {s["iterations"]} iterations)'),
        *([("solver choice", s["solver_reason"])] if "solver_reason" in s else []),
        ("status", s["status"]),
    ]
    if result.solved:
        rows += [
            ("closed nodes", s["n_closed"]),
            ("contact half-width", f'{s["contact_half_width"]:.6g}'),
            ("max pressure", f'{s["max_pressure"]:.6g}'),
            ("normal force", f'{s["normal_force"]:.6g}'),
            ("elastic energy", f'{s["elastic_energy"]:.6g}'),
        ]
        if "n_stick" in s:
            rows += [
                ("stick / slip nodes", f'{s["n_stick"]} / {s["n_slip"]}'),
                ("tangential force", f'{s["tangential_force"]:.6g}'),
            ]
        if "picard" in s:
            picard = s["picard"]
            newton = picard["attempts"][0].get("newton")
            answered = newton is not None and newton.startswith("solved") and picard["iterations"] == 1
            rows.append(("Picard map", "not run: Newton's method answered" if answered else
                         f'{picard["outcome"]} after {picard["iterations"]} iterations'))
            if newton:
                rows.append(("Newton (Coulomb)", newton))
            rows.append(("Picard attempts", "; ".join(f'{a["formulation"]}/{a["solver"]} ω={a["relaxation"]:g}: '
                                                      f'{a["outcome"]} ({a["iterations"]})' for a in picard["attempts"])))
        rows += [
            ("certificate (worst)", f'{s["certificate"]["worst"]:.2e}'),
        ]
        if s["error_budget"] is not None:
            budget = s["error_budget"]
            algebraic, discretization = ("— (zero answer)" if budget[name] is None else f"{budget[name]:.1e}"
                                         for name in ("algebraic", "discretization"))
            bound = budget.get("estimator", "").startswith("equilibrated")
            how = "≤ {} (equilibrated bound" if bound else "≈ {} (residual estimate, calibrated"
            errors = f"algebraic {algebraic}, discretization {how.format(discretization)}, docs/estimate.md)"
            rows.append(("error / ‖u‖_E", errors))
    if s["message"]:
        rows.append(("message", s["message"]))
    rows += [("warning", warning) for warning in s["warnings"]]
    rows.append(("times [s]", ", ".join(f"{k} {v:.3f}" for k, v in s["timings"].items())))
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


def history_table(history) -> str:
    """One row per step of a history: time, status, forces, zones, certificate."""
    series = history.series()
    header = (f"{'step':>4} {'time':>8} {'status':<13} {'normal F':>11} {'tangential F':>12} {'closed':>6} "
              f"{'stick':>5} {'slip':>5} {'certificate':>11}")
    rows = [header]

    def number(value, spec):
        return format(value, spec) if value is not None else "—"

    for k, time in enumerate(series["time"]):
        rows.append(f"{k + 1:>4} {time:>8.4g} {series['status'][k]:<13} {number(series['normal_force'][k], '>11.5g')} "
                    f"{number(series['tangential_force'][k], '>12.5g')} {number(series['n_closed'][k], '>6')} "
                    f"{number(series['n_stick'][k], '>5')} {number(series['n_slip'][k], '>5')} "
                    f"{number(series['certificate'][k], '>11.2e')}")
    rows.append(f"status {history.status}" + (f": {history.message}" if history.message else ""))
    rows.append("times [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in history.timings.items()))
    return "\n".join(rows)


def solutions_table(found) -> str:
    """The statement of completeness, then one row per solution."""
    rows = [found.statement, f"{'#':>3} {'continuum':>9} {'Picard slope':>12} {'certificate':>11}  states"]
    for k, solution in enumerate(found.solutions, start=1):
        summary = solution.summary()
        states = ", ".join(f"{state} {summary['states'].count(state)}" for state in dict.fromkeys(summary["states"]))
        rows.append(f"{k:>3} {summary['continuum']:>9} {summary['picard_slope']:>12.3g} "
                    f"{summary['certificate']:>11.2e}  {states}")
    return "\n".join(rows)


EXIT = {"solved": 0, "inaccurate": 3, "not converged": 3, "not complete": 3}
"""Exit codes: 0 solved and certified, 3 an answer with a caveat (see the message), 1 no answer, 2 bad input."""


OUTPUTS = ("summary.json", "solution.vtu", "solution.pvd", "solution_*.vtu", "solution_*", "deformed.png",
           "contact.png", "picard.png", "history.png", "pressures.png", "adaptive.png")
"""What a run writes into --out: the names it would replace."""


def check_outputs(out: Path | None, json_file: Path | None, overwrite: bool, outputs=OUTPUTS) -> None:
    """Refuse, before any work, outputs that would fail or replace a file without --overwrite (``outputs``: the
    names the command writes into --out)."""
    if out is not None:
        check_new_files(out, outputs, "--out", overwrite)
    if json_file is not None:
        check_new_file(json_file, "--json", overwrite)


def report(result, out: Path | None, json_file: Path | None) -> int:
    """Print ``result``, write its files (each output whole or not at all) and return the exit code."""
    from .drivers.history_run import HistoryResult
    from .drivers.solutions import SolutionSet

    print(history_table(result) if isinstance(result, HistoryResult) else solutions_table(result)
          if isinstance(result, SolutionSet) else table(result))
    if out is not None:
        print("wrote", ", ".join(str(p) for p in staged(out, result.save)))
    if json_file is not None:
        write_text(json_file, json.dumps(result.summary(), indent=1))
    return EXIT.get(result.status, 1)


def compare_scene(args) -> dict | None:
    """The exact answer of the scene file against a peer's output file (``convexcontact compare SCENE PEER``):
    the outputs, the scene and the peer's file are checked before the solve; None when the solve has no answer."""
    from .scene.meshing import build_mesh
    from .scene.toml import load_scene
    from .studies.crossvalidation.peer import check_dimension, peer_errors, plot_pressures, read_peer

    check_outputs(args.out, None, args.overwrite, ("pressures.png",))
    scene = load_scene(args.reference)
    if scene.history is not None:
        raise ValueError(f"{args.reference}: compare takes a static scene; drop its [history]")
    peer = read_peer(args.other, args.displacement, args.pressure)
    check_dimension(peer, build_mesh(scene.body).dim())
    if args.out is not None and peer.pressure is None:
        raise ValueError(f"--out: {args.other} has no contact pressure, so there is no pressures.png to write; drop "
                         "--out, or name the peer's pressure with --pressure NAME")
    result = solve(scene)
    if not result.solved:  # no answer to compare with: exit 1, not a bad input
        print(f"error: {args.reference}: the exact solve returned {result.status}: {result.message}", file=sys.stderr)
        return None
    report = peer_errors(result, peer)
    if args.out is not None:  # written whole or not at all, as a run's outputs
        print("wrote", *staged(args.out, lambda folder: [plot_pressures(report, folder / "pressures.png")]))
    report.pop("pressure_curves", None)
    return report


def compare_summaries(args) -> dict:
    """Two summary.json files (``convexcontact compare A.json B.json``); the options of a peer file are refused."""
    from .studies.crossvalidation.compare import compare_files

    for option, value in (("--displacement", args.displacement), ("--pressure", args.pressure), ("--out", args.out)):
        if value is not None:
            raise ValueError(f"{option}: serves a scene compared with a peer's file (REFERENCE a .toml); two "
                             "summary.json files have no point data and no pressure overlay — drop it")
    return compare_files(args.reference, args.other)


ANSWERED = ("solved", "inaccurate")
"""Statuses of a study's case that gave an answer."""


def failed_all(found) -> bool:
    """Whether a study (its rows, or a sweep holding them) ran cases and none gave an answer; rows without a
    status (``study uniqueness``: counts of solutions) are answers, a run with nothing left to do failed nothing."""
    rows = list(getattr(found, "rows", found) or [])
    return bool(rows) and not any(row.get("status", "solved") in ANSWERED for row in rows)


def main(argv=None) -> int:
    """The ``convexcontact`` command; Ctrl-C ends it quietly with code 130 (outputs are written whole or not
    at all: see :func:`~convexcontact.results.output.staged`)."""
    try:
        return commands(argv)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def commands(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="convexcontact", description="Exact contact solves as convex programs.")
    commands = parser.add_subparsers(dest="command", required=True)
    for name, help_text in (("demo", "solve the built-in Hertz punch scene"), ("run", "solve a scene from a TOML file")):
        command = commands.add_parser(name, help=help_text)
        if name == "run":
            command.add_argument("scene", type=Path, help="scene file (see docs/scenes.md); a [history] runs every step")
            command.add_argument("--solutions", choices=["one", "all"], default="one",
                                 help="all: every solution of a Coulomb scene, each certified (docs/uniqueness.md)")
            command.add_argument("--confirm", action="store_true", help="run a history or a --solutions all search "
                                 "estimated to take over an hour (refused otherwise, with the estimate)")
            command.add_argument("--adapt", action="store_true", help="refine where the error indicators are "
                                 "largest until --target is met (triangles, tetrahedra; docs/estimate.md)")
            command.add_argument("--target", type=float, help="with --adapt: estimated relative energy error to "
                                 "reach (default 1e-2)")
            command.add_argument("--max-dofs", type=int, help="with --adapt: no mesh beyond this many DOFs "
                                 "(default 200000)")
        else:
            command.add_argument("--nx", type=arguments.integer(2, 80), default=80,
                                 help="elements across the block (default 80)")
        command.add_argument("--solver", default="auto", help="auto (newton-cg on a matrix-free dual, else clarabel) "
                             "| clarabel | osqp | cvxpy[:NAME] | newton-cg")
        command.add_argument("--formulation", default="auto",
                             help="auto (default: chosen from the problem's shape) | primal | dual (condensed on Γ_C) "
                             "| dual-matrix-free (W through K's factors, never formed)")
        command.add_argument("--tol", type=arguments.number("1e-8"), default=None,
                             help="solver tolerance (default: the adapter's)")
        command.add_argument("--out", type=Path, default=Path("out") if name == "demo" else None,
                             help="folder for summary.json, solution.vtu, PNG plots")
        command.add_argument("--json", type=Path, default=None, help="also write the JSON summary here")
        command.add_argument("--overwrite", action="store_true",
                             help="replace the outputs of an earlier run in --out / --json (refused otherwise)")
    study = commands.add_parser("study", help="work-precision SCENE … | sweep penalty|regularization … | stability … "
                                "| uniqueness … | grid SCENE --param PATH=V1,V2 … | sfepy …", add_help=False)
    study.add_argument("kind", choices=["work-precision", "sweep", "stability", "uniqueness", "grid", "sfepy"])
    study.add_argument("arguments", nargs=argparse.REMAINDER)
    commands.add_parser("fclib", help="FClib HDF5 problems: solve FILE.hdf5 | export SCENE.toml --out FILE.hdf5 "
                        "[--global] (docs/fclib.md)", add_help=False)
    commands.add_parser("bench", help="contact solve ÷ one linear solve per size (--dim 2|3 --sizes …, --sweep N, "
                        "--history N)")
    compare = commands.add_parser(
        "compare", help="compare two summary.json files, or a scene's exact answer with another code's output file",
        description="REFERENCE OTHER: two summary.json files of one mesh (contact-node fields), or SCENE.toml and a "
                    "peer's output (VTU, XDMF, Exodus… read by meshio) on its own mesh: the scene is solved exactly "
                    "and the peer's fields are interpolated onto our mesh (docs/peer.md)")
    compare.add_argument("reference", type=Path, help="summary.json, or a scene file (.toml)")
    compare.add_argument("other", type=Path, help="summary.json, or the peer's output file")
    compare.add_argument("--displacement", default=None, help="the peer's displacement point data (default: found by name)")
    compare.add_argument("--pressure", default=None, help="the peer's contact pressure point data (default: by name)")
    compare.add_argument("--out", type=Path, default=None, help="folder for the pressure overlay PNG (peer files)")
    compare.add_argument("--overwrite", action="store_true", help="replace a pressures.png already in --out")
    argv = sys.argv[1:] if argv is None else list(argv)
    options = argv[:argv.index("--")] if "--" in argv else argv
    dashes = next((word for word in options if word.startswith("--") and word.endswith("=--")), None)
    if dashes:  # argparse (3.11) reads "--tol=--" as an empty list and passes it on, past every type check
        parser.error(f"{dashes[:-3]}: expected a value, got '--' (the end of options); give {dashes[:-2]}VALUE")
    if argv[:1] == ["study"] and (len(argv) == 1 or argv[1] in ("-h", "--help")):
        study.print_help()
        print("\neach study has its own options: convexcontact study KIND --help")
        return 0
    if argv[:1] == ["fclib"]:  # its subcommands belong to its own parser
        from .interop.fclib_cli import main as fclib_main

        return fclib_main(argv[1:])
    if argv[:1] == ["bench"]:  # its options (--dim …) belong to its own parser
        from .studies.benchmarks import bench, history_bench

        history = any(word == "--history" or word.startswith("--history=") for word in argv)
        rows = (history_bench if history else bench).main(argv[1:])  # bad input: argparse's exit 2
        return 0 if rows else 1  # every case failed (each said why)
    args = parser.parse_args(argv)
    if args.command == "study":
        from .studies.crossvalidation import sfepy_peer, sweeps
        from .studies.parameters import grid
        from .studies.precision import stability, work_precision
        from .studies.verification import uniqueness

        studies = {"work-precision": work_precision, "sweep": sweeps, "stability": stability, "uniqueness": uniqueness,
                   "grid": grid, "sfepy": sfepy_peer}
        try:
            found = studies[args.kind].main(args.arguments)
        except (SceneError, ValueError) as error:  # bad input, named by the study before any work
            print(f"error: {error}", file=sys.stderr)
            return 2
        except RuntimeError as error:  # a reference the study needs could not be solved: no answer
            print(f"error: {error}", file=sys.stderr)
            return 1
        return 1 if failed_all(found) else 0  # every case failed (each said why)
    if args.command == "compare":
        from .studies.crossvalidation.compare import format_report

        try:
            report = compare_scene(args) if args.reference.suffix.lower() == ".toml" else compare_summaries(args)
        except (OSError, ValueError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        if report is None:
            return 1
        print(format_report(report))
        return 0
    return run_command(args)


OPTION_FIELDS = ("formulation", "solutions", "confirm", "solver", "tol")
"""Keywords of cc.solve whose errors the command line names by its option."""


def as_option(error: Exception) -> str:
    """The error's message, a keyword of cc.solve named as the option that set it (``formulation:`` →
    ``--formulation:``)."""
    message = str(error)
    keyword = message.split(":", 1)[0]
    return f"--{message}" if keyword in OPTION_FIELDS else message


def step_printer():
    """Progress of a history: each step's status, the time so far and the time left at the mean step's pace."""
    import time

    start = time.perf_counter()

    def printer(k: int, count: int, step) -> None:
        elapsed = time.perf_counter() - start
        print(f"step {k}/{count}: {step.status} ({elapsed:.3g} s, about {elapsed / k * (count - k):.3g} s left)",
              flush=True)

    return printer


def adapt_command(args, scene, options: dict):
    """``run SCENE --adapt``: every level of :func:`~convexcontact.drivers.adapt.adapt`, each level's size, estimate and
    time so far in the last one's ``extra`` (summary.json); a level's line printed as it ends."""
    from .drivers.adapt import adapt, check_adapt_options

    for option, value in (("--target", args.target), ("--max-dofs", args.max_dofs)):
        if value is not None and not args.adapt:
            raise ValueError(f"{option}: only means something with --adapt; add --adapt or drop it")
    if scene.history is not None or args.solutions != "one":
        raise ValueError("--adapt: refines one static solve; drop it for a [history] or --solutions all")
    target = 1e-2 if args.target is None else args.target
    max_dofs = 200_000 if args.max_dofs is None else args.max_dofs
    try:
        check_adapt_options(target, max_dofs, 0.5)
    except ValueError as error:
        raise ValueError(f"--{str(error).replace('_', '-')}") from None

    def progress(level, result):
        budget = result.error_budget or {}
        print(f"level {level}: {result.ndof} DOFs, {result.status}, estimated error "
              f"{budget.get('discretization', float('nan')):.2e}", flush=True)

    levels = adapt(scene, target, max_dofs, solver=args.solver, progress=progress, formulation=args.formulation,
                   **options)
    levels[-1].extra["adaptive_levels"] = [{"ndof": r.ndof, "status": r.status, "seconds": r.extra["adaptive_seconds"],
                                            **{key: (r.error_budget or {}).get(key) for key in ("discretization", "eta")}}
                                           for r in levels]
    return levels


def run_command(args) -> int:
    """``demo`` or ``run``: check the outputs, solve, report."""
    try:
        check_outputs(args.out, args.json, args.overwrite)
        solvers.check_name(args.solver)
        if args.command == "demo":
            from .scene.meshing import check_size

            scene = hertz_punch(nx=args.nx)
            with arguments.named("--nx"):
                check_size(scene.body)
        else:
            from .scene.toml import load_scene

            scene = load_scene(args.scene)
        options = {} if args.tol is None else {"tol": args.tol}
        solutions = getattr(args, "solutions", "one")
        if solutions == "all":
            options["progress"] = lambda done, count, what: print(f"{what} ({done}/{count})", flush=True)
        elif scene.history is not None:
            options["progress"] = step_printer()
        if getattr(args, "adapt", False) or getattr(args, "target", None) is not None \
                or getattr(args, "max_dofs", None) is not None:
            levels = adapt_command(args, scene, options)
            result = levels[-1]
        else:
            result = solve(scene, args.solver, formulation=args.formulation, solutions=solutions,
                           confirm=getattr(args, "confirm", False), **options)
    except (SceneError, ValueError) as error:
        print(f"error: {as_option(error)}", file=sys.stderr)
        return 2
    try:
        code = report(result, args.out, args.json)
        if args.out is not None and "adaptive_levels" in result.extra:  # the mesh sequence and the error curves
            from .drivers.adapt import plot_levels

            print("wrote", *staged(args.out, lambda folder: [plot_levels(levels, folder / "adaptive.png")]))
        return code
    except OSError as error:  # a full disk, a folder without write permission: --out is left as it was
        print(f"error: could not write the outputs: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
