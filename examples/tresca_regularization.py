"""Exact Tresca friction as an SOCP, and how far Hild's ε-regularization moves the answer.

    python examples/tresca_regularization.py [--nx 40] [--out out/tresca]
"""

import argparse

import numpy as np

import convexcontact as cc
from convexcontact.scene.library import tresca_punch


def main(nx: int = 40, out: str = "out/tresca"):
    # slip bound 0.005: a traction (a number, a formula in x and y, or nodal values)
    exact = cc.solve(tresca_punch(nx, slip_bound=0.005))
    print(f"exact: stick {np.sum(exact.contact.status == 'stick')} nodes, certificate {exact.certificate.worst:.1e}")
    rows = []
    for epsilon in (1e-4, 1e-5, 1e-6, 1e-7):
        regularized = cc.solve(tresca_punch(nx, slip_bound=0.005, regularization=epsilon))
        error = np.abs(regularized.displacement - exact.displacement).max() / np.abs(exact.displacement).max()
        rows.append((epsilon, error))
        print(f"ε = {epsilon:.0e}: relative displacement difference {error:.2e}")
    exact.save(out)
    return exact, rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nx", type=int, default=40)
    parser.add_argument("--out", default="out/tresca")
    main(**vars(parser.parse_args()))
