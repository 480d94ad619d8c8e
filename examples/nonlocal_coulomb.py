"""Nonlocal Coulomb friction (Oden–Duvaut): the slip bound is F times the mollified pressure.

    python examples/nonlocal_coulomb.py [--h 0.01] [--out out/nonlocal]
"""

import argparse

import numpy as np

import convexcontact as cc
from convexcontact.scene.description import Coulomb
from convexcontact.scene.library import frictional_punch


def main(h: float = 0.01, out: str = "out/nonlocal"):
    results = {}
    for radius in (0.0, 0.02, 0.04):  # ρ = 0 is the local law; ρ below the node spacing is too
        law = Coulomb(friction=0.6, smoothing_radius=radius)
        results[radius] = cc.solve(frictional_punch(h=h, element="Q1", law=law))
        r = results[radius]
        print(f"ρ = {radius}: {r.extra['picard']['outcome']} in {r.extra['picard']['iterations']} iterations, "
              f"stick nodes {np.sum(r.contact.status == 'stick')}, max |λ_T| {np.abs(r.contact.friction).max():.4g}")
    results[0.04].save(out)
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.01)
    parser.add_argument("--out", default="out/nonlocal")
    main(**vars(parser.parse_args()))
