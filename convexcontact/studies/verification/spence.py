"""Spence's monotone indentation: the self-similar stick zone c/a, the load step and the block (issue 24).

A rigid cylinder (R = 1) pressed monotonically into an elastic body with Coulomb friction F: the
contact half-width a grows, and the stick zone |x| < c keeps c/a constant (self-similarity). Two
computations of that ratio:

- :func:`half_plane_stick_ratio`, the continuum limit, independent of the finite elements. With
  p = a P(x/a) and q = a Q(x/a) (a parabolic profile), the rates at a fixed point, ṗ = P − ξP′ and
  q̇ = Q − ξQ′, solve the problem of a *flat* punch of half-width a: the profile does not change
  during the step, only the approach, so u̇_z′ = 0 over the contact; u̇_x = 0 in the stick zone and
  q̇ = F ṗ (outwards) in the slip zones. The self-similar c/a is the one of the flat punch pressed
  monotonically, a problem with no step at all (its answer is proportional to the load), solved here
  on the half-plane by boundary elements.
- :func:`indentation`, the project's load-history driver on a finite clamped block (Q1, the graded
  mesh of :func:`~convexcontact.scene.library.punch_mesh`), the depth multiplied by ``step_ratio``
  each step. The annulus that enters contact during a step slips in that step, so c cannot exceed the
  previous step's a: coarse steps cap c/a near a_{k−1}/a_k.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import brentq

import convexcontact as cc
from convexcontact.drivers.history_run import run
from convexcontact.scene.library import frictional_punch, punch_mesh
from convexcontact.scene.load_history import History

FIRST_DEPTH, LAST_DEPTH = 0.004, 0.004 * 1.25**7
"""The depths of the first and last step (those of docs/history.md's eight steps × 1.25)."""


def dundurs_beta(nu: float) -> float:
    """β = (1 − 2ν) / (2(1 − ν)): the coupling of normal and tangential surface response of a half-plane."""
    return (1 - 2 * nu) / (2 * (1 - nu))


def clustered(start: float, stop: float, cells: int) -> np.ndarray:
    """``cells + 1`` points from ``start`` to ``stop``, cosine-clustered at both ends."""
    return start + (stop - start) * 0.5 * (1 - np.cos(np.linspace(0.0, np.pi, cells + 1)))


def strip_integral(t: np.ndarray) -> np.ndarray:
    """∫ ln|t| dt = t ln|t| − t, 0 at t = 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(t == 0, 0.0, t * np.log(np.abs(t)) - t)


def flat_punch(stick: float, friction: float, beta: float, cells: int = 200):
    """Flat punch of half-width 1 on a half-plane, unit load, stick zone |x| < ``stick``, slip F p outside.

    Piecewise-constant tractions on ``cells`` elements in each of [0, stick] and [stick, 1] (mirrored:
    p even, q odd), collocation at their midpoints, surface displacements in units of the compliance
    A = 2(1 − ν²)/E: a unit pressure on [s₁, s₂] moves the surface by u_z = −(1/π)[I(x − s₁) − I(x − s₂)]
    (into the body) and u_x = −(β/2)(|x − s₁| − |x − s₂|), a unit shear by u_x = −(1/π)[I(x − s₁) − I(x − s₂)]
    and u_z = (β/2)(|x − s₁| − |x − s₂|), I = :func:`strip_integral` (the point-load kernels of Johnson, Contact Mechanics,
    ch. 2, integrated over the strip). We write these few lines by hand: no library solves half-plane contact.

    Returns the midpoints x, pressure p, shear q and tangential displacement u_x (x ≥ 0).
    """
    edges = clustered(0.0, 1.0, cells) if stick <= 0 else np.concatenate(
        [clustered(0.0, stick, cells), clustered(stick, 1.0, cells)[1:]])
    x = 0.5 * (edges[1:] + edges[:-1])[:, None]
    s1, s2 = edges[None, :-1], edges[None, 1:]
    log_here, log_mirror = strip_integral(x - s1) - strip_integral(x - s2), strip_integral(x + s2) - strip_integral(x + s1)
    sign_here, sign_mirror = np.abs(x - s1) - np.abs(x - s2), np.abs(x + s2) - np.abs(x + s1)
    uz_p, ux_p = -(log_here + log_mirror) / np.pi, -beta / 2 * (sign_here + sign_mirror)
    ux_q, uz_q = -(log_here - log_mirror) / np.pi, beta / 2 * (sign_here - sign_mirror)
    n, sticking = len(edges) - 1, x[:, 0] < stick
    tangential = np.where(sticking[:, None], np.hstack([ux_p, ux_q]),
                          np.hstack([-friction * np.eye(n), np.eye(n)]))  # u_x = 0 or q = F p
    system = np.block([[uz_p, uz_q, -np.ones((n, 1))],           # u_z = the punch's approach
                       [tangential, np.zeros((n, 1))],
                       [2 * np.diff(edges)[None, :], np.zeros((1, n + 1))]])  # the load
    solution = np.linalg.solve(system, np.r_[np.zeros(2 * n), 1.0])
    p, q = solution[:n], solution[n:2 * n]
    return x[:, 0], p, q, ux_p @ p + ux_q @ q


def half_plane_stick_ratio(friction: float, nu: float, cells: int = 200) -> float:
    """The self-similar c/a of monotone indentation of a half-plane (the flat punch's, see the module).

    c is where the shear reaches F p continuously: the stick element next to c has q = F p (a c too
    large gives q > F p there, the square-root singularity of a stick zone that cannot hold; too small,
    q < F p). The smallest such c in [0.02, 0.995] is taken (closer to 1 the thin slip zone is not
    resolved); the stick and slip inequalities are checked at it.
    """
    if friction <= 0:
        raise ValueError(f"friction: must be positive, got {friction}; give F > 0")
    if not 0 <= nu < 0.5:
        raise ValueError(f"nu: must be in [0, 0.5), got {nu}; ν = 0.5 has no coupling (c/a = 1)")
    beta = dundurs_beta(nu)

    def excess(stick: float) -> float:
        x, p, q, _ = flat_punch(stick, friction, beta, cells)
        last = np.flatnonzero(x < stick)[-1]
        return q[last] / (friction * p[last]) - 1

    trial = np.linspace(0.02, 0.995, 40)
    values = [excess(c) for c in trial]
    change = next((k for k in range(len(trial) - 1) if values[k] < 0 <= values[k + 1]), None)
    if change is None:
        raise ArithmeticError(f"friction: no stick zone edge found for F = {friction}, ν = {nu} between c/a = "
                              f"{trial[0]} and {trial[-1]}, the range the boundary elements resolve")
    stick = brentq(excess, trial[change], trial[change + 1], xtol=1e-8)
    x, p, q, ux = flat_punch(stick, friction, beta, cells)
    inside = x < stick
    if (np.abs(q[inside]) > friction * p[inside] * (1 + 1e-3)).any() or (ux[~inside] > 0).any():
        raise ArithmeticError(f"the half-plane stick zone c/a = {stick:.4f} breaks the Coulomb law")
    return float(stick)


def indentation_scene(friction: float, step_ratio: float, width: float, h: float) -> cc.Scene:
    """The frictional punch (ν = 0.3, Q1) on a clamped block ``width`` × ``width``/2, depth × ``step_ratio``
    per step from FIRST_DEPTH to LAST_DEPTH."""
    if not step_ratio > 1:
        raise ValueError(f"step_ratio: must exceed 1, got {step_ratio}; give e.g. 1.06")
    if not width >= 0.5:
        raise ValueError(f"width: must be at least 0.5 (the fine zone is |x| < 0.15), got {width}")
    steps = math.ceil(math.log(LAST_DEPTH / FIRST_DEPTH) / math.log(step_ratio) - 1e-9) + 1
    depths = list(FIRST_DEPTH * step_ratio ** np.arange(steps))
    scene = frictional_punch(h=h, friction=friction, element="Q1")
    body = cc.Body(punch_mesh(h, width=width, depth=width / 2, quads=True), "Q1")
    history = History(times=list(range(1, steps + 1)), values={"obstacle.depth": depths})
    return dataclasses.replace(scene, body=body, history=history)


def zone_half_widths(step: cc.ContactResult) -> tuple[float, float]:
    """(c, a): half the extent of the sticking and of the closed nodes, plus half a node spacing each
    (the true edges lie between the last node in and the first node out)."""
    s, status = step.contact.coordinate, step.contact.status
    closed = np.sort(s[status != "open"])
    spacing = np.diff(closed).min()
    stick = s[status == "stick"]
    c = (np.ptp(stick) + spacing) / 2 if stick.size else 0.0
    return float(c), float((np.ptp(closed) + spacing) / 2)


def indentation(friction: float, step_ratio: float, width: float = 4.0, h: float = 0.0025) -> dict:
    """Run one history; c/a and a of every step, and their self-similar summary over the upper half
    (log scale) of the depths: mean and spread of c/a, the mean growth a_k/a_{k−1} per step."""
    scene = indentation_scene(friction, step_ratio, width, h)
    result = run(scene, "auto")
    if result.status != "solved":
        raise RuntimeError(f"the indentation history F = {friction}, × {step_ratio}: {result.message}")
    zones = np.array([zone_half_widths(step) for step in result.steps])
    depths = np.array(scene.history.values["obstacle.depth"])
    late = depths >= math.sqrt(FIRST_DEPTH * LAST_DEPTH)
    ratios = zones[:, 0] / zones[:, 1]
    return {"friction": friction, "step_ratio": step_ratio, "width": width, "h": h, "steps": len(depths),
            "final_a": zones[-1, 1], "a_growth": float(np.exp(np.diff(np.log(zones[:, 1]))[late[1:]].mean())),
            "c_over_a": float(ratios[late].mean()), "spread": float(np.ptp(ratios[late])),
            "ratios": ratios, "a": zones[:, 1], "depths": depths,
            "certificate": max(step.certificate.worst for step in result.steps)}
