"""Coulomb friction by a Picard map over pressures: Oden's frictional punch (DESIGN.md case 4).

    python examples/coulomb_punch.py [--h 0.005] [--friction 0.6] [--out out/coulomb]
"""

import argparse

import numpy as np

import convexcontact as cc
from convexcontact.scene.library import frictional_punch


def main(h: float = 0.005, friction: float = 0.6, out: str = "out/coulomb"):
    def progress(iteration, change):
        print(f"  Picard {iteration:3d}: relative change of the slip bounds {change:.2e}")

    result = cc.prepare(frictional_punch(h=h, friction=friction, element="Q1")).solve("clarabel", progress=progress)
    s, status = result.contact.coordinate, result.contact.status
    c, a = np.ptp(s[status == "stick"]) / 2, np.ptp(s[status != "open"]) / 2
    print(f"{result.extra['picard']['outcome']} after {result.extra['picard']['iterations']} iterations; "
          f"stick zone c/a = {c / a:.3f}; Coulomb residual {result.certificate.worst:.1e}")
    result.save(out)  # contact.png: λ_T against ±F λ_N with the zones; picard.png: the convergence
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.005)
    parser.add_argument("--friction", type=float, default=0.6)
    parser.add_argument("--out", default="out/coulomb")
    main(**vars(parser.parse_args()))
