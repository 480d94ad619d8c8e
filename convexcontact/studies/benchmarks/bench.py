"""``convexcontact bench``: a contact solve against one linear elastic solve, per mesh size.

For each size and law (Signorini, Tresca, Coulomb) on the punch scene (or, with
``--scenario whole-face``, a block whose whole bottom face is in contact; ``two-body``, a punch on
a foundation (3-D: two spheres' caps); ``shapes``, each scene of the family of :mod:`.shapes`; ``plastic``, a plastic step:
:mod:`.plastic_bench`), one fresh
process assembles the scene, then times (a) one linear elastic solve, K's sparse
factorization plus u = K⁻¹f, and (b) the contact solve on the same assembly: the
condensation (if the formulation condenses), the formulation, the solver (the whole
Picard loop for Coulomb) and the certificate. The ratio (b) ÷ (a), measured in one run,
is what DESIGN.md calls "fast"; absolute times on shared machines are not stable. The
end-to-end ratio puts the assembly, which every user pays, on both sides: (assembly + b) ÷
(assembly + a), scene to certified answer against scene to linear answer.

Peak memory is the growth of the process's peak resident set over the assembled model,
for (a) and (b) separately: the kernel's peak counter is reset (``/proc/self/clear_refs``)
after the assembly and after (a), so neither includes the other nor the assembly, and the heap's free memory is
given back first, so neither reuses what the other freed (:func:`_reset_peak`).
"""

from __future__ import annotations

import argparse
import csv
import ctypes
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ...results.output import check_folder_target, check_new_files
from ..arguments import SECONDS_PER_DOF, check_duration, integer, named, number
from . import plastic_bench

LAWS = ("signorini", "tresca", "coulomb")
SIZES = {2: (1e4, 1e5, 1e6), 3: (1e4, 1e5, 3e5)}
SCENARIOS = ("punch", "whole-face", "two-body", "shapes", "plastic")
NODES = {2: (1e3, 4e3), 3: (1e3, 4e3)}
"""Contact nodes of the whole-face cases, by default (``--nodes``)."""
COLUMNS = ("scenario", "dim", "law", "dofs", "contact_nodes", "unknowns", "formulation", "solver", "status", "iterations",
           "coulomb_newton", "assembly", "linear", "condensation", "contact_solve", "contact_total", "ratio", "end_to_end", "memory_linear_mb",
           "memory_contact_mb", "memory_ratio", "certificate")


ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1", **os.environ}
"""The cases' environment: numpy's OpenBLAS on one thread unless the user says otherwise. With two
threads on the shared 2-vCPU machines the dense Cholesky of a 2028² S took 0.7–2.8 s against 0.1 s
(MKL PARDISO keeps its own threads)."""


def law_of(name: str):
    from ...scene.description import Coulomb, Signorini, Tresca

    return {"signorini": Signorini(), "tresca": Tresca(slip_bound=0.002), "coulomb": Coulomb(friction=0.3)}[name]


def punch_scene(dim: int, law: str, dofs: float):
    """The benchmark's punch: a rigid paraboloid (R = 1) indents a clamped block's top by 0.01.

    2-D: the block [−2, 2] × [−2, 0] with nx × nx/2 P1 triangles graded 4:1 towards the
    punch; 3-D: the quarter model of :func:`~convexcontact.scene.library.punch_3d`, Q1.
    ``dofs`` sets the mesh: about 2(nx + 1)(nx/2 + 1) or 3(cells + 1)³ DOFs.
    """
    import dataclasses

    from ...scene.description import Contact, Obstacle
    from ...scene.library import hertz_punch, punch_3d

    if dim == 3:
        return punch_3d(cells=max(2, round((dofs / 3) ** (1 / 3)) - 1), law=law_of(law), element="Q1")
    nx = max(4, 2 * round(np.sqrt(dofs) / 2))
    scene = hertz_punch(nx=nx, law=law_of(law))
    contact = Contact("top", Obstacle("parabolic", radius=1.0, depth=0.01), law_of(law))
    return dataclasses.replace(scene, name="punch", contact=contact)


def two_body_scene(law: str, dofs: float, dim: int = 2):
    """Two bodies, mortar. 2-D: a stiffer cylindrical punch with its own mesh pressed into an elastic foundation
    (:func:`~convexcontact.scene.bodies_library.punch_on_foundation`); its meshes are graded towards the
    contact, so ``dofs`` sets the cell size h there by the measured fit dofs ≈ 5·10⁴ (0.001/h)^0.86. 3-D: a quarter
    of two spheres' caps of P1 tetrahedra (:func:`~convexcontact.scene.bodies_library.two_spheres`), the upper one 10
    times stiffer (as the 2-D punch: the normal load shears the interface), n³ cells each, 2·3(n + 1)³ ≈ ``dofs``."""
    from ...scene.bodies_library import punch_on_foundation, two_spheres

    if dim == 3:
        return two_spheres(max(2, round((dofs / 6) ** (1 / 3)) - 1), moduli=(10.0, 1.0), law=law_of(law))
    return punch_on_foundation(0.001 * (5e4 / dofs) ** (1 / 0.86), law=law_of(law))


def scene_of(scenario: str, dim: int, law: str, dofs: float, nodes: float | None = None):
    """The bench's scene: the punch, the whole face of :func:`~convexcontact.scene.library.whole_face`, two
    bodies (:func:`two_body_scene`), or a shape of :mod:`.shapes` named as the scenario."""
    from .shapes import SHAPES, shape_scene

    if scenario == "punch":
        return punch_scene(dim, law, dofs)
    if scenario == "two-body":
        return two_body_scene(law, dofs, dim)
    if scenario in SHAPES[dim]:
        return shape_scene(scenario, law_of(law), dofs, dim)
    if scenario == "plastic":
        return plastic_bench.punch_scene(dofs, law)
    from ...scene.library import whole_face

    return whole_face(dim, int(nodes), dofs, law_of(law))


def _reset_peak() -> bool:
    """Reset the kernel's peak-RSS counter (VmHWM) to the live memory; False where the kernel does not allow it.

    The heap's free memory is first given back (glibc's ``malloc_trim``): left resident, the phase measured reused
    it without raising the RSS, so its growth counted only what the earlier phases had not freed (the same linear
    solve of the 3-D plate 20 : 20 : 1, 3.3·10⁴ DOFs, read 63 and 92 MB in two runs)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: the growth may undercount, as before
        pass
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def _rss_mb(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1]) / 1024
    return float("nan")


def measure(dim: int, law: str, dofs: float, formulation: str, solver: str, scenario: str = "punch",
            nodes: float | None = None) -> dict:
    """One benchmark case in this process (call it in a fresh one: see :func:`run`)."""
    if scenario == "plastic":
        return plastic_bench.measure(law, dofs, solver)
    from ... import solvers
    from ...drivers.prepared import formulate
    from ...drivers.rules import MATRIX_FREE
    from ...fem.assembly import assemble
    from ...fem.factorization import condense, factorize

    scene = scene_of(scenario, dim, law, dofs, nodes)
    start = time.perf_counter()
    fem = assemble(scene)
    K, f = fem.K, fem.f
    assembly = time.perf_counter() - start
    # load the sparse solver's libraries and thread pools before any timing (MKL: ~0.1–0.5 s once)
    small = np.arange(min(fem.n_free, 300))
    condense(K[small][:, small], small[-10:], dim=fem.dim).solve(f[small])

    resettable = _reset_peak()
    base = _rss_mb("VmRSS")
    start = time.perf_counter()
    u = factorize(K, dim=fem.dim).solve(f)
    linear = time.perf_counter() - start
    memory_linear = _rss_mb("VmHWM") - base
    del u

    _reset_peak()
    base = _rss_mb("VmRSS")
    timings: dict = {}
    start = time.perf_counter()
    model = formulate(fem, formulation, timings)
    result = model.solve(solver)
    total = time.perf_counter() - start
    memory_contact = _rss_mb("VmHWM") - base
    unknowns = fem.contact.m + (model.friction.R.shape[0] if model.friction is not None else 0)
    return {
        "scenario": scenario, "dim": dim, "law": law, "dofs": fem.n_free, "contact_nodes": fem.contact.m,
        "unknowns": unknowns, "formulation": MATRIX_FREE if solvers.matrix_free(model.program) else model.formulation,
        "solver": result.solver, "status": result.status,
        "iterations": result.extra.get("picard", {}).get("iterations", result.iterations),
        "coulomb_newton": (result.extra.get("picard", {}).get("attempts") or [{}])[0].get("newton") or "",
        "assembly": assembly, "linear": linear, "condensation": timings.get("condensation", 0.0),
        "contact_solve": result.timings.get("solve", 0.0), "contact_total": total, "ratio": total / linear,
        "end_to_end": (assembly + total) / (assembly + linear),
        "memory_linear_mb": memory_linear if resettable else float("nan"),
        "memory_contact_mb": memory_contact if resettable else float("nan"),
        "memory_ratio": memory_contact / max(memory_linear, 1.0) if resettable else float("nan"),
        "certificate": result.certificate.worst if result.certificate is not None else float("nan"),
        "reason": model.reason, "timings": result.timings,
    }


def run(dim: int, sizes, laws=LAWS, formulation: str = "auto", solver: str = "auto", progress=print,
        scenario: str = "punch", nodes=(None,)) -> list:
    """All cases, each in a fresh Python process (clean caches, thread pools and peak memory)."""
    from .shapes import SHAPES

    rows = []
    family = SHAPES[dim] if scenario == "shapes" else (scenario,)
    for dofs, count, scene in ((dofs, count, scene) for dofs in sizes for count in nodes for scene in family):
        for law in laws:
            case = json.dumps([dim, law, dofs, formulation, solver, scene, count])
            done = subprocess.run([sys.executable, "-m", "convexcontact.studies.benchmarks.bench", "--case", case],
                                  check=False, capture_output=True, text=True, env=ENVIRONMENT)
            if done.returncode != 0:
                progress(f"{dim}-D {scene} {law} {dofs:.0e}: failed\n{done.stderr.strip()[-2000:]}")
                continue
            rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
            progress((plastic_bench.format_row if scenario == "plastic" else format_row)(rows[-1]))
    return rows


def friction_sweep(dim: int, dofs: float, coefficients, solver: str = "auto", progress=print) -> dict:
    """Coulomb solves for many friction coefficients: independent solves against one model reused
    through :meth:`~convexcontact.drivers.prepared.Model.with_law` (assembly, trace, condensation kept)."""
    from ...drivers.prepared import prepare
    from ...scene.description import Coulomb

    scene = punch_scene(dim, "coulomb", dofs)
    start = time.perf_counter()
    independent = [prepare(scene.with_law(Coulomb(friction=F))).solve(solver) for F in coefficients]
    alone = time.perf_counter() - start
    start = time.perf_counter()
    model = prepare(scene)
    reused = [model.with_law(Coulomb(friction=F)).solve(solver) for F in coefficients]
    shared = time.perf_counter() - start
    difference = max(float(np.abs(a.contact.pressure - b.contact.pressure).max() / a.max_pressure)
                     for a, b in zip(independent, reused, strict=True))
    row = {"dim": dim, "dofs": model.fem.n_free, "count": len(coefficients), "formulation": model.formulation,
           "independent": alone, "reused": shared, "speedup": alone / shared, "max_pressure_difference": difference}
    progress(f"{dim}-D sweep of {len(coefficients)} friction coefficients, {row['dofs']} DOFs ({row['formulation']}): "
             f"independent {alone:.2f} s, one model {shared:.2f} s, {row['speedup']:.1f}× faster; "
             f"pressures agree to {difference:.1e} p_max")
    return row


def format_row(row: dict) -> str:
    from .shapes import SHAPES

    return ((f"{row['scenario']:>17} " if row["scenario"] in SHAPES[row["dim"]] else "") + f"{row['dim']}-D {row['law']:>9} {row['dofs']:>8d} DOFs {row['unknowns']:>5d} unknowns "
            f"{row['formulation']:>6}/{row['solver']:<9} {row['status']:>10} it {row['iterations']:>3}  "
            f"assembly {row['assembly']:6.2f} s  linear {row['linear']:6.2f} s  contact {row['contact_total']:6.2f} s "
            f"(condensation {row['condensation']:.2f}, solve {row['contact_solve']:.2f})  ratio {row['ratio']:5.2f}  "
            f"end-to-end {row['end_to_end']:5.2f}  "
            f"memory {row['memory_contact_mb']:.0f}/{row['memory_linear_mb']:.0f} MB = {row['memory_ratio']:.2f}  "
            f"certificate {row['certificate']:.1e}" + (f"  Newton {row['coulomb_newton']}" if row.get("coulomb_newton") else ""))


def write_csv(rows: list, path, columns=COLUMNS) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def plot(rows: list, path) -> Path:
    """The ratio contact ÷ linear solve against DOFs, one line per (dimension, law)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...results.plots import save_figure

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for dim, law in sorted({(r["dim"], r["law"]) for r in rows}):
        mine = sorted((r for r in rows if (r["dim"], r["law"]) == (dim, law)), key=lambda r: r["dofs"])
        ax.plot([r["dofs"] for r in mine], [r["ratio"] for r in mine], "o-" if dim == 2 else "s--",
                label=f"{dim}-D {law}")
    for target, dim in ((2, 2), (3, 2), (5, 3), (8, 3)):
        ax.axhline(target, color="0.7", lw=0.8, ls=":" if dim == 2 else "-.")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("free DOFs")
    ax.set_ylabel("contact solve ÷ one linear solve")
    ax.set_title("cost of contact against one linear elastic solve (grey: targets)")
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def check_arguments(args) -> None:
    """The solver, formulation, output folder, sizes and the estimated run time, before any case runs."""
    from ... import solvers
    from ...scene.meshing import check_memory, check_size

    solvers.check_name(args.solver)
    if args.scenario == "plastic":
        plastic_bench.check_arguments(args)
    if args.formulation not in ("auto", "primal", "dual", "dual-matrix-free"):
        raise ValueError(f"--formulation: unknown {args.formulation!r}; use auto, primal, dual or dual-matrix-free")
    if args.sizes is not None and min(args.sizes) < 100:
        raise ValueError(f"--sizes: {min(args.sizes):g} DOFs; give sizes of at least 100 free DOFs, "
                         "e.g. --sizes 1e4 1e5")
    if args.nodes is not None and (args.scenario != "whole-face" or min(args.nodes) < 2):
        raise ValueError("--nodes: give at least 2 contact nodes, with --scenario whole-face")
    if args.sweep:
        check_folder_target(args.out, "--out")
    else:
        check_new_files(args.out, (f"{csv_name(args)}.csv", f"{csv_name(args)}.png"), "--out", args.overwrite)
    sizes = args.sizes or SIZES[args.dim]
    for dofs in sizes:
        if args.scenario in ("two-body", "shapes"):  # meshes built with the scene: estimated from the target DOFs
            with named("--sizes"):
                check_memory(dofs, args.dim, "--sizes", f"--sizes {dofs:g}", "give fewer DOFs")
            continue
        for nodes in nodes_of(args):
            with named("--sizes" if nodes is None else "--sizes/--nodes"):
                check_size(scene_of(args.scenario, args.dim, "signorini", dofs, nodes).body)
    cases = 2 * args.sweep if args.sweep else len(sizes) * len(args.laws) * len(nodes_of(args)) * len(family_of(args))
    mean = sizes[0] if args.sweep else sum(sizes) / len(sizes)
    check_duration("--sweep" if args.sweep else "--sizes", cases, SECONDS_PER_DOF * mean, "contact solves",
                   "give fewer or smaller sizes" + (", or a smaller COUNT" if args.sweep else ", or fewer --laws"))


def csv_name(args) -> str:
    """The name of the bench's CSV and PNG in --out."""
    return f"bench_{args.dim}d" + ("" if args.scenario == "punch" else f"_{args.scenario}")


def family_of(args) -> tuple:
    """The scenes of the scenario: each shape of :mod:`.shapes`, or the scenario's one scene."""
    from .shapes import SHAPES

    return SHAPES[args.dim] if args.scenario == "shapes" else (args.scenario,)


def nodes_of(args) -> tuple:
    """The contact nodes of the whole-face cases (None for the punch, whose mesh sets them)."""
    if args.scenario != "whole-face":
        return (None,)
    return tuple(args.nodes or NODES[args.dim])


def main(argv=None) -> list:
    """``convexcontact bench [--dim 2|3] [--sizes N …]``: contact against linear solve, per size."""
    parser = argparse.ArgumentParser(prog="convexcontact bench", description=main.__doc__)
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--sizes", type=number("1e4", positive=False), nargs="+", default=None,
                        help="target free DOFs (default: 1e4 … 1e6 in 2-D, 1e4 … 3e5 in 3-D)")
    parser.add_argument("--laws", nargs="+", choices=LAWS, default=None,
                        help="default: all three; signorini with --scenario plastic")
    parser.add_argument("--scenario", choices=SCENARIOS, default="punch",
                        help="punch (a small contact zone), whole-face (a block's whole bottom face in contact) "
                        "or two-body (a punch with its own mesh on an elastic foundation, mortar; 3-D: two spheres) or "
                        "shapes (a family: 2-D block, tall block, strips 20:1 to 400:1 with free or clamped ends; 3-D "
                        "flat and tall blocks, plates 20:20:1 with free or clamped edges; two bodies), "
                        "or plastic (a plastic step of Prandtl's punch: conic, Newton's fast path and return "
                        "mapping; 2-D)")
    parser.add_argument("--nodes", type=number("1e3"), nargs="+", default=None,
                        help="whole-face: contact nodes (default: 1e3 4e3), each case at each of --sizes")
    parser.add_argument("--formulation", default="auto", help="auto | primal | dual | dual-matrix-free")
    parser.add_argument("--solver", default="auto", help="auto (the one that takes the program) | clarabel | "
                        "osqp | cvxpy[:NAME] | newton-cg")
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="folder for bench_<dim>d.csv and .png")
    parser.add_argument("--overwrite", action="store_true", help="replace the CSV and PNG of an earlier bench in --out")
    parser.add_argument("--sweep", type=integer(1, 10), default=0, metavar="COUNT",
                        help="instead: COUNT Coulomb coefficients in [0.1, 0.5] at the first size, independent "
                        "solves against one reused model")
    parser.add_argument("--case", help=argparse.SUPPRESS)  # internal: one case, in this process
    args = parser.parse_args(argv)
    args.laws = args.laws or (["signorini"] if args.scenario == "plastic" else list(LAWS))
    if args.case:
        print(json.dumps(measure(*json.loads(args.case))))
        return []
    try:
        check_arguments(args)
    except ValueError as error:  # SceneError too: argparse's exit 2, usage and "error: --OPTION: …"
        parser.error(str(error))
    if args.sweep:
        return [friction_sweep(args.dim, (args.sizes or SIZES[args.dim])[0], np.linspace(0.1, 0.5, args.sweep),
                               args.solver)]
    rows = run(args.dim, args.sizes or SIZES[args.dim], args.laws, args.formulation, args.solver,
               scenario=args.scenario, nodes=nodes_of(args))
    if rows:
        name = csv_name(args)
        columns = plastic_bench.COLUMNS if args.scenario == "plastic" else COLUMNS
        print("wrote", write_csv(rows, args.out / f"{name}.csv", columns), plot(rows, args.out / f"{name}.png"))
    return rows


if __name__ == "__main__":
    main()
