"""``convexcontact bench --history N``: a load history against N static solves and one linear solve.

The scene is the sliding block of issue 11: a clamped top presses a block into a rigid plane, then
drags it out and back (Tresca, or Coulomb with ``--law coulomb``), N steps in all. In one process
per size the benchmark times (a) one linear elastic solve, K's factorization plus u = K⁻¹f,
(b) the whole history through :func:`~convexcontact.drivers.history_run.run` — one assembly, one
condensation, one solver session warm-started from step to step — and (c) the same N steps as N
independent static solves, each assembled, condensed and solved afresh (the static problem of
step k with the previous slip is what the history solves; (c) has no memory, so it is a cost
reference, not the same answer). Ratios (b)/(a) and (b)/(c) are reported.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np

from ...results.output import check_new_files
from ..arguments import SECONDS_PER_DOF, check_duration, integer, named, number

CSV = "history_bench.csv"
COLUMNS = ("dofs", "contact_nodes", "steps", "law", "formulation", "status", "linear", "history", "static",
           "history_per_linear", "history_per_static", "certificate")


def sliding_block(dofs: float, steps: int, law: str):
    """The block ``[0, 4] × [0, 1]`` of about ``dofs`` DOFs (P1), pressed by 0.01 and dragged out and back."""
    import convexcontact as cc
    from convexcontact.scene.load_history import History

    nx = max(8, 4 * round(np.sqrt(2 * dofs) / 4))  # 2(nx + 1)(nx/4 + 1) ≈ nx²/2 DOFs
    stroke = np.linspace(0.0, 0.02, steps // 2 + 1)
    ux = np.concatenate([stroke, stroke[-2::-1]])[:steps]
    contact_law = cc.Tresca(slip_bound=0.002) if law == "tresca" else cc.Coulomb(friction=0.3)
    return cc.Scene(
        name="sliding block",
        body=cc.Body(cc.Rectangle(width=4.0, height=1.0, nx=nx, ny=max(2, nx // 4))),
        materials=cc.Material(1.0, 0.3),
        dirichlet=(cc.Dirichlet("top", ux=0.0, uy=-0.01),),
        contact=cc.Contact("bottom", cc.Obstacle("flat"), contact_law),
        history=History(times=list(range(1, steps + 1)), values={"dirichlet[top].ux": list(ux)}),
    )


def case(dofs: float, steps: int, law: str) -> dict:
    """One size: the three timings and their ratios (see the module docstring)."""
    import dataclasses

    import convexcontact as cc
    from convexcontact.drivers.history_run import run
    from convexcontact.fem.assembly import assemble
    from convexcontact.fem.factorization import factorize

    scene = sliding_block(dofs, steps, law)
    fem = assemble(scene)
    start = time.perf_counter()
    factorize(fem.K, dim=fem.dim).solve(fem.f)
    linear = time.perf_counter() - start

    start = time.perf_counter()
    history = run(scene, "auto")  # as cc.solve, which the static solves below use
    elapsed = time.perf_counter() - start

    start = time.perf_counter()
    for k in range(steps):
        cc.solve(dataclasses.replace(scene.history.scene(scene, k), history=None))
    static = time.perf_counter() - start
    last = history.steps[-1]
    return {"dofs": fem.n_free, "contact_nodes": fem.contact.m, "steps": steps, "law": law,
            "formulation": last.formulation, "status": history.status, "linear": linear, "history": elapsed,
            "static": static, "history_per_linear": elapsed / linear, "history_per_static": elapsed / static,
            "certificate": max(s.certificate.worst for s in history.steps if s.certificate)}


def check_arguments(args) -> None:
    """Sizes, memory, the estimated run time and the output folder, before any case runs."""
    from ...scene.meshing import check_size

    if min(args.sizes) < 100:
        raise ValueError(f"--sizes: {min(args.sizes):g} DOFs; give at least 100 DOFs each, e.g. --sizes 1e4 1e5")
    for dofs in args.sizes:
        with named("--sizes"):
            check_size(sliding_block(dofs, 2, args.law).body)
    check_duration("--history", 2 * args.history * len(args.sizes), SECONDS_PER_DOF * max(args.sizes),
                   "contact solves (the history's steps, then as many static solves)",
                   "give fewer steps or smaller --sizes")
    check_new_files(args.out, (CSV,), "--out", args.overwrite)


def main(argv=None) -> list[dict]:
    """``convexcontact bench --history N [--sizes N …]``: a history against N static solves and one linear solve,
    per size; a table, and history_bench.csv in --out."""
    parser = argparse.ArgumentParser(prog="convexcontact bench --history", description=main.__doc__)
    parser.add_argument("--history", type=integer(2, 20), required=True, metavar="N", help="steps of the history")
    parser.add_argument("--sizes", type=number("1e4", positive=False), nargs="+", default=[1e4, 1e5],
                        help="approximate DOFs")
    parser.add_argument("--law", choices=["tresca", "coulomb"], default="tresca")
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="folder for history_bench.csv")
    parser.add_argument("--overwrite", action="store_true", help="replace the history_bench.csv of an earlier bench")
    args = parser.parse_args(argv)
    try:
        check_arguments(args)
    except ValueError as error:  # SceneError too: argparse's exit 2, usage and "error: --OPTION: …"
        parser.error(str(error))
    rows = []
    for dofs in args.sizes:
        rows.append(case(dofs, args.history, args.law))
        row = rows[-1]
        print(f"{row['dofs']:>8} DOFs {row['contact_nodes']:>5} contact nodes {row['steps']} steps: history "
              f"{row['history']:.2f} s = {row['history_per_linear']:.1f} linear solves = "
              f"{row['history_per_static']:.2f} × the {row['steps']} static solves ({row['static']:.2f} s); "
              f"{row['status']}, certificate ≤ {row['certificate']:.1e}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / CSV, "w", newline="") as handle:
        writer = csv.DictWriter(handle, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    print(json.dumps({"csv": str(args.out / CSV)}))
    return rows
