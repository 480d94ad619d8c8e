"""Penalty / regularized Newton baselines against the exact Signorini solve and the closed-form rates.

Displacement-controlled Hertz scene (coarse: 5 closed nodes), everything in scaled units.
"""

import dataclasses
import itertools

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.baselines import penalty_coulomb, penalty_signorini, regularized_tresca
from convexcontact.scene.library import hertz_punch

PENALTY = 1e4  # scaled: 1e4 × E / L


@pytest.fixture(scope="module")
def hertz():
    """FE model and exact (Clarabel) scaled pressure of a punch pressed in by depth 0.02."""
    scene = dataclasses.replace(
        hertz_punch(nx=24), contact=cc.Contact("top", cc.Obstacle("parabolic", radius=1.0, depth=0.02))
    )
    exact = cc.prepare(scene).solve("clarabel")
    assert exact.status == "solved"
    return exact.fem, exact.contact.pressure / exact.fem.scaling.pressure


@pytest.fixture(scope="module")
def slip_bound(hertz):
    """Tresca bound s = 0.5 λ_N of the penalty Signorini answer (Oden's algorithm III, first step)."""
    fem, _ = hertz
    return 0.5 * penalty_signorini(fem.K, fem.f, fem.contact, PENALTY).pressure


def loglog_slope(penalties, errors) -> float:
    return float(np.polyfit(np.log(penalties), np.log(errors), 1)[0])


@pytest.mark.parametrize("power, penalties", [(1, [1e2, 1e3, 1e4, 1e5]), (2, [1e3, 1e4, 1e5, 1e6])])
def test_penalty_pressure_error_like_c_to_minus_one_over_p(hertz, power, penalties):
    """Case 6: the normal compliance pressure tends to the exact Signorini pressure like c^(−1/p)."""
    fem, exact = hertz
    errors = []
    for c in penalties:
        result = penalty_signorini(fem.K, fem.f, fem.contact, c, power=power)
        assert result.converged
        if power == 1:
            assert result.iterations <= 4  # semismooth Newton: the active set settles at once here
        errors.append(np.abs(result.pressure - exact).max() / exact.max())
    assert min(errors) > 1e-6  # far above the exact solve's accuracy
    assert loglog_slope(penalties, errors) == pytest.approx(-1.0 / power, rel=0.2)


def test_zero_slip_bound_is_penalty_signorini(hertz):
    fem, _ = hertz
    signorini = penalty_signorini(fem.K, fem.f, fem.contact, PENALTY)
    tresca = regularized_tresca(fem.K, fem.f, fem.contact, 0.0, 1e-3, PENALTY)
    assert tresca.converged and tresca.iterations == signorini.iterations
    np.testing.assert_allclose(tresca.u, signorini.u, rtol=0, atol=1e-14 * np.abs(signorini.u).max())
    np.testing.assert_allclose(tresca.pressure, signorini.pressure, rtol=1e-14)
    assert not tresca.friction.any()


def test_regularized_tresca_bound_signs_and_monotone_energy(hertz, slip_bound):
    """|λ_T| ≤ s; λ_T = −s u_T/|u_T| where |u_T| ≫ ε; equilibrium Ku − f + NᵀWλ_N − TᵀWλ_T = 0; E decreases."""
    fem, _ = hertz
    contact, epsilon = fem.contact, 1e-6
    result = regularized_tresca(fem.K, fem.f, contact, slip_bound, epsilon, PENALTY)
    assert result.converged

    assert np.all(np.abs(result.friction) <= slip_bound)
    slip = contact.T @ result.u + contact.tangent_offset
    slipping = np.abs(slip) > 1e3 * epsilon
    stuck = (slip_bound > 0) & ~slipping
    assert slipping[slip_bound > 0].any() and stuck.any()  # a stick zone and slip zones
    np.testing.assert_allclose(result.friction[slipping], -slip_bound[slipping] * np.sign(slip[slipping]), rtol=1e-3)
    assert np.all(np.abs(result.friction[stuck]) < slip_bound[stuck])

    w = contact.weights
    equilibrium = fem.K @ result.u - fem.f + contact.N.T @ (w * result.pressure) - contact.T.T @ (w * result.friction)
    assert np.abs(equilibrium).max() <= 1e-9 * np.abs(contact.N.T @ (w * result.pressure)).max()

    energy = result.history["energy"]
    assert energy.size == result.iterations + 1 >= 3
    assert np.all(np.diff(energy) <= 1e-12 * np.abs(energy[:-1]))
    assert energy[-1] < energy[0]


def test_regularized_tresca_converges_like_epsilon(hertz, slip_bound):
    """Case 6: the ε-regularized answer moves by O(ε): each decade of ε shrinks the change tenfold."""
    fem, _ = hertz
    answers = [regularized_tresca(fem.K, fem.f, fem.contact, slip_bound, eps, PENALTY).u for eps in (1e-3, 1e-4, 1e-5)]
    changes = [np.abs(b - a).max() for a, b in itertools.pairwise(answers)]
    assert changes[0] / changes[1] == pytest.approx(10.0, rel=0.2)


def test_backtracking_keeps_plain_newton_monotone_from_a_slipping_start(hertz, slip_bound):
    """From the frictionless (slipping) answer the exact Hessian overshoots the kink: the line search must act."""
    fem, _ = hertz
    start = penalty_signorini(fem.K, fem.f, fem.contact, PENALTY).u
    plain = regularized_tresca(fem.K, fem.f, fem.contact, slip_bound, 1e-4, PENALTY, u0=start, primal_dual=False)
    assert plain.converged
    assert plain.history["step_length"].min() < 0.1
    energy = plain.history["energy"]
    assert np.all(np.diff(energy) <= 1e-12 * np.abs(energy[:-1]))

    primal_dual = regularized_tresca(fem.K, fem.f, fem.contact, slip_bound, 1e-4, PENALTY, u0=start)
    assert primal_dual.converged and primal_dual.iterations < plain.iterations / 2
    np.testing.assert_allclose(primal_dual.u, plain.u, rtol=0, atol=1e-9 * np.abs(plain.u).max())


def test_answer_does_not_depend_on_dof_numbering(hertz, slip_bound):
    fem, _ = hertz
    contact = fem.contact
    order = np.random.default_rng(1).permutation(fem.n_free)
    relabeled = dataclasses.replace(contact, N=contact.N[:, order], T=contact.T[:, order])
    reference = regularized_tresca(fem.K, fem.f, contact, slip_bound, 1e-4, PENALTY)
    permuted = regularized_tresca(fem.K[order][:, order], fem.f[order], relabeled, slip_bound, 1e-4, PENALTY)
    assert permuted.converged
    np.testing.assert_allclose(permuted.u, reference.u[order], rtol=0, atol=1e-10 * np.abs(reference.u).max())
    np.testing.assert_allclose(permuted.friction, reference.friction, rtol=0, atol=1e-8 * slip_bound.max())


def test_coulomb_fixed_point(hertz):
    """s = F λ_N at convergence, so |λ_T| ≤ F λ_N; F = 0 is the frictionless penalty answer."""
    fem, _ = hertz
    friction, tol = 0.5, 1e-8
    result = penalty_coulomb(fem.K, fem.f, fem.contact, friction, 1e-4, PENALTY, tol=tol)
    assert result.converged
    changes = result.history["slip_bound_change"]
    assert changes.size == result.iterations and changes[-1] <= tol < changes[0]
    assert np.all(np.abs(result.friction) <= friction * result.pressure * (1 + 10 * tol) + 1e-12)

    frictionless = penalty_coulomb(fem.K, fem.f, fem.contact, 0.0, 1e-4, PENALTY)
    signorini = penalty_signorini(fem.K, fem.f, fem.contact, PENALTY)
    assert frictionless.converged and frictionless.iterations == 1
    np.testing.assert_allclose(frictionless.pressure, signorini.pressure, rtol=1e-12)


def test_non_convergence_is_reported(hertz, slip_bound):
    fem, _ = hertz
    result = regularized_tresca(fem.K, fem.f, fem.contact, slip_bound, 1e-6, PENALTY, max_iter=1)
    assert not result.converged and result.iterations == 1
    assert result.history["residual"][-1] > 1e-10
    assert not penalty_signorini(fem.K, fem.f, fem.contact, PENALTY, power=2, max_iter=1).converged


def test_force_control_is_refused():
    fem = cc.prepare(hertz_punch(nx=8)).fem
    with pytest.raises(ValueError, match="displacement control"):
        penalty_signorini(fem.K, fem.f, fem.contact, PENALTY)
