"""Mindlin–Deresiewicz: press with P, pull to Q* < F P, pull back to Q — a load history (issue 11, case 5).

Loading: the stick zone is c/a = sqrt(1 − Q*/(F P)) (Cattaneo–Mindlin). Unloading to Q reverses the
slip in an annulus c′ < |x| < a, c′/a = sqrt(1 − (Q* − Q)/(2 F P)), while the points inside keep their
position: friction acts on the slip increment of each step, so this comes out of the law. β = 0 needs
ν → ½ (the Cattaneo–Mindlin example's Q2 block on rollers), solved as that example (auto: the dual).

    python examples/cattaneo_mindlin_cycle.py [--h 0.01] [--peak 0.75] [--back 0.25] [--out out/cycle]
"""

import argparse
import dataclasses
import importlib.util
from pathlib import Path

import numpy as np

import convexcontact as cc
from convexcontact.scene.library import HERTZ_FORCE

FRICTION = 0.6


def static_scene(h: float) -> cc.Scene:
    """The Cattaneo–Mindlin scene of ``cattaneo_mindlin.py`` (loaded from beside this file)."""
    spec = importlib.util.spec_from_file_location("cattaneo_mindlin", Path(__file__).with_name("cattaneo_mindlin.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.scene(h, 0.0, FRICTION)


def ratio(step, state: str) -> float:
    """Half-extent of the nodes in ``state`` over the contact half-width a."""
    s, status = step.contact.coordinate, step.contact.status
    inside = status == state
    return float(np.ptp(s[inside]) / np.ptp(s[status != "open"])) if inside.any() else 0.0


def main(h: float = 0.01, peak: float = 0.75, back: float = 0.25, out: str = "out/cycle"):
    loads = [0.0, peak, back]  # Q / (F P) at each step: press, pull, pull back
    history = cc.History(times=[1.0, 2.0, 3.0],
                         values={"obstacle.tangential_force": [q * FRICTION * HERTZ_FORCE for q in loads]})
    result = cc.run_history(dataclasses.replace(static_scene(h), history=history), "auto")
    loading, unloading = result.steps[1], result.steps[2]
    measured = {"stick on loading": ratio(loading, "stick"), "stick on unloading": ratio(unloading, "stick")}
    theory = {"stick on loading": np.sqrt(1 - peak), "stick on unloading": np.sqrt(1 - (peak - back) / 2)}
    for name, value in measured.items():
        print(f"{name}: c/a = {value:.3f}, theory {theory[name]:.3f}")
    print(f"status {result.status}; certificates ≤ {max(s.certificate.worst for s in result.steps):.1e}")
    result.save(out)
    return result, measured, theory


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=float, default=0.01)
    parser.add_argument("--peak", type=float, default=0.75)
    parser.add_argument("--back", type=float, default=0.25)
    parser.add_argument("--out", default="out/cycle")
    main(**vars(parser.parse_args()))
