"""Command line: ``convexcontact demo``, ``run SCENE.toml``, ``compare``, ``study …`` and ``bench``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import solvers
from .drivers.solve import solve
from .scene.library import hertz_punch
from .scene.model import SceneError


def table(result) -> str:
    """A short human-readable summary of a result."""
    s = result.summary()
    rows = [
        ("scene", s["scene"]),
        ("free DOFs", s["ndof"]),
        ("contact nodes", s["n_contact_nodes"]),
        ("formulation", f'{s["formulation"]} ({s["formulation_reason"]})'),
        ("solver", f'{s["solver"]} ({s["solver_status"]}, {s["iterations"]} iterations)'),
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
            rows.append(("Picard map", f'{picard["outcome"]} after {picard["iterations"]} iterations'))
            rows.append(("Picard attempts", "; ".join(f'{a["formulation"]}/{a["solver"]} ω={a["relaxation"]:g}: '
                                                      f'{a["outcome"]} ({a["iterations"]})' for a in picard["attempts"])))
        rows += [
            ("certificate (worst)", f'{s["certificate"]["worst"]:.2e}'),
        ]
    if s["message"]:
        rows.append(("message", s["message"]))
    rows += [("warning", warning) for warning in s["warnings"]]
    rows.append(("times [s]", ", ".join(f"{k} {v:.3f}" for k, v in s["timings"].items())))
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


EXIT = {"solved": 0, "inaccurate": 3, "not converged": 3}
"""Exit codes: 0 solved and certified, 3 an answer with a caveat (see the message), 1 no answer, 2 bad input."""


def report(result, out: Path | None, json_file: Path | None) -> int:
    print(table(result))
    if out is not None:
        paths = result.save(out)
        print("wrote", ", ".join(str(p) for p in paths))
    if json_file is not None:
        json_file.write_text(json.dumps(result.summary(), indent=1))
    return EXIT.get(result.status, 1)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="convexcontact", description="Exact contact solves as convex programs.")
    commands = parser.add_subparsers(dest="command", required=True)
    for name, help_text in (("demo", "solve the built-in Hertz punch scene"), ("run", "solve a scene from a TOML file")):
        command = commands.add_parser(name, help=help_text)
        if name == "run":
            command.add_argument("scene", type=Path, help="scene file (see docs/scenes.md)")
        else:
            command.add_argument("--nx", type=int, default=80, help="elements across the block (default 80)")
        command.add_argument("--solver", default="clarabel", help="clarabel | osqp | cvxpy[:NAME]")
        command.add_argument("--formulation", default="auto",
                             help="auto (default: chosen from the problem's shape) | primal | dual (condensed on Γ_C)")
        command.add_argument("--tol", type=float, default=None, help="solver tolerance (default: the adapter's)")
        command.add_argument("--out", type=Path, default=Path("out") if name == "demo" else None,
                             help="folder for summary.json, solution.vtu, PNG plots")
        command.add_argument("--json", type=Path, default=None, help="also write the JSON summary here")
    study = commands.add_parser("study", help="work-precision SCENE … | sweep penalty|regularization … | stability …",
                                add_help=False)
    study.add_argument("kind", choices=["work-precision", "sweep", "stability"])
    study.add_argument("arguments", nargs=argparse.REMAINDER)
    commands.add_parser("bench", help="contact solve ÷ one linear solve per size (--dim 2|3 --sizes …, --sweep N)")
    compare = commands.add_parser("compare", help="compare two summary.json files (contact-node fields)")
    compare.add_argument("reference", type=Path)
    compare.add_argument("other", type=Path)
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:  # its options (--dim …) belong to its own parser
        from .studies import bench

        bench.main(argv[1:])
        return 0
    args = parser.parse_args(argv)
    if args.command == "study":
        from .studies import stability, sweeps, work_precision

        {"work-precision": work_precision, "sweep": sweeps, "stability": stability}[args.kind].main(args.arguments)
        return 0
    if args.command == "compare":
        from .studies.compare import compare_files, format_report

        try:
            print(format_report(compare_files(args.reference, args.other)))
        except (OSError, ValueError) as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        return 0
    try:
        solvers.check_name(args.solver)
        if args.command == "demo":
            scene = hertz_punch(nx=args.nx)
        else:
            from .scene.toml import load_scene

            scene = load_scene(args.scene)
        options = {} if args.tol is None else {"tol": args.tol}
        result = solve(scene, args.solver, formulation=args.formulation, **options)
    except (SceneError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return report(result, args.out, args.json)


if __name__ == "__main__":
    sys.exit(main())
