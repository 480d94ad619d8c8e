"""Near-incompressible bodies (ν → ½): the condensed dual's Picard steps stay certified.

There W = B K⁻¹ Bᵀ has eigenvalues ∝ 1 − 2ν (condition 1e9 at ν = 0.499 on the Cattaneo–Mindlin scene) and Clarabel
stops AlmostSolved with multipliers up to 1e5 where a ball's radius is 0; the active-set polish must judge the signs
of its own answer on that answer's scale, not the interior point's, and a slip's sign on the slips' scale, not on the far
open nodes' gaps.
"""

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import convexcontact as cc
from convexcontact.conic import ConicProgram, ConicSolution, nonnegative, soc
from convexcontact.solvers.polish import polish


def test_polish_refuses_a_wrong_sign_hidden_by_a_wild_interior_point_multiplier():
    """min ½|x|² + x₁ − x₂ over x ≥ 0 has x = (0, 1). An iterate guessing both bounds active, with a multiplier of
    1e11 on the second, gives the KKT point x = 0 whose second multiplier is −1: a wrong sign, not noise."""
    program = ConicProgram(sp.identity(2, format="csc"), np.array([1.0, -1.0]), -sp.identity(2, format="csc"),
                           np.zeros(2), (nonnegative(2),))
    polished = polish(program, iterate([0.0, 0.0], [1.0, 1e11], [0.0, 0.0]))
    assert polished.info.get("polished")
    np.testing.assert_allclose(polished.x, [0.0, 1.0], atol=1e-14)
    np.testing.assert_allclose(polished.z, [1.0, 0.0], atol=1e-14)


def iterate(x, z, s) -> ConicSolution:
    """An AlmostSolved interior-point answer to polish."""
    return ConicSolution(x=np.array(x), z=np.array(z), s=np.array(s), status="inaccurate", solver_status="AlmostSolved",
                         iterations=40, solve_time=0.0, solver="clarabel")


def test_polish_judges_a_slip_on_the_slips_scale_not_on_a_far_gap():
    """A dual's shape: a gap multiplier g ≥ 0 of 1e4 (an open node far away) and a tangential force |t| ≤ 1 whose
    optimum t = 1 − 1e-8 sticks. Guessing t = 1 (slipping) gives a slip of −1e-8 against the force: judged beside
    the gap's 1e4 it passed as noise; beside the slips it is a wrong sign and the polish reaches the stick."""
    A = sp.csc_matrix(np.array([[-1.0, 0.0], [0.0, 0.0], [0.0, -1.0]]))
    program = ConicProgram(sp.identity(2, format="csc"), np.array([1e4, -(1 - 1e-8)]), A, np.array([0.0, 1.0, 0.0]),
                           (nonnegative(1), soc(2)))
    polished = polish(program, iterate([0.0, 1.0], [1e4, 1.0, -1.0], [0.0, 1.0, 1.0]))
    assert polished.info.get("polished")
    assert polished.x[1] == pytest.approx(1 - 1e-8, abs=1e-14)
    np.testing.assert_allclose(polished.z, [1e4, 0.0, 0.0], atol=1e-12)


def cattaneo_mindlin_scene() -> cc.Scene:
    """examples/cattaneo_mindlin.py's scene at h = 0.01, Q = ½ F P."""
    path = Path(__file__).resolve().parent.parent / "examples" / "cattaneo_mindlin.py"
    spec = importlib.util.spec_from_file_location("cattaneo_mindlin", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.scene(0.01, 0.5)


@pytest.mark.parametrize("nu", [0.499, 0.4999])
def test_dual_coulomb_on_the_cattaneo_mindlin_scene_is_certified(nu):
    """The example's scene (Q2 block on rollers, F = 0.6, Q = ½ F P) below its ν = 0.49999: every Picard step's Tresca
    program polished, the map certified (before: inner solves at 3e-3 and 1e-5, not converged), the stick zone within
    5 % of Cattaneo–Mindlin's c/a = sqrt(½) (β ∝ 1 − 2ν is small but not 0 here)."""
    base = cattaneo_mindlin_scene()
    result = cc.solve(dataclasses.replace(base, materials=dataclasses.replace(base.materials, nu=nu)),
                      formulation="dual")
    assert result.status == "solved" and result.extra["picard"]["outcome"] == "converged"
    assert result.certificate.passes(1e-6)
    s, status = result.contact.coordinate, result.contact.status
    assert np.ptp(s[status == "stick"]) / np.ptp(s[status != "open"]) == pytest.approx(np.sqrt(0.5), rel=0.05)
