"""Issue 27, 3-D friction and normal compliance on plastic bodies by Newton's method (drivers/plastic_polish.py: the
slipping points' discs by their dissipation s‖w‖, the sticking ones as rows; compliance's energy). Before, these steps rested on the interior point alone, which left
equilibrium at 1e-6 on the stacked blocks' first flowing step (Tresca: `inaccurate`; Coulomb: the map not converged);
now each is certified to 1e-8 and equals the conic program's answer at a tight tolerance."""

import numpy as np
import pytest
from test_plasticity_bodies import stacked

import convexcontact as cc
from convexcontact.drivers import plastic_polish
from convexcontact.studies.benchmarks import plastic_bench

DEPTHS = [0.0018, 0.006, 0.012]  # elastic (0.9 × first yield), then flowing: the plastic block widens over the elastic
BOUND, FRICTION = 4e-4, 0.2  # a fifth of the yield stress, which the interface pressure reaches


def conic_only(scene, monkeypatch, **options):
    """``scene``'s history with every step by the conic program alone (no Newton, neither fast path nor finish)."""
    with monkeypatch.context() as patch:
        patch.setattr(plastic_polish, "applies", lambda model: False)
        return cc.run_history(scene, **options)


def test_a_3d_tresca_step_on_a_plastic_block_is_certified_and_is_the_conic_answer(monkeypatch):
    """Tresca discs between the 3-D stacked blocks: the flowing steps (points slipping and sticking) by Newton,
    certified to 1e-8 (the interior point alone at its default tolerance: 1.1e-6, `inaccurate`); the conic program at tol 1e-10
    (Solved, equilibrium 1.1e-8 and 5.8e-8; with the symmetry planes' friction rows emptied 2.5e-8 and 3.6e-7, where
    Newton's steps are certified to 6e-13 and 6e-16 either way) gives the same displacements and friction tractions
    to its own accuracy: within 10 × its certificate (at least 1e-7; measured 8.7e-8 and 6.8e-7 of the displacement)."""
    scene = stacked(DEPTHS, dim=3, law=cc.Tresca(slip_bound=BOUND))
    fast = cc.run_history(scene)
    assert fast.status == "solved" and max(step.certificate.worst for step in fast.steps) < 1e-8
    assert [step.extra["path"] for step in fast.steps[1:]] == ["newton", "newton"]
    for step in fast.steps[1:]:
        assert step.max_equivalent_plastic_strain > 0
        status = step.contact.status.astype(str)
        assert np.char.startswith(status, "slip").any() and (status == "stick").any()
    conic = conic_only(scene, monkeypatch, tol=1e-10)
    scale = np.abs(conic.steps[-1].displacement).max()
    traction = np.abs(conic.steps[-1].contact.friction).max()
    def accuracy(step):
        return max(1e-7, 10 * step.certificate.worst)

    for a, b in zip(fast.steps, conic.steps, strict=True):
        assert b.extra["path"] == "conic" and b.status == "solved"
        assert np.abs(a.displacement - b.displacement).max() < accuracy(b) * scale
    for a, b in zip(fast.steps[1:], conic.steps[1:]):  # the slipping points' tractions are compared (a sticking one's
        # was not unique on the corner node, whose tangential rows repeated both rollers' conditions before the
        # symmetry planes' rows were emptied)
        slipping = np.char.startswith(b.contact.status.astype(str), "slip")
        assert np.array_equal(slipping, np.char.startswith(a.contact.status.astype(str), "slip"))
        assert np.abs(a.contact.friction - b.contact.friction)[slipping].max() < accuracy(b) * traction


@pytest.mark.parametrize("depths", [DEPTHS, [0.012]])
def test_a_3d_coulomb_step_on_a_plastic_block_is_certified(depths):
    """Coulomb (F = 0.2) between the 3-D stacked blocks, the Picard map over plastic Tresca steps: every step certified
    to 1e-8, the flowing steps' inner steps by Newton. Before, the second step of ``DEPTHS`` stopped `not converged`
    (best Coulomb residual 1.9e-6) and the one-step history was certified only at 4e-8."""
    result = cc.run_history(stacked(depths, dim=3, law=cc.Coulomb(friction=FRICTION)))
    assert result.status == "solved" and max(step.certificate.worst for step in result.steps) < 1e-8
    last = result.steps[-1]
    assert last.max_equivalent_plastic_strain > 0 and np.char.startswith(last.contact.status.astype(str), "slip").any()
    assert all(entry["path"] == "newton" for entry in last.extra["history"][1:])


def test_normal_compliance_on_a_plastic_punch_is_certified_by_newton(monkeypatch):
    """Normal compliance (c_N = 100 E/L, p = 1) under Prandtl's punch (nx = 8, the bench's ten steps to the limit
    load), and the 3-D stacked blocks with a compliant interface: every step by Newton (compliance's energy in Φ),
    certified to 1e-10, where the interior point alone left 5e-10 to 6e-8 on the punch (1e-7 to 4e-7 on the blocks);
    the conic program's answers agree to its own accuracy: within 10 × the largest certificate of its steps so far,
    relative to the displacement (a history carries each step's error on; measured 0.09–2.7 ×, the interior point's
    stopping point moving with the mortar integrals' rounding: the blocks' last step 1.1e-6 or 2.6e-7 of the
    displacement, its certificate 4.2e-7 or 1.0e-7)."""
    for scene in (plastic_bench.punch_scene(256, "signorini").with_law(cc.NormalCompliance(100.0)),
                  stacked(DEPTHS, dim=3, law=cc.NormalCompliance(1.0))):
        fast, conic = cc.run_history(scene), conic_only(scene, monkeypatch)
        assert fast.status == "solved" and all(step.extra["path"] == "newton" for step in fast.steps)
        assert max(step.certificate.worst for step in fast.steps) < 1e-10
        assert max(step.certificate.worst for step in conic.steps) > 1e-8
        assert fast.steps[-1].max_equivalent_plastic_strain > 0
        scale = np.abs(conic.steps[-1].displacement).max()
        accuracy = np.maximum.accumulate([step.certificate.worst for step in conic.steps])
        for a, b, bound in zip(fast.steps, conic.steps, accuracy, strict=True):
            assert np.abs(a.displacement - b.displacement).max() < 10 * bound * scale
