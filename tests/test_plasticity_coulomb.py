"""Issue 27, Coulomb friction on elasto-viscoplastic bodies: within each step the Picard map over the step's normal
pressures (drivers/picard.py), each inner problem the exact plastic Tresca step (drivers/plastic_coulomb.py). Checked
against today's elastic Coulomb history, against an independent plastic Tresca step at the answer's own slip bound
(the fixed point), against the Signorini answer at μ = 0, against the fully sticking (rough) punch at large μ, and the
certificate against a wrong answer."""

import dataclasses

import numpy as np
import pytest
from test_plasticity import example
from test_plasticity_fast import history

import convexcontact as cc
from convexcontact.drivers import plastic_history
from convexcontact.drivers.picard import pressure_map
from convexcontact.drivers.plastic_coulomb import PlasticTresca

E, NU, FRICTION = 1.0, 0.3, 0.3
PUNCH = example("plastic_punch")


def sliding_block(material: cc.Material) -> cc.Scene:
    """A block pressed onto a Coulomb foundation by its top, then its top moved sideways in three steps: the corners
    slip outwards, then more points slip sideways until all do, the slip carried from step to step."""
    shifts = [0.0, 0.002, 0.004, 0.03]
    return cc.Scene(
        name="sliding block", body=cc.Body(cc.Rectangle(1.0, 0.5, 6, 3), "Q1"), materials=material,
        dirichlet=(cc.Dirichlet("top", ux=0.0, uy=-0.01),),
        contact=cc.Contact("bottom", cc.Obstacle("flat"), cc.Coulomb(friction=FRICTION)),
        history=cc.History([1.0, 2.0, 3.0, 4.0], {"dirichlet[top].ux": shifts, "dirichlet[top].uy": [-0.01] * 4}))


def punch(law, multiples=(2, 8, 32)) -> cc.Scene:
    """Prandtl's punch (nx = 8) pushed to ``multiples`` of the elastic limit depth, under ``law``."""
    return PUNCH.flat_punch(8, [m * PUNCH.PRANDTL / E for m in multiples]).with_law(law)


def test_without_yield_each_step_is_the_elastic_coulomb_history():
    """σ_Y far above every stress: step by step the plastic Coulomb history is today's elastic one (a Picard map over
    elastic Tresca programs), to the maps' tolerance; nothing flows, and the block sticks, then slips."""
    elastic = sliding_block(cc.Material(E, NU))
    plastic = cc.run_history(dataclasses.replace(elastic, materials=cc.Material(E, NU, yield_stress=1e3)))
    elastic = cc.run_history(elastic)
    assert plastic.status == elastic.status == "solved"
    series = plastic.series()
    assert series["n_slip"][-1] == series["n_closed"][-1] > series["n_slip"][1]  # at last every point slips:
    assert abs(plastic.steps[-1].tangential_force) == pytest.approx(FRICTION * plastic.steps[-1].normal_force)  # T = FN
    for a, b in zip(plastic.steps, elastic.steps, strict=True):
        assert np.abs(a.displacement - b.displacement).max() < 1e-7 * np.abs(b.displacement).max()
        assert np.abs(a.contact.forces - b.contact.forces).max() < 1e-7 * np.abs(b.contact.forces).max()
        assert a.max_equivalent_plastic_strain == 0.0
        assert a.extra["picard"]["outcome"] == "converged"


def test_the_answer_is_the_plastic_tresca_step_at_its_own_slip_bound():
    """The fixed point: one step of the punch to 8× the elastic limit depth (flowing, some points slipping) under
    Coulomb equals an independent plastic Tresca step, by the conic program, whose slip bound is F λ_N taken from the
    Coulomb answer."""
    coulomb = cc.run_history(punch(cc.Coulomb(friction=0.2), (8,))).steps[0]
    assert coulomb.status == "solved" and coulomb.max_equivalent_plastic_strain > 0
    assert np.char.startswith(coulomb.contact.status.astype(str), "slip").any()
    bound = 0.2 * coulomb.contact.pressure
    tresca = history(punch(cc.Tresca(slip_bound=bound), (8,)), fast=False).steps[0]
    assert tresca.status == "solved" and tresca.extra["path"] == "conic"
    scale = np.abs(coulomb.displacement).max()
    assert np.abs(tresca.displacement - coulomb.displacement).max() < 1e-7 * scale
    assert np.abs(tresca.contact.forces - coulomb.contact.forces).max() < 1e-7 * np.abs(coulomb.contact.forces).max()


def test_without_friction_it_is_the_signorini_answer():
    """F = 0: every slip bound is 0, the map's first inner step is its fixed point, and it is the plastic Signorini
    history's answer."""
    coulomb = cc.run_history(punch(cc.Coulomb(friction=0.0)))
    signorini = cc.run_history(punch(cc.Signorini()))
    assert coulomb.status == signorini.status == "solved"
    for a, b in zip(coulomb.steps, signorini.steps, strict=True):
        assert a.extra["picard"]["iterations"] == 1
        assert np.abs(a.displacement - b.displacement).max() < 1e-10 * np.abs(b.displacement).max()
        assert abs(a.normal_force - b.normal_force) < 1e-10 * b.normal_force


def test_large_friction_approaches_the_rough_punch():
    """The punch's force grows with F from the smooth punch's to the rough one's (Tresca with a bound no traction
    reaches: every point sticks), which large F reaches exactly (every point sticks under Coulomb too)."""
    forces = [np.array(cc.run_history(punch(law)).series()["normal_force"]) for law in (
        cc.Signorini(), cc.Coulomb(friction=0.2), cc.Coulomb(friction=10.0), cc.Tresca(slip_bound=1e3 * E))]
    smooth, some, large, rough = forces
    assert (smooth < some).all() and (some < large).all()
    np.testing.assert_allclose(large, rough, rtol=1e-9)


def test_the_coulomb_residual_catches_a_wrong_slip_bound():
    """The certificate's Coulomb residual (s = F λ_N at the answer, not the inner Tresca one's): a plastic Tresca step
    solved with F λ_N(1 + δ) of the answer passes its own Tresca certificate, but against the Coulomb law its residual
    grows as δ, while the answer's stays at the map's tolerance."""
    scene = punch(cc.Coulomb(friction=0.2), (8,))
    process, stepper = plastic_history.build(scene, "auto", "clarabel", {}, {})
    model = process.step_model(0, {})
    answer = stepper.solve(model, process.key, {})
    assert answer.status == "solved" and answer.certificate.worst < 1e-8
    bound = pressure_map(model)[0]
    exact = bound(answer.contact.pressure / model.fem.scaling.pressure)
    residuals = []
    for delta in (1e-2, 1e-4):
        inner = PlasticTresca(stepper, model, {})
        inner.solve(exact * (1 + delta))
        assert inner.residual(model, inner.fields, exact * (1 + delta)) < 1e-10  # its own Tresca step: exact
        residuals.append(inner.residual(model, inner.fields, bound(inner.fields.pressure)))
    assert residuals[0] > 1e-6 and 50 < residuals[0] / residuals[1] < 200


def test_the_conic_inner_steps_give_newtons_answer():
    """Every inner step by Newton from the last iterate (the fast path), or every one by the conic program: the same
    Coulomb answer to the map's tolerance, each iterate's path and Newton steps in the map's record."""
    fast, conic = (history(punch(cc.Coulomb(friction=0.2), (2, 8)), fast=fast) for fast in (True, False))
    assert fast.status == conic.status == "solved"
    for a, b in zip(fast.steps, conic.steps, strict=True):
        assert {entry["path"] for entry in a.extra["history"]} == {"newton"}
        assert {entry["path"] for entry in b.extra["history"]} == {"conic"}
        assert a.extra["picard"]["iterations"] == len(a.extra["history"]) > 1
        assert np.abs(a.displacement - b.displacement).max() < 1e-7 * np.abs(b.displacement).max()


def test_a_failing_inner_step_is_reported_not_raised(monkeypatch):
    """Where every inner step fails (Newton not applicable, the conic solver returning no answer), the step is reported
    with the solver's word and no answer — never an exception, never a silent success — and the history stops there."""
    from convexcontact import solvers
    from convexcontact.conic import ConicSolution
    from convexcontact.drivers import plastic_polish

    def failed(program, *args, **kwargs):
        size = program.q.size
        return ConicSolution(x=np.full(size, np.nan), z=np.full(program.b.size, np.nan), s=np.full(program.b.size, np.nan),
                             status="failed", solver_status="NumericalError", iterations=0, solve_time=0.0,
                             solver="clarabel")

    monkeypatch.setattr(plastic_polish, "applies", lambda model: False)
    monkeypatch.setattr(solvers, "solve", failed)
    result = cc.run_history(punch(cc.Coulomb(friction=0.2)))
    assert len(result.steps) == 1 and result.status == "failed"
    assert result.steps[0].displacement is None and "NumericalError" in result.message
    assert "inner solve NumericalError" in result.steps[0].extra["picard"]["outcome"]
