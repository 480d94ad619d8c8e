"""Picard loop for the frictional punch: time per inner solve with and without reuse.

With reuse: the driver's one solver session (Clarabel keeps its setup, OSQP its
factorization and warm start; the dual keeps K's factorization and W). Without: every
step builds and solves a fresh program (formulation + solver setup), as a naive loop would.

    python -m convexcontact.studies.benchmarks.picard_reuse [--sizes 0.01 0.005] [--solvers clarabel osqp]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from convexcontact import prepare, solvers
from convexcontact.drivers.picard import initial_pressure, pressure_map
from convexcontact.scene.library import frictional_punch


def fresh_loop(model, solver: str, iterations: int) -> float:
    """Mean time of a step that rebuilds the program and the solver (no reuse)."""
    bound, _ = pressure_map(model)
    s = bound(initial_pressure(model, solver, {}))
    times = []
    for _ in range(iterations):
        start = time.perf_counter()
        program, recover, _ = model.build(model.friction, s, model.epsilon)
        pressure = recover(solvers.solve(program, solver)).pressure
        times.append(time.perf_counter() - start)
        s = bound(pressure)
    return float(np.mean(times))


def main(sizes, solver_names, formulations):
    print(f"{'h':>7} {'DOFs':>7} {'form':>6} {'solver':>9} {'Picard it.':>10} {'reuse [s/step]':>15} {'fresh [s/step]':>15}")
    for h in sizes:
        for formulation in formulations:
            model = prepare(frictional_punch(h=h, element="Q1"), formulation)
            for solver in solver_names:
                result = model.solve(solver)
                history = result.extra["history"]
                reuse = np.mean([step["inner_time"] for step in history])
                fresh = fresh_loop(dataclasses.replace(model), solver, len(history))
                print(f"{h:7.4f} {model.fem.n_free:7d} {formulation:>6} {solver:>9} {len(history):10d} "
                      f"{reuse:15.3f} {fresh:15.3f}   ({result.extra['picard']['outcome']})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.01, 0.005])
    parser.add_argument("--solvers", nargs="+", default=["clarabel", "osqp"])
    parser.add_argument("--formulations", nargs="+", default=["primal", "dual"])
    args = parser.parse_args()
    main(args.sizes, args.solvers, args.formulations)
