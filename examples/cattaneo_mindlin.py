"""Cattaneo–Mindlin: press with P, pull with Q < F P; the stick zone is c/a = sqrt(1 − Q/(F P)) (case 5).

β = 0 needs an incompressible body (ν → 0.5): Q2 elements (Q1/P1 lock) and a large block on
rollers (a clamped base couples normal and tangential response). ``auto`` condenses K onto the
157 contact nodes (the dual: the Picard map's Tresca steps on 314 unknowns) and certifies the answer
in 8 Picard steps (certificate 1e-7, 3–6 s); Clarabel on the sparse primal with a static
regularization took 8 solves of ~6 s.

    python examples/cattaneo_mindlin.py [--h 0.01] [--ratio 0.5] [--out out/cattaneo]
"""

import argparse
import dataclasses

import numpy as np

import convexcontact as cc
from convexcontact.scene.description import Coulomb
from convexcontact.scene.library import HERTZ_FORCE, frictional_punch, punch_mesh


def scene(h: float, ratio: float, friction: float = 0.6) -> cc.Scene:
    # Picard tol above the inner solves' noise: with λ/μ ≈ 1e5 the relative change hovers at 1e-8 – 5e-8
    # once converged (measured), so tol = 1e-8 would be met only by chance
    law = Coulomb(friction=friction, tol=1e-7)
    punch = cc.Obstacle("parabolic", radius=1.0, force=HERTZ_FORCE, tangential_force=ratio * friction * HERTZ_FORCE)
    return dataclasses.replace(
        frictional_punch(nu=0.49999, element="Q2", law=law),
        body=cc.Body(punch_mesh(h, width=16.0, depth=8.0, quads=True), "Q2"),
        dirichlet=(cc.Dirichlet("bottom", uy=0.0), cc.Dirichlet("left", ux=0.0), cc.Dirichlet("right", ux=0.0)),
        contact=cc.Contact("top", punch, law),
    )


def main(h: float = 0.01, ratio: float = 0.5, out: str = "out/cattaneo"):
    result = cc.solve(scene(h, ratio))
    s, status = result.contact.coordinate, result.contact.status
    c, a = np.ptp(s[status == "stick"]) / 2, np.ptp(s[status != "open"]) / 2
    print(f"c/a = {c / a:.3f}, Cattaneo–Mindlin {np.sqrt(1 - ratio):.3f}; Q/(F P) = "
          f"{result.tangential_force / (0.6 * result.normal_force):.3f}; certificate {result.certificate.worst:.1e}")
    result.save(out)
    return result, c / a


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.01)
    parser.add_argument("--ratio", type=float, default=0.5)
    parser.add_argument("--out", default="out/cattaneo")
    main(**vars(parser.parse_args()))
