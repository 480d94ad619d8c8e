"""``convexcontact study uniqueness``: how many solutions Hild's one-triangle problem has, over F and the load.

The load (F1, F2) = (cos θ, sin θ) turns through every direction; for each friction coefficient F
and angle θ the exhaustive enumeration (:func:`~convexcontact.drivers.solutions.all_solutions`)
counts the solutions (a continuum counts as ∞). The map reproduces the regions of Prop. 4.1 (seed
001): one solution below F_c = 3 − 4ν, a continuum on the line F1 = F F2 at F = F_c, two or three
beyond; the closed-form count is written beside the computed one.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

CSV, PNG = "uniqueness.csv", "uniqueness.png"
COLUMNS = ("friction", "angle", "F1", "F2", "solutions", "closed_form", "continuum", "slopes")


def triangle(F1: float, F2: float, friction: float, nu: float):
    """Hild's triangle A(0,0), B(1,0), C(0,1): [B,C] clamped, traction on [A,C], contact on [A,B]."""
    import skfem as fe

    import convexcontact as cc

    mesh = fe.MeshTri1(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.array([[0], [1], [2]])).with_boundaries({
        "contact": lambda x: np.isclose(x[1], 0.0),
        "clamped": lambda x: np.isclose(x[0] + x[1], 1.0),
        "loaded": lambda x: np.isclose(x[0], 0.0),
    })
    return cc.Scene(name="hild", body=cc.Body(mesh, "P1"), materials=cc.Material(1.0, nu),
                    dirichlet=(cc.Dirichlet("clamped", ux=0.0, uy=0.0),),
                    tractions=(cc.Traction("loaded", vector=(F1, F2)),),
                    contact=cc.Contact("contact", cc.Obstacle("flat", gap=0.0), cc.Coulomb(friction=friction)))


def run(frictions, angles, nu: float = 0.3) -> list[dict]:
    """One row per (F, θ): the number of solutions found and the closed form's."""
    from ...analytic import hild_one_triangle_solutions
    from ...drivers.solutions import all_solutions

    rows = []
    for friction in frictions:
        for angle in angles:
            F1, F2 = np.cos(angle), np.sin(angle)
            found = all_solutions(triangle(F1, F2, friction, nu))
            exact = hild_one_triangle_solutions(F1, F2, friction, 1.0, nu, 1.0)
            continuum = any(s.continuum for s in found.solutions)
            rows.append({"friction": friction, "angle": angle, "F1": F1, "F2": F2,
                         "solutions": float("inf") if continuum else len(found),
                         "closed_form": float("inf") if any(e["continuum"] for e in exact) else len(exact),
                         "continuum": continuum,
                         "slopes": " ".join(f"{s.picard_slope:.3g}" for s in found.solutions)})
    return rows


def plot(rows: list[dict], nu: float, path: Path) -> Path:
    """The count of solutions over (θ, F), with F_c and the critical load line F1 = F F2 marked."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    from ...results.plots import save_figure

    frictions = sorted({r["friction"] for r in rows})
    angles = sorted({r["angle"] for r in rows})
    counts = np.array([[next(r["solutions"] for r in rows if r["friction"] == f and r["angle"] == a)
                        for a in angles] for f in frictions])
    counts = np.where(np.isinf(counts), 4, counts)
    fig, ax = plt.subplots(figsize=(8, 5))
    image = ax.pcolormesh(np.degrees(angles), frictions, counts, shading="nearest", vmin=0.5, vmax=4.5,
                          cmap=ListedColormap(["#d9ecd0", "#f7d794", "#e58e73", "#7b3f61"]))
    bar = fig.colorbar(image, ticks=[1, 2, 3, 4])
    bar.ax.set_yticklabels(["1", "2", "3", "∞"])
    bar.set_label("solutions")
    ax.axhline(3 - 4 * nu, color="k", lw=1, ls="--", label=f"F_c = 3 − 4ν = {3 - 4 * nu:g}")
    theta = np.linspace(-np.pi, 0, 202)[1:-1]
    line = np.cos(theta) / np.sin(theta)  # F1 = F F2: F = cot θ (F2 < 0)
    ax.plot(np.degrees(theta), line, "k:", lw=1, label="F1 = F F2")
    ax.set_ylim(min(frictions), max(frictions))
    ax.set_xlim(np.degrees(min(angles)), np.degrees(max(angles)))
    ax.set_xlabel("load angle θ [°], (F1, F2) = (cos θ, sin θ)")
    ax.set_ylabel("friction coefficient F")
    ax.set_title("Hild's one-triangle problem: number of solutions (exhaustive)")
    ax.legend(loc="upper right", fontsize=8)
    return save_figure(fig, path)


CASE_SECONDS = 0.1
"""Seconds of one case (the exhaustive enumeration on the triangle), a low estimate: measured 0.16 s on the
shared 2-vCPU machines."""


def main(argv=None) -> list[dict]:
    """``convexcontact study uniqueness [--frictions N] [--angles N] …``: count the solutions of Hild's triangle over
    a grid of F and load angles; uniqueness.csv and uniqueness.png in --out."""
    from ...results.output import check_new_files
    from ..arguments import check_duration, integer, number

    parser = argparse.ArgumentParser(prog="convexcontact study uniqueness", description=main.__doc__)
    parser.add_argument("--frictions", type=integer(2, 61), default=61, help="values of F in [0, --max-friction]")
    parser.add_argument("--max-friction", type=number("3"), default=3.0)
    parser.add_argument("--angles", type=integer(2, 46), default=46, help="load directions in --angle-range")
    parser.add_argument("--angle-range", type=number("-180 -90", positive=False), nargs=2, default=[-180.0, -90.0],
                        metavar=("FROM", "TO"), help="degrees, FROM < TO (default: F1, F2 ≤ 0, where uniqueness is "
                        "lost)")
    parser.add_argument("--nu", type=number("0.3", positive=False), default=0.3, help="Poisson's ratio, 0 ≤ ν < 0.5")
    parser.add_argument("--out", type=Path, default=Path("out/uniqueness"), help="folder for the CSV and PNG")
    parser.add_argument("--overwrite", action="store_true", help="replace the CSV and PNG of an earlier run")
    args = parser.parse_args(argv)
    if not 0 <= args.nu < 0.5:
        raise ValueError(f"--nu: {args.nu:g} is no Poisson's ratio of a compressible solid; give 0 ≤ ν < 0.5, "
                         "e.g. 0.3")
    if not args.angle_range[0] < args.angle_range[1]:
        raise ValueError(f"--angle-range: FROM {args.angle_range[0]:g} must be below TO {args.angle_range[1]:g}, "
                         "e.g. --angle-range -180 -90")
    check_duration("--frictions/--angles", args.frictions * args.angles, CASE_SECONDS, "cases",
                   "give fewer --frictions or --angles")
    check_new_files(args.out, (CSV, PNG), "--out", args.overwrite)
    frictions = np.linspace(0.0, args.max_friction, args.frictions)
    angles = np.radians(np.linspace(*args.angle_range, args.angles))
    rows = run(frictions, angles, args.nu)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / CSV, "w", newline="") as handle:
        writer = csv.DictWriter(handle, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    plot(rows, args.nu, args.out / PNG)
    disagree = sum(r["solutions"] != r["closed_form"] for r in rows)
    print(f"{len(rows)} cases; counts {dict(sorted(_tally(rows).items()))}; differ from Prop. 4.1 in {disagree}; "
          f"wrote {args.out / CSV}, {args.out / PNG}")
    return rows


def _tally(rows):
    counts = {}
    for r in rows:
        key = "∞" if np.isinf(r["solutions"]) else int(r["solutions"])
        counts[key] = counts.get(key, 0) + 1
    return counts
