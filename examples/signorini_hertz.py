"""Signorini contact: a rigid cylinder pressed with force P on a block, against Hertz (DESIGN.md case 2).

    python examples/signorini_hertz.py [--nx 80] [--out out/signorini]
"""

import argparse

import convexcontact as cc
from convexcontact.analytic import hertz_plane_strain
from convexcontact.scene.library import HERTZ_FORCE, hertz_punch


def main(nx: int = 80, out: str = "out/signorini"):
    result = cc.solve(hertz_punch(nx=nx), solver="clarabel")
    a, p0 = hertz_plane_strain(HERTZ_FORCE, 1.0, 1.0, 0.3)
    print(f"contact half-width {result.contact_half_width:.4f} (Hertz {a:.4f}), "
          f"peak pressure {result.max_pressure:.5f} (Hertz {p0:.5f}), certificate {result.certificate.worst:.1e}")
    result.save(out)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=80)
    parser.add_argument("--out", default="out/signorini")
    main(**vars(parser.parse_args()))
