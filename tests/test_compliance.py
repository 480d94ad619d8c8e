"""Normal compliance (penalty) contact: the limit c_N → ∞ and the independent Newton baseline."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.baselines.penalty import penalty_signorini
from convexcontact.scene.description import Coulomb, NormalCompliance
from convexcontact.scene.library import hertz_punch
from convexcontact.scene.toml import scene_from_dict
from convexcontact.solvers import ConeNotSupported


def punch(law, nx=24):
    """Displacement-controlled punch: the penalty baseline takes no force control."""
    return dataclasses.replace(hertz_punch(nx=nx, law=law),
                               contact=cc.Contact("top", cc.Obstacle("parabolic", radius=1.0, depth=0.01), law))


@pytest.fixture(scope="module")
def exact():
    return cc.solve(punch(cc.Signorini()))


def test_penalty_pressure_error_decays_like_one_over_c(exact):
    """Slope of log(error) against log(c_N) within 20% of −1 over three decades.

    OSQP (polished: an active-set answer) because Clarabel stops with InsufficientProgress
    for c_N ≥ 1e5 here — a stiff penalty makes P ill-conditioned (docs/friction.md).
    """
    stiffness = np.array([1e3, 1e4, 1e5, 1e6])
    errors = []
    for c in stiffness:
        result = cc.solve(punch(NormalCompliance(c)), "osqp")
        assert result.status == "solved" and result.certificate.passes(1e-8)
        errors.append(np.abs(result.contact.pressure - exact.contact.pressure).max() / exact.max_pressure)
    assert errors[-1] > 1e-7  # above the solver tolerance floor
    slope = np.polyfit(np.log(stiffness), np.log(errors), 1)[0]
    assert slope == pytest.approx(-1.0, rel=0.2)


@pytest.mark.parametrize("exponent, tol", [(1.0, 1e-10), (1.5, 2e-5)])
def test_conic_compliance_equals_the_newton_baseline(exponent, tol):
    """The conic energy (QP / power cones) and plain Newton agree at the same c_N.

    Power cones (p > 1) are solved to ~1e-6 on the compliance law only (docs/friction.md).
    """
    model = cc.prepare(punch(NormalCompliance(1e3, exponent)))
    conic = model.solve("clarabel")
    stiffness, p = model.compliance
    newton = penalty_signorini(model.fem.K, model.fem.f, model.fem.contact, stiffness, power=p)
    assert newton.converged
    pressure = newton.pressure * model.fem.scaling.pressure
    assert np.abs(conic.contact.pressure - pressure).max() < tol * conic.max_pressure
    u = model.fem.full(newton.u) * model.fem.scaling.displacement
    assert np.abs(conic.displacement - u).max() < tol * np.abs(u).max()


def test_osqp_refuses_power_cones_and_dual_refuses_compliance():
    with pytest.raises(ConeNotSupported, match="power cone"):
        cc.solve(punch(NormalCompliance(1e3, 2.0)), "osqp")
    with pytest.raises(cc.SceneError) as caught:
        cc.solve(punch(NormalCompliance(1e3)), formulation="dual")
    assert caught.value.field == "formulation"


def test_coulomb_with_compliance_tends_to_exact_coulomb():
    exact = cc.solve(punch(Coulomb(friction=0.3)))
    errors = []
    for c in (1e2, 1e3):
        result = cc.solve(punch(Coulomb(friction=0.3, compliance=NormalCompliance(c))))
        assert result.extra["picard"]["outcome"] == "converged" and result.certificate.passes(1e-8)
        errors.append(np.abs(result.contact.friction - exact.contact.friction).max() / exact.max_pressure)
    assert errors[1] < errors[0] / 5


def test_toml_keys_for_compliance():
    base = {"body": {"mesh": "rectangle"}, "material": {"E": 1.0, "nu": 0.3},
            "dirichlet": [{"boundary": "bottom", "ux": 0.0, "uy": 0.0}]}
    scene = scene_from_dict({**base, "contact": {"boundary": "top", "law": "normal_compliance", "stiffness": 1e4}})
    assert scene.contact.law == NormalCompliance(1e4)
    scene = scene_from_dict({**base, "contact": {"boundary": "top", "law": "coulomb", "friction": 0.3,
                                                 "stiffness": 1e4, "exponent": 2.0}})
    assert scene.contact.law.compliance == NormalCompliance(1e4, 2.0)
    with pytest.raises(cc.SceneError) as caught:
        scene_from_dict({**base, "contact": {"boundary": "top", "law": "normal_compliance", "stiffness": -1.0}})
    assert caught.value.field == "contact.stiffness"
