"""Prandtl's flat punch: a smooth rigid punch of half-width a pressed into an elastic–perfectly plastic (von Mises)
plane-strain block; the force levels off near the limit load 2a (2 + π) k, k = σ_Y/√3 (docs/plasticity.md).

    python examples/plastic_punch.py [--nx 24 32 48] [--out out/plastic_punch]
"""

import argparse

import numpy as np

import convexcontact as cc

HALF_WIDTH, YIELD_STRESS, E, NU = 0.25, 1e-3, 1.0, 0.3
PRANDTL = 2 * HALF_WIDTH * (2 + np.pi) * YIELD_STRESS / np.sqrt(3)
"""The limit force per unit thickness of a smooth (or rough) flat punch on a rigid–perfectly plastic half-plane."""


def flat_punch(nx: int, depths) -> cc.Scene:
    """The block [-1, 1] × [-1, 0] (P2, uniform: the punch edges on nodes when nx is a multiple of 8), rate-independent
    J2, pushed by the punch to ``depths`` (one step each)."""
    return cc.Scene(
        name="prandtl", body=cc.Body(cc.Rectangle(2.0, 1.0, nx, nx // 2, origin=(-1.0, -1.0)), "P2"),
        materials=cc.Material(E, NU, yield_stress=YIELD_STRESS),
        dirichlet=(cc.Dirichlet("bottom", ux=0.0, uy=0.0), cc.Dirichlet("left", ux=0.0), cc.Dirichlet("right", ux=0.0)),
        contact=cc.Contact("top", cc.Obstacle("flat_punch", radius=HALF_WIDTH, depth=depths[-1]), cc.Signorini()),
        history=cc.History(list(range(1, len(depths) + 1)), {"obstacle.depth": list(depths)}))


def main(nx=(24,), out: str | None = "out/plastic_punch"):
    """Push to 2, 8 and 32 times the depth the limit force takes elastically; print force / Prandtl's per mesh."""
    depths = [m * PRANDTL / E for m in (2, 8, 32)]
    for cells in nx:
        history = cc.run_history(flat_punch(cells, depths))
        ratios = np.array(history.series()["normal_force"]) / PRANDTL
        print(f"nx = {cells} (h = a/{cells // 8}): force / 2a(2 + π)k = {', '.join(f'{r:.4f}' for r in ratios)}, "
              f"{history.status}, certificate ≤ {max(s.certificate.worst for s in history.steps):.1e}")
    if out is not None:
        history.save(out)
    return ratios, history


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, nargs="+", default=[24])
    parser.add_argument("--out", default="out/plastic_punch")
    main(**vars(parser.parse_args()))
