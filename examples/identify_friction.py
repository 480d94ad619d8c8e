"""Identify the friction coefficient μ and Young's modulus E from a noisy force–displacement curve.

A block pressed on a rigid foundation (its top lowered by d) is moved sideways by a: the measured
curve is the normal force P(a) and the friction force Q(a) on the foundation — Q grows with a (the
slope set by E) until the whole contact slips (Q = μ P; P set by E). Synthetic measurements are
made with the truth and Gaussian noise; the misfit J = ½ Σ ((P − P̂)² + (Q − Q̂)²)/σ² is minimized
by L-BFGS-B with its exact gradient: one adjoint solve per point of the curve (cc.gradient), no
finite differences. The standard errors come from the Gauss–Newton Hessian, assembled from the
forward sensitivities (cc.sensitivity): the estimate should lie within about two of them of the truth.

    python examples/identify_friction.py [--points 8] [--noise 2e-4] [--seed 0] [--nx 12]
"""

import argparse
import time

import numpy as np
import scipy.optimize

import convexcontact as cc

TRUTH = {"friction": 0.3, "E": 1.0}
START = {"friction": 0.15, "E": 2.0}
PARAMETERS = ("friction", "E")


def block(friction: float, E: float, slide: float, press: float = 0.01, nx: int = 12) -> cc.Scene:
    """A 2 × 1 block, its top lowered by ``press`` and moved sideways by ``slide``, Coulomb friction below."""
    return cc.Scene(name="sliding_block", body=cc.Body(cc.Rectangle(width=2.0, height=1.0, nx=nx, ny=nx // 2)),
                    materials=cc.Material(E=E, nu=0.3), dirichlet=(cc.Dirichlet("top", ux=slide, uy=-press),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), cc.Coulomb(friction=friction)))


def curve(theta: dict, slides: np.ndarray, nx: int = 12) -> list[cc.ContactResult]:
    """The certified answers along the curve for parameters ``theta``."""
    results = [cc.solve(block(theta["friction"], theta["E"], a, nx=nx), formulation="dual") for a in slides]
    assert all(r.status == "solved" for r in results), [r.message for r in results if r.status != "solved"]
    return results


def forces(results) -> np.ndarray:
    """(P, Q) at every point of the curve, stacked."""
    return np.array([[r.normal_force, r.tangential_force] for r in results]).ravel()


def misfit(x: np.ndarray, slides: np.ndarray, measured: np.ndarray, noise: float, nx: int,
           log: list) -> tuple[float, np.ndarray]:
    """J and dJ/dx for x = (μ, ln E): the adjoint gradient of each point's answer, chained."""
    theta = {"friction": x[0], "E": float(np.exp(x[1]))}
    results = curve(theta, slides, nx)
    residual = (forces(results) - measured) / noise
    grad = np.zeros(2)
    for r, (dP, dQ) in zip(results, residual.reshape(-1, 2)):
        g = cc.gradient(r, list(PARAMETERS), normal_force=dP / noise, tangential_force=dQ / noise)
        grad += [g["friction"], g["E"] * theta["E"]]
    log.append((theta, 0.5 * residual @ residual))
    return 0.5 * residual @ residual, grad


def standard_errors(theta: dict, slides: np.ndarray, noise: float, nx: int) -> dict:
    """sqrt(diag((JᵀJ)⁻¹)) of the residuals' Jacobian J (forward sensitivities) at ``theta``."""
    rows = []
    for r in curve(theta, slides, nx):
        found = cc.sensitivity(r, list(PARAMETERS))
        rows += [[found[p].derivative.normal_force for p in PARAMETERS],
                 [found[p].derivative.tangential_force for p in PARAMETERS]]
    jacobian = np.array(rows) / noise
    return dict(zip(PARAMETERS, np.sqrt(np.diag(np.linalg.inv(jacobian.T @ jacobian)))))


def main(points: int = 8, noise: float = 2e-4, seed: int = 0, nx: int = 12):
    slides = np.linspace(0.002, 0.03, points)
    exact = forces(curve(TRUTH, slides, nx))
    measured = exact + noise * np.random.default_rng(seed).standard_normal(exact.size)
    log = []
    start = time.perf_counter()
    fit = scipy.optimize.minimize(misfit, [START["friction"], np.log(START["E"])], args=(slides, measured, noise, nx, log),
                                  jac=True, method="L-BFGS-B", bounds=[(0.01, 2.0), (np.log(0.05), np.log(20.0))])
    elapsed = time.perf_counter() - start
    estimate = {"friction": float(fit.x[0]), "E": float(np.exp(fit.x[1]))}
    errors = standard_errors(estimate, slides, noise, nx)
    print(f"{len(log)} evaluations of J and its gradient ({points} solves + {points} adjoints each) in {elapsed:.1f} s;"
          f" J from {log[0][1]:.3g} to {fit.fun:.3g} ({2 * points} measurements)")
    for name in PARAMETERS:
        print(f"  {name:8s} truth {TRUTH[name]:.4f}  start {START[name]:.4f}  estimate {estimate[name]:.4f} "
              f"± {errors[name]:.4f}  ({(estimate[name] - TRUTH[name]) / errors[name]:+.1f} standard errors)")
    return estimate, errors, fit, log


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=8)
    parser.add_argument("--noise", type=float, default=2e-4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nx", type=int, default=12)
    main(**vars(parser.parse_args()))
