"""3-D Hertz: a rigid sphere on an elastic body, quarter model, against a = (3PR/(4E*))^(1/3), p₀ = 3P/(2πa²).

Run ``python examples/hertz_sphere.py`` for the mesh-convergence table of docs/scenes.md.
"""

import numpy as np

import convexcontact as cc
from convexcontact.analytic import hertz_sphere
from convexcontact.scene.library import HERTZ_SPHERE_FORCE
from convexcontact.scene.library import hertz_sphere as scene


def fit(result) -> tuple[float, float]:
    """p0 and a of p² = p0²(1 − r²/a²) fitted to the nodes above 30% of the peak pressure."""
    p, r = result.contact.pressure, result.contact.radius
    inside = p > 0.3 * p.max()
    (c0, c1), *_ = np.linalg.lstsq(np.column_stack([np.ones(inside.sum()), r[inside] ** 2]), p[inside] ** 2, rcond=None)
    return float(np.sqrt(c0)), float(np.sqrt(-c0 / c1))


def main(cells=(12, 16, 20), out: str | None = "out/hertz_sphere"):
    a, p0 = hertz_sphere(HERTZ_SPHERE_FORCE, 1.0, 1.0, 0.3)
    rows = []
    for n in cells:
        result = cc.solve(scene(n), "clarabel")
        fitted_p0, fitted_a = fit(result)
        rows.append((n, result.ndof, result.max_pressure / p0 - 1, fitted_p0 / p0 - 1, fitted_a / a - 1,
                     result.contact_half_width / a - 1, result.timings["solve"]))
        print("cells {:3d}  DOFs {:6d}  p_max {:+.2%}  fitted p0 {:+.2%}  fitted a {:+.2%}  "
              "last closed node {:+.2%}  solve {:.1f} s".format(*rows[-1]))
    if out:
        result.save(out)
    return result, rows


if __name__ == "__main__":
    main()
