"""Parameter sweeps of the approximate models against the exact answer, with fitted log-log slopes.

- :func:`penalty_sweep` — normal compliance c_N against exact non-penetration: the pressure
  error max|λ_N(c) − λ_N| / max λ_N decays like 1/c_N (expected slope −1) until it meets the
  solver's accuracy. OSQP by default: Clarabel stops on stiff penalties (docs/friction.md).
- :func:`regularization_sweep` — Hild's ε-regularized friction against the exact law: the
  displacement error max|u_ε − u| / max|u| grows like ε (expected slope +1) once ε is small
  against the slip itself. ::

    sweep = penalty_sweep(scene); print(sweep.slope); plot_sweep(sweep, "penalty.png")
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ...drivers.prepared import prepare
from ...results.result import ContactResult
from ...scene.description import NormalCompliance, Scene, Signorini, has_friction
from ..precision.work_precision import wall_time


@dataclasses.dataclass
class Sweep:
    """Rows (parameter, error, status, time) of one sweep and the slope the theory expects."""

    parameter: str
    error: str
    expected_slope: float
    rows: list[dict]

    @property
    def slope(self) -> float:
        """Least-squares slope of log(error) against log(parameter) over the solved rows (nan with < 2)."""
        return fitted_slope(self.rows)


def fitted_slope(rows: Sequence[dict]) -> float:
    points = [(r["parameter"], r["error"]) for r in rows if r.get("error") is not None and r["error"] > 0]
    if len(points) < 2:
        return math.nan
    x, y = np.log(np.array(points)).T
    return float(np.polyfit(x, y, 1)[0])


def exact_law(law):
    """The law without its approximation: no compliance, no regularization."""
    if not has_friction(law):
        return Signorini()
    return dataclasses.replace(law, compliance=None, regularization=None)


def row(parameter: float, result: ContactResult, error: float | None) -> dict:
    return {"parameter": float(parameter), "error": error, "status": result.status, "time": wall_time(result),
            "certificate": None if result.certificate is None else float(result.certificate.worst)}


def exact_solve(scene: Scene, solver: str, **options) -> ContactResult:
    result = prepare(scene.with_law(exact_law(scene.contact.law))).solve(solver, **options)
    if not result.solved:
        raise RuntimeError(f"exact solve: {result.status}: {result.message}")
    return result


def penalty_sweep(scene: Scene, stiffness: Sequence[float] = np.logspace(3, 6, 4), solver: str = "osqp",
                  **options) -> Sweep:
    """Pressure error of normal compliance c_N (user units, p = 1) against the exact law, per c_N."""
    exact = exact_solve(scene, solver, **options)
    law, rows = exact_law(scene.contact.law), []
    for c in stiffness:
        penalty = NormalCompliance(float(c))
        result = prepare(scene.with_law(dataclasses.replace(law, compliance=penalty) if has_friction(law)
                                        else penalty)).solve(solver, **options)
        error = None
        if result.solved:
            error = float(np.abs(result.contact.pressure - exact.contact.pressure).max() / exact.max_pressure)
        rows.append(row(c, result, error))
    return Sweep("c_N", "max |λ_N(c) − λ_N| / max λ_N", -1.0, rows)


def regularization_sweep(scene: Scene, epsilon: Sequence[float] = np.logspace(-5, -7, 3), solver: str = "clarabel",
                         **options) -> Sweep:
    """Displacement error of the ε-regularized friction law (ε a length, user units) against the exact law."""
    law = scene.contact.law
    if not has_friction(law):
        raise ValueError("regularization_sweep: the scene's law has no friction; use Tresca or Coulomb")
    exact = exact_solve(scene, solver, **options)
    scale = np.abs(exact.displacement).max()
    rows = []
    for e in epsilon:
        result = prepare(scene.with_law(dataclasses.replace(exact_law(law), regularization=float(e)))).solve(
            solver, **options)
        error = float(np.abs(result.displacement - exact.displacement).max() / scale) if result.solved else None
        rows.append(row(e, result, error))
    return Sweep("ε", "max |u_ε − u| / max |u|", 1.0, rows)


def plot_sweep(sweep: Sweep | Sequence[dict], path, title: str | None = None, expected_slope: float = -1.0) -> Path:
    """Log-log error against the parameter, the fitted slope in the legend and the expected slope as a dashed line.

    ``sweep``: a :class:`Sweep`, or its rows (then ``expected_slope`` gives the reference line).
    """
    if not isinstance(sweep, Sweep):
        sweep = Sweep("parameter", "error", expected_slope, list(sweep))
    from ...results.plots import plt, save_figure

    solved = [r for r in sweep.rows if r["error"] is not None and r["error"] > 0]
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    x = np.array([r["parameter"] for r in solved])
    y = np.array([r["error"] for r in solved])
    ax.loglog(x, y, "o-", label=f"measured (fitted slope {sweep.slope:+.2f})")
    if len(x):
        anchor = np.exp(np.mean(np.log(y)) - sweep.expected_slope * np.mean(np.log(x)))
        ax.loglog(x, anchor * x**sweep.expected_slope, "k--", lw=1, label=f"slope {sweep.expected_slope:+g}")
    ax.set_xlabel(sweep.parameter)
    ax.set_ylabel(sweep.error)
    ax.set_title(title or f"{sweep.parameter} sweep")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    return save_figure(fig, path)


def table(sweep: Sweep) -> str:
    lines = [f"{sweep.parameter:>10}  {'error':>10}  {'status':<12}{'time [s]':>9}"]
    for r in sweep.rows:
        error = "" if r["error"] is None else f"{r['error']:.2e}"
        lines.append(f"{r['parameter']:>10.1e}  {error:>10}  {r['status']:<12}{r['time']:>9.3f}")
    lines.append(f"fitted slope {sweep.slope:+.3f} (expected {sweep.expected_slope:+g})")
    return "\n".join(lines)


PLOT = Path("out/sweep.png")
"""Where ``convexcontact study sweep`` draws its plot unless told (--out)."""


def main(argv=None) -> Sweep:
    """``convexcontact study sweep penalty|regularization [--nx N] [--values V …]``: errors against the exact
    answer, the fitted slope, a plot."""
    import argparse

    from ... import solvers
    from ...results.output import check_folder_target, check_new_file
    from ...scene.library import hertz_punch, tresca_punch
    from ...scene.meshing import check_size
    from ..arguments import SECONDS_PER_DOF, check_duration, integer, named, number

    parser = argparse.ArgumentParser(prog="convexcontact study sweep", description=main.__doc__)
    parser.add_argument("kind", choices=["penalty", "regularization"])
    parser.add_argument("--nx", type=integer(2, 16), default=16, help="elements across the block (default 16)")
    parser.add_argument("--values", type=number("1e4"), nargs="+", default=None,
                        help="c_N (penalty) or ε (regularization) values, user units (default: logspace)")
    parser.add_argument("--solver", default=None, help="default: osqp (penalty), clarabel (regularization)")
    parser.add_argument("--out", type=Path, default=None, help="the plot (PNG; default out/sweep.png)")
    parser.add_argument("--overwrite", action="store_true", help="replace the plot of an earlier sweep")
    args = parser.parse_args(argv)
    if args.solver is not None:
        solvers.check_name(args.solver)
    scene = hertz_punch(nx=args.nx) if args.kind == "penalty" else tresca_punch(nx=args.nx)
    with named("--nx"):
        check_size(scene.body)
    values = args.values or (np.logspace(3, 6, 4) if args.kind == "penalty" else np.logspace(-5, -7, 3))
    dofs = 2 * (args.nx + 1) * (args.nx // 2 + 1)
    check_duration("--nx/--values", len(values) + 1, SECONDS_PER_DOF * dofs, "contact solves",
                   "give a smaller --nx or fewer --values")
    if args.out is None:  # the default's folder is made for it
        check_folder_target(PLOT.parent, "--out")
        PLOT.parent.mkdir(parents=True, exist_ok=True)
    out = args.out or PLOT
    check_new_file(out, "--out", args.overwrite, PLOT.name)
    if args.kind == "penalty":
        sweep = penalty_sweep(scene, values, args.solver or "osqp")
    else:
        sweep = regularization_sweep(scene, values, args.solver or "clarabel")
    print(table(sweep))
    print("wrote", plot_sweep(sweep, out, expected_slope=sweep.expected_slope))
    return sweep
