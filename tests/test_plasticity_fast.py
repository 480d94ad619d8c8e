"""Issue 27's fast path for plastic steps: Newton from the last step's answer on the reduced step energy, the conic
program only as its fallback (drivers/plastic_polish.py, docs/plasticity.md). It gives the conic path's answer to the
certificate's accuracy on a punch whose plastic zone grows; the fallback is taken where Newton alone fails; the
bench's plastic case reports both paths and the return-mapping baseline on the same mesh."""

import numpy as np
import pytest
from test_plasticity import confined_block

import convexcontact as cc
from convexcontact.drivers import plastic_history, plastic_polish
from convexcontact.studies.benchmarks import plastic_bench


def history(scene, fast: bool):
    """``scene``'s history with every step by the fast path (``fast``) or by the conic program."""
    original = plastic_history.PlasticStepper.__init__.__defaults__
    plastic_history.PlasticStepper.__init__.__defaults__ = (fast,)
    try:
        return cc.run_history(scene)
    finally:
        plastic_history.PlasticStepper.__init__.__defaults__ = original


@pytest.mark.parametrize("law", [cc.Signorini(), cc.Tresca(slip_bound=plastic_bench.YIELD_STRESS)])
def test_the_fast_path_gives_the_conic_answer_while_the_plastic_zone_grows(law):
    """Prandtl's punch (nx = 8, the bench's ten steps to the limit load, smooth and rough): every step by Newton alone,
    certified to 1e-10 (material and contact), equal to the conic path's displacements and pressures to 1e-9; the
    plastic zone grows from step to step (more points flow, ε̄_p rises)."""
    scene = plastic_bench.punch_scene(256, "signorini").with_law(law)
    fast, conic = history(scene, True), history(scene, False)
    assert fast.status == conic.status == "solved"
    assert [step.extra["path"] for step in fast.steps] == ["newton"] * len(scene.history)
    assert all(step.extra["path"] == "conic" for step in conic.steps)
    assert max(step.certificate.worst for step in fast.steps + conic.steps) < 1e-10
    scale = np.abs(conic.steps[-1].displacement).max()
    pressure = np.abs(conic.steps[-1].contact.pressure).max()
    for a, b in zip(fast.steps, conic.steps, strict=True):
        assert np.abs(a.displacement - b.displacement).max() < 1e-9 * scale
        assert np.abs(a.contact.pressure - b.contact.pressure).max() < 1e-9 * pressure
    flowing = [int((np.linalg.norm(s.plastic.increment.reshape(-1, s.plastic.points.components), axis=1) > 0).sum())
               for s in fast.steps]
    assert flowing[-1] > flowing[2] > 0
    assert np.all(np.diff(fast.series()["max_equivalent_plastic_strain"]) > 0)


def test_the_conic_program_is_the_fallback_where_newton_alone_fails():
    """The creeping block rests on its foundation alone (rollers on its sides, a pressure on top): at the first step,
    from rest, no contact row is closed, the tangent without them is singular, and Newton finds no descent — the step
    is the conic program's (the reason kept in ``extra["fallback"]``); from its answer on, Newton alone. Every step is
    certified and the top sinks as the closed form of test_plasticity's creep test (there to 1e-9)."""
    result = cc.run_history(confined_block("P1", 0.4 * np.arange(1, 4), eta=0.5, creep=True))
    assert result.status == "solved"
    first, *rest = result.steps
    assert first.extra["path"] == "conic"
    assert first.extra["fallback"].startswith("the line search on the step energy found no decrease")
    assert 0 < first.extra["fallback_newton_steps"] <= plastic_polish.STEPS
    assert all(step.extra["path"] == "newton" and "fallback" not in step.extra for step in rest)
    assert max(step.certificate.worst for step in result.steps) < 1e-10


def test_the_bench_reports_both_paths_and_the_baseline_on_one_mesh():
    """``convexcontact bench --scenario plastic``'s case at its smallest mesh: the fast path by Newton, both paths
    certified and equal to 1e-9, the return-mapping baseline within its penalty's error (1e-3 of max |u| at c = 1e5,
    measured 1.4e-5), the ratios those of the times."""
    row = plastic_bench.measure("signorini", 256)
    assert row["fast_path"] == "newton" and row["fallback"] == ""
    assert row["conic_status"] == row["fast_status"] == "solved"
    assert max(row["conic_certificate"], row["fast_certificate"]) < 1e-10
    assert row["fast_conic_difference"] < 1e-9
    assert 1e-9 < row["return_mapping_difference"] < 1e-3
    for path in ("conic", "fast", "return_mapping"):
        assert row[f"{path}_ratio"] == pytest.approx(row[path] / row["linear"])
