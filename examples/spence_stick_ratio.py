"""Spence's monotone indentation: the stick ratio c/a against the load step and the block width (issue 24).

A rigid cylinder (R = 1) pressed into a clamped block (ν = 0.3, Q1, h over |x| < 0.15) with Coulomb
friction, the depth × λ per step from 0.004 to 0.019: c/a averaged over the upper half of the depths,
beside the half-plane's self-similar value (a flat punch solved by boundary elements, no step at all;
convexcontact/studies/verification/spence.py says why). Prints the table, writes spence.csv and spence.png.

    python examples/spence_stick_ratio.py                 # F 0.2 0.4 0.6, λ 1.25 1.06, the 4-wide block (~1 min)
    python examples/spence_stick_ratio.py --full          # λ 1.25 … 1.03, widths 1 3 10 30, h 0.00125 (~15 min)
    python examples/spence_stick_ratio.py --friction 0.4 --step-ratios 1.25 1.03 --widths 10 --h 0.00125
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from convexcontact.studies.verification.spence import dundurs_beta, half_plane_stick_ratio, indentation

NU = 0.3
FULL = {"step_ratios": [1.25, 1.12, 1.06, 1.03], "widths": [10.0, 1.0, 3.0, 30.0], "h": 0.00125}
COLUMNS = ("friction", "width", "step_ratio", "steps", "final_a", "a_growth", "c_over_a", "spread", "cap",
           "half_plane", "certificate")


def study(frictions, step_ratios, widths, h, out: Path) -> list[dict]:
    """Every (F, width, λ) history; rows written to ``out``/spence.csv as they come."""
    reference = {friction: half_plane_stick_ratio(friction, NU) for friction in frictions}
    rows = []
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "spence.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for width in widths:
            for friction in frictions:
                for step_ratio in step_ratios:
                    row = indentation(friction, step_ratio, width, h)
                    row.update(cap=1 / row["a_growth"], half_plane=reference[friction])
                    rows.append(row)
                    writer.writerow({k: f"{v:.6g}" if isinstance(v, float) else v for k, v in row.items()})
                    file.flush()
                    print(f"F = {friction}, width {width:g} ({width / row['final_a']:.0f} a), depth × {step_ratio}"
                          f" (a × {row['a_growth']:.3f}): c/a = {row['c_over_a']:.3f} ± {row['spread'] / 2:.3f}"
                          f" (half-plane {reference[friction]:.3f}, cap a_{{k-1}}/a_k = {row['cap']:.3f})")
    return rows


def table(rows: list[dict]) -> str:
    """Markdown: one line per (F, width), one column per λ, the half-plane value last."""
    ratios = sorted({r["step_ratio"] for r in rows}, reverse=True)
    head = "| F | block width | " + " | ".join(f"× {s:g}" for s in ratios) + " | half-plane |"
    lines = [head, "|" + "---|" * (len(ratios) + 3)]
    for friction, width in dict.fromkeys((r["friction"], r["width"]) for r in rows):
        cells = {r["step_ratio"]: r for r in rows if r["friction"] == friction and r["width"] == width}
        a = cells[ratios[0]]["final_a"]
        lines.append(f"| {friction:g} | {width:g} ({width / a:.0f} a) | " + " | ".join(
            f"{cells[s]['c_over_a']:.3f}" if s in cells else "" for s in ratios)
            + f" | {cells[ratios[0]]['half_plane']:.3f} |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> None:
    """c/a against the growth of a per step, one panel per F: a line per width, the half-plane value and
    the cap a_{k−1}/a_k."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frictions = sorted({r["friction"] for r in rows})
    figure, axes = plt.subplots(1, len(frictions), figsize=(4.2 * len(frictions), 3.8), squeeze=False)
    growth = np.linspace(1.0, max(r["a_growth"] for r in rows) * 1.02, 50)
    for axis, friction in zip(axes[0], frictions):
        mine = [r for r in rows if r["friction"] == friction]
        for width in sorted({r["width"] for r in mine}):
            line = sorted((r["a_growth"], r["c_over_a"], r["spread"]) for r in mine if r["width"] == width)
            g, c, spread = np.array(line).T
            a = next(r["final_a"] for r in mine if r["width"] == width)
            axis.errorbar(g - 1, c, yerr=spread / 2, marker="o", capsize=2, label=f"block {width:g} wide ({width / a:.0f} a)")
        axis.axhline(mine[0]["half_plane"], color="k", lw=1, label="half-plane, no step")
        axis.plot(growth - 1, 1 / growth, "k:", lw=1, label="cap a$_{k-1}$/a$_k$")
        axis.set(title=f"F = {friction:g}, ν = {NU}, β/F = {dundurs_beta(NU) / friction:.2f}",
                 xlabel="growth of a per step, a$_k$/a$_{k-1}$ − 1", ylabel="stick ratio c/a", xlim=(0, None))
        axis.grid(alpha=0.3)
    axes[0][-1].legend(fontsize=7, loc="lower left")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(friction=(0.2, 0.4, 0.6), step_ratios=(1.25, 1.06), widths=(4.0,), h=0.0025, out="out/spence",
         full=False):
    if full:
        step_ratios, widths, h = FULL["step_ratios"], FULL["widths"], FULL["h"]
    out = Path(out)
    rows = study(list(friction), list(step_ratios), list(widths), h, out)
    print(table(rows))
    plot(rows, out / "spence.png")
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--friction", type=float, nargs="+", default=[0.2, 0.4, 0.6])
    parser.add_argument("--step-ratios", type=float, nargs="+", default=[1.25, 1.06], help="depth ratio per step")
    parser.add_argument("--widths", type=float, nargs="+", default=[4.0], help="block widths (the depth is half)")
    parser.add_argument("--h", type=float, default=0.0025, help="cell size over |x| < 0.15")
    parser.add_argument("--out", default="out/spence")
    parser.add_argument("--full", action="store_true", help="the study of docs/history.md (overrides the three above)")
    main(**vars(parser.parse_args()))
