"""``convexcontact fclib solve FILE.hdf5`` and ``convexcontact fclib export SCENE.toml --out FILE.hdf5``.

Exit codes: 0 solved (certified by FClib's merit), 1 answered but not certified, 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ..results.output import check_file_target
from ..scene.model import SceneError


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="convexcontact fclib", description="FClib (Siconos' frictional-contact "
                                  "problem library, HDF5) problems: solve one exactly, or export a scene (docs/fclib.md)")
    commands = top.add_subparsers(dest="command", required=True)
    solve = commands.add_parser("solve", help="solve an FClib local or global problem, certified by fclib's merit")
    solve.add_argument("file", type=Path, help="FClib HDF5 file (/fclib_local or /fclib_global)")
    solve.add_argument("--merit-tol", type=float, default=1e-12, help="stop at this FClib merit (default 1e-12)")
    solve.add_argument("--max-iterations", type=int, default=100, help="Picard steps at most (default 100)")
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
        command.add_argument("--tol", type=float, default=None, help="solver tolerance (default: the adapter's)")
        command.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    return top


def check_target(path: Path | None, overwrite: bool, option: str) -> None:
    """Refuse, before any work, an output file that is a folder, lacks its folder, or exists without --overwrite."""
    if path is None:
        return
    check_file_target(path, option, example="problem.hdf5")
    if path.exists() and not overwrite:
        raise ValueError(f"{option}: {path} exists; pass --overwrite to replace it")


def solve_file(args) -> int:
    from .fclib import LocalProblem, Solution, read, write
    from .fclib_solve import condense, merit, solve_global, solve_local

    problem, stored, _ = read(args.file)
    options = {} if args.tol is None else {"tol": args.tol}
    settings = {"merit_tol": args.merit_tol, "max_iterations": args.max_iterations, "relaxation": args.relaxation}
    local = isinstance(problem, LocalProblem)
    answer = (solve_local if local else solve_global)(problem, args.solver, **settings, **options)
    rows = [("file", str(args.file)), ("title", problem.info.get("title", "")),
            ("problem", f"{'local' if local else 'global'}, spacedim {problem.spacedim}, {problem.mu.size} contacts"),
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
        args.json.write_text(json.dumps(answer.summary(), indent=2, default=float))
    if args.out is not None:
        write(args.out, problem, Solution(r=answer.r, u=answer.u, v=answer.v, l=answer.l))
    return 0 if answer.status == "solved" else 1


def export_scene(args) -> int:
    from ..scene.toml import load_scene
    from .fclib_scene import export
    from .fclib_solve import condense, merit

    options = {} if args.tol is None else {"tol": args.tol}
    problem, solution, result = export(load_scene(args.scene), args.out, args.kind, args.solver, **options)
    print(f"wrote {args.out}: FClib {args.kind} problem, spacedim {problem.spacedim}, {problem.mu.size} contacts")
    if solution is None:
        print(f"no /solution: our solve ended {result.status} ({result.message})")
        return 1
    local = problem if args.kind == "local" else condense(problem)[0]
    print(f"/solution: our answer ({result.status}, certificate {result.certificate.worst:.2e}), "
          f"fclib merit {merit(local, solution.r, solution.l):.3e}")
    return 0 if result.status == "solved" else 1


def main(argv=None) -> int:
    """The ``fclib`` command; ``argv`` without the words ``convexcontact fclib``."""
    args = parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        check_target(args.out, args.overwrite, "--out")
        check_target(getattr(args, "json", None), args.overwrite, "--json")
        return solve_file(args) if args.command == "solve" else export_scene(args)
    except (SceneError, ValueError, ImportError, OSError, KeyError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
