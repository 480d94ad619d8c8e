"""Two elastic cylinders pressed together, non-matching meshes (docs/bodies.md): mortar, node-to-segment, Hertz.

Plane strain, R₁ = R₂ = 4 (R = 2), E = 1 and ν = 0.3 for both (E* = E/(2(1 − ν²))), the lower mesh 1.3 times
coarser. Mortar follows Hertz's pressure to about 1 % of p₀; node-to-segment oscillates by about 7 %.

    python examples/two_cylinders.py [--h 0.005] [--out out/two_cylinders]
"""

import argparse

import numpy as np

import convexcontact as cc
from convexcontact.analytic import hertz_plane_strain, hertz_pressure


def main(h: float = 0.005, out: str = "out/two_cylinders") -> dict:
    errors = {}
    for method in ("mortar", "node_to_segment"):
        scene = cc.bodies_library.two_cylinders(h, radii=(4.0, 4.0), approach=0.006, width=4.0, height=2.0,
                                                master_h=1.3 * h, method=method)
        result = cc.solve(scene)
        a, p0 = hertz_plane_strain(result.normal_force, 2.0, 0.5, 0.3)  # E/2: the two bodies' compliances add
        s = result.contact.coordinate
        inside = np.abs(s) < 0.8 * a
        errors[method] = np.abs(result.contact.pressure - hertz_pressure(s, a, p0))[inside].max() / p0
        print(f"{method:16s} a {result.contact_half_width:.4f} (Hertz {a:.4f}), p_max {result.max_pressure:.5f} "
              f"(p0 {p0:.5f}), largest error over |x| < 0.8a {errors[method]:.2%}, certificate "
              f"{result.certificate.worst:.1e}")
        if method == "mortar":
            result.save(out)
    return errors


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.005)
    parser.add_argument("--out", default="out/two_cylinders")
    main(**vars(parser.parse_args()))
