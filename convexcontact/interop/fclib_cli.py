"""``convexcontact fclib solve FILE.hdf5`` and ``convexcontact fclib export SCENE.toml --out FILE.hdf5``.

Exit codes, those of ``convexcontact`` (cli.EXIT): 0 solved (certified by FClib's merit), 3 an answer with a
caveat (inaccurate: its merit is above the certificate's bound), 1 no answer (the solver failed), 2 bad input
(``error: --option: …`` or ``error: fclib_local/vectors/q: …`` on stderr), every option checked before any work.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..results.output import check_file_target, write_text
from ..scene.description import SceneError

EXIT = {"solved": 0, "answered": 3, "no answer": 1}
"""cli.EXIT's codes: solved and certified, an answer with a caveat, no answer (tests/test_bad_inputs_fclib.py
checks they agree)."""


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="convexcontact fclib", description="FClib (Siconos' frictional-contact "
                                  "problem library, HDF5) problems: solve one exactly, or export a scene (docs/fclib.md)")
    commands = top.add_subparsers(dest="command", required=True)
    solve = commands.add_parser("solve", help="solve an FClib local or global problem, certified by fclib's merit")
    solve.add_argument("file", type=Path, help="FClib HDF5 file (/fclib_local or /fclib_global)")
    solve.add_argument("--merit-tol", type=float, default=1e-12, help="stop at this FClib merit > 0 (default 1e-12)")
    solve.add_argument("--max-iterations", type=int, default=100, help="Picard steps at most, ≥ 1 (default 100)")
    solve.add_argument("--relaxation", type=float, default=1.0, help="Picard relaxation ω in (0, 1] (default 1)")
    solve.add_argument("--json", type=Path, default=None, help="write the summary (and the history) here")
    solve.add_argument("--out", type=Path, default=None, help="write the problem with our answer as /solution here")
    export = commands.add_parser("export", help="write a Coulomb scene as an FClib problem with our answer")
    export.add_argument("scene", type=Path, help="scene file (TOML, docs/scenes.md) with a Coulomb law")
    export.add_argument("--out", type=Path, required=True, help="the FClib HDF5 file to write")
    export.add_argument("--global", dest="kind", action="store_const", const="global", default="local",
                        help="the global problem (M = K, H, f, w, μ) instead of the local one (W, q, μ)")
    for command in (solve, export):
        command.add_argument("--solver", default="clarabel", help="clarabel | osqp (2-D only) | cvxpy[:NAME]")
        command.add_argument("--tol", type=float, default=None, help="solver tolerance > 0 (default: the adapter's)")
        command.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    return top


def check_target(path: Path | None, overwrite: bool, option: str) -> None:
    """Refuse, before any work, an output file that is a folder, lacks its folder, or exists without --overwrite."""
    if path is None:
        return
    check_file_target(path, option, example="summary.json" if option == "--json" else "problem.hdf5")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: {path} exists; pass --overwrite to replace it")


def check_number(value: float | None, option: str, rule: str, ok, example: str) -> None:
    """Refuse a number (NaN and infinities included) that is not ``rule``, i.e. for which ``ok`` is false."""
    if value is not None and not (math.isfinite(value) and ok(value)):
        raise ValueError(f"{option}: {value!r} is not {rule}; give e.g. {option} {example}")


def check_solver(name: str) -> None:
    from .. import solvers

    try:
        solvers.check_name(name)
    except ValueError as error:
        raise ValueError(f"--{error}") from None


def check_options(args) -> None:
    """Every option of ``fclib solve``/``export``, before any file is read or written."""
    check_solver(args.solver)
    check_number(args.tol, "--tol", "a finite number > 0", lambda tol: tol > 0, "1e-10")
    if args.command == "solve":
        check_number(args.merit_tol, "--merit-tol", "a finite number > 0", lambda tol: tol > 0, "1e-12")
        check_number(args.relaxation, "--relaxation", "in (0, 1]", lambda omega: 0 < omega <= 1, "0.5")
        check_number(args.max_iterations, "--max-iterations", "an integer ≥ 1", lambda count: count >= 1, "100")
        if args.json is not None and args.out is not None and args.json.resolve() == args.out.resolve():
            raise ValueError(f"--json: {args.json} is also --out; give the summary another name")
        check_target(args.json, args.overwrite, "--json")
    elif not args.scene.is_file():
        raise ValueError(f"scene: {args.scene}: {'a folder' if args.scene.is_dir() else 'no such file'}; give a "
                         "scene TOML file (docs/scenes.md)")
    check_target(args.out, args.overwrite, "--out")


CONDENSED_BYTES = 24
"""Bytes per entry of the dense W = Hᵀ M⁻¹ H a global solve holds at its peak: 16 measured (800 contacts, 2,400
contact unknowns: 94 MB above the interpreter's 165 MB), with a margin."""


def check_condensation(problem) -> None:
    """Refuse, before the work, a global problem whose dense condensed W would not fit in this machine's memory."""
    from ..scene.meshing import available_memory

    unknowns = problem.H.shape[1]
    need, have = CONDENSED_BYTES * float(unknowns) ** 2, available_memory()
    if need > have:
        fit = int((have / CONDENSED_BYTES) ** 0.5 / problem.spacedim)
        raise ValueError(f"fclib_global/H: {unknowns} contact unknowns; condensing onto them (a dense W = Hᵀ M⁻¹ H) "
                         f"needs about {need / 2**30:.3g} GiB and this machine has {have / 2**30:.3g} GiB available; "
                         f"problems of up to about {fit} contacts fit")


def solve_file(args) -> int:
    from .fclib import LocalProblem, Solution, read, write
    from .fclib_solve import condense, merit, solve_global, solve_local

    problem, stored, _ = read(args.file)
    if args.solver == "osqp" and problem.spacedim == 3:
        raise ValueError(f"--solver: osqp takes linear cones only and {args.file} is 3-D (second-order friction "
                         "cones); use --solver clarabel")
    if not isinstance(problem, LocalProblem):
        check_condensation(problem)
    options = {} if args.tol is None else {"tol": args.tol}
    settings = {"merit_tol": args.merit_tol, "max_iterations": args.max_iterations, "relaxation": args.relaxation}
    local = isinstance(problem, LocalProblem)
    answer = (solve_local if local else solve_global)(problem, args.solver, **settings, **options)
    rows = [("file", str(args.file)), ("title", problem.info.get("title", "")),
            ("problem", f"{'local' if local else 'global'}, spacedim {problem.spacedim}, {problem.mu.size} contacts"),
            *(("read as", warning) for warning in problem.warnings),
            ("status", f"{answer.status} (Picard {answer.outcome}, {answer.iterations} steps)"),
            ("fclib merit", f"{answer.merit:.3e}"),
            ("siconos error", f"{answer.siconos_error:.3e} ({'' if local else 'g'}fc{problem.spacedim}d_compute_error)"),
            ("natural-map residual", f"{max(answer.residuals.values()):.3e} (worst of {len(answer.residuals)})"),
            ("time", f"{answer.timings['total']:.3f} s")]
    if stored is not None and stored.r is not None:
        stored_merit = merit(problem if local else condense(problem)[0], stored.r, stored.l)
        difference = np.abs(answer.r - stored.r).max() / max(np.abs(stored.r).max(), np.abs(answer.r).max(), 1e-300)
        answer.extra["stored_solution"] = {"fclib_merit": stored_merit, "relative_difference_r": float(difference)}
        rows.append(("stored /solution", f"merit {stored_merit:.3e}, ‖r − ours‖∞/‖r‖∞ = {difference:.3e}"))
    print("\n".join(f"{name:<22} {value}" for name, value in rows))
    if args.json is not None:
        summary = {**answer.summary(), "reader_warnings": problem.warnings}
        write_text(args.json, json.dumps(summary, indent=2, default=float))
    if args.out is not None:
        write(args.out, problem, Solution(r=answer.r, u=answer.u, v=answer.v, l=answer.l))
    return EXIT["solved"] if answer.status == "solved" else EXIT["no answer"] if answer.status == "failed" \
        else EXIT["answered"]


def export_scene(args) -> int:
    from ..scene.toml import load_scene
    from .fclib_scene import export
    from .fclib_solve import condense, merit

    options = {} if args.tol is None else {"tol": args.tol}
    problem, solution, result = export(load_scene(args.scene), args.out, args.kind, args.solver, **options)
    print(f"wrote {args.out}: FClib {args.kind} problem, spacedim {problem.spacedim}, {problem.mu.size} contacts")
    if solution is None:
        print(f"no /solution: our solve ended {result.status} ({result.message})")
        return EXIT["no answer"]
    local = problem if args.kind == "local" else condense(problem)[0]
    print(f"/solution: our answer ({result.status}, certificate {result.certificate.worst:.2e}), "
          f"fclib merit {merit(local, solution.r, solution.l):.3e}")
    return EXIT["solved"] if result.status == "solved" else EXIT["answered"]


def main(argv=None) -> int:
    """The ``fclib`` command; ``argv`` without the words ``convexcontact fclib``."""
    args = parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        check_options(args)
        return solve_file(args) if args.command == "solve" else export_scene(args)
    except (SceneError, ValueError, ImportError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
