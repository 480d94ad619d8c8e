"""Spence's monotone indentation (issue 24): the half-plane's self-similar stick ratio and the load step's cap."""

import numpy as np
import pytest

from convexcontact.studies.verification.spence import dundurs_beta, flat_punch, half_plane_stick_ratio, indentation

HALF_PLANE = {0.2: 0.3604, 0.4: 0.8645, 0.6: 0.9732}
"""The self-similar c/a at ν = 0.3 (200 cells a side), checked below."""


def test_the_half_plane_flat_punch_without_friction_is_sadowskys():
    """Boundary elements of the half-plane against the closed form: p = P / (π sqrt(a² − x²)) and, from
    u_x′ = −β A p, u_x = −β A (P/π) arcsin(x/a) (A = 1, P = 1, a = 1)."""
    beta = dundurs_beta(0.3)
    x, p, q, ux = flat_punch(0.0, 0.0, beta, cells=100)
    inner = x < 0.9
    np.testing.assert_allclose(p[inner], 1 / (np.pi * np.sqrt(1 - x[inner] ** 2)), rtol=1e-3)
    assert not q.any()
    np.testing.assert_allclose(ux, -beta * np.arcsin(x) / np.pi, atol=2e-3 * beta)  # the edge cells of the singular p: 1.5e-3


def test_the_half_plane_stick_ratio_grows_with_friction_and_with_nu():
    """c/a at ν = 0.3 for F = 0.2 / 0.4 / 0.6 with 50 cells a side is the 200 cells' to 1e-3; more friction or
    less coupling β holds more of the contact."""
    ratios = [half_plane_stick_ratio(friction, 0.3, cells=50) for friction in HALF_PLANE]
    np.testing.assert_allclose(ratios, list(HALF_PLANE.values()), atol=1e-3)
    assert half_plane_stick_ratio(0.2, 0.45, cells=50) > ratios[0] + 0.3


def test_coarse_steps_cap_the_stick_zone_at_the_last_contact_zone():
    """Depth × 1.25 per step (a × 1.13): the annulus that closes in a step slips in it, so every step's stick
    zone lies inside the previous step's contact zone (within a node: the edge node, whose pressure goes to 0,
    may count as open a step before it closes), and F = 0.6 sticks on less than the half-plane's 0.973."""
    h = 0.0025
    run = indentation(0.6, 1.25, width=4.0, h=h)
    c = run["ratios"] * run["a"]
    assert (c[1:] <= run["a"][:-1] + h * 1.001).all()
    assert (c[1:] >= run["a"][:-1] - h * 0.999).all()  # and fills it: the cap holds c/a here
    assert run["c_over_a"] < HALF_PLANE[0.6] - 0.05


def test_fine_steps_on_a_wide_block_reach_the_half_plane_stick_ratio():
    """F = 0.4, depth × 1.06 per step on a block 110 a wide: c/a within 0.02 (a node spacing is 0.03 a) of the
    half-plane's self-similar value, and steady over the last half of the depths."""
    run = indentation(0.4, 1.06, width=10.0, h=0.0025)
    assert run["c_over_a"] == pytest.approx(HALF_PLANE[0.4], abs=0.02)
    assert run["certificate"] < 1e-8
