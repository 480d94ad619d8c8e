"""Near-incompressible bodies (ν → ½): the condensed dual's Picard steps stay certified.

There W = B K⁻¹ Bᵀ has eigenvalues ∝ 1 − 2ν (condition 1e9 at ν = 0.499 on the Cattaneo–Mindlin scene) and Clarabel
stops AlmostSolved with multipliers up to 1e5 where a ball's radius is 0; the active-set polish must judge the signs
of its own answer on that answer's scale, not the interior point's.
"""

import numpy as np
import scipy.sparse as sp

from convexcontact.conic import ConicProgram, ConicSolution, nonnegative
from convexcontact.solvers.polish import polish


def test_polish_refuses_a_wrong_sign_hidden_by_a_wild_interior_point_multiplier():
    """min ½|x|² + x₁ − x₂ over x ≥ 0 has x = (0, 1). An iterate guessing both bounds active, with a multiplier of
    1e11 on the second, gives the KKT point x = 0 whose second multiplier is −1: a wrong sign, not noise."""
    program = ConicProgram(sp.identity(2, format="csc"), np.array([1.0, -1.0]), -sp.identity(2, format="csc"),
                           np.zeros(2), (nonnegative(2),))
    guess = ConicSolution(x=np.zeros(2), z=np.array([1.0, 1e11]), s=np.zeros(2), status="inaccurate",
                          solver_status="AlmostSolved", iterations=40, solve_time=0.0, solver="clarabel")
    polished = polish(program, guess)
    assert polished.info.get("polished")
    np.testing.assert_allclose(polished.x, [0.0, 1.0], atol=1e-14)
    np.testing.assert_allclose(polished.z, [1.0, 0.0], atol=1e-14)
