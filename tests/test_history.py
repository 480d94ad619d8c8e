"""Quasistatic histories (issue 11): one step is the static problem, friction acts on the slip increment,
Kelvin–Voigt bodies creep as backward Euler says, and everything is reused from step to step."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.drivers.history_run import run
from convexcontact.scene.description import SceneError
from convexcontact.scene.load_history import History

SLIP_BOUND, DEPTH, WIDTH = 0.002, 0.01, 1.0


def sliding_block(ux: list[float], law=None) -> cc.Scene:
    """A block pressed DEPTH into a flat rigid plane by its clamped top, which then moves by ``ux``."""
    return cc.Scene(
        name="sliding block",
        body=cc.Body(cc.Rectangle(width=WIDTH, height=0.5, nx=16, ny=8)),
        materials=cc.Material(1.0, 0.3),
        dirichlet=(cc.Dirichlet("top", ux=0.0, uy=-DEPTH),),
        contact=cc.Contact("bottom", cc.Obstacle("flat"), law or cc.Tresca(slip_bound=SLIP_BOUND)),
        history=History(times=list(range(1, len(ux) + 1)), values={"dirichlet[top].ux": ux}),
    )


@pytest.mark.parametrize("law", [cc.Signorini(), cc.Tresca(slip_bound=0.005)])
@pytest.mark.parametrize("formulation", ["primal", "dual"])
def test_a_one_step_history_is_the_static_problem(law, formulation):
    """The punch indented in one step: the static answer, to solver accuracy."""
    scene = cc.library.tresca_punch(nx=16).with_law(law)
    static = cc.solve(scene, formulation=formulation)
    history = run(dataclasses.replace(scene, history=History(times=[1.0], values={"obstacle.depth": [0.01]})),
                  formulation=formulation)
    step = history.steps[0]
    assert history.status == static.status == "solved"
    assert np.abs(step.displacement - static.displacement).max() < 1e-10 * np.abs(static.displacement).max()
    assert np.abs(step.contact.forces - static.contact.forces).max() < 1e-10 * np.abs(static.contact.forces).max()


def test_a_dragged_block_sticks_then_slips_at_the_bound_and_slips_back_when_unloaded():
    """Tresca: the tangential reaction rises while the block sticks, saturates at s × length once the whole
    interface slips, and on the way back falls through 0 to −s × length; each step certified."""
    out = [0.002 * k for k in range(9)]
    result = run(sliding_block(out + out[-2::-1]))
    assert result.status == "solved"
    force = np.array(result.series()["tangential_force"])
    saturated = SLIP_BOUND * WIDTH
    assert np.all(np.diff(force[:9]) <= 1e-12)  # pulled along +x: friction on the body along −x grows
    np.testing.assert_allclose(force[5:9], -saturated, rtol=1e-9)  # the whole interface slips
    assert (result.steps[8].contact.status == "slip+").all()
    np.testing.assert_allclose(force[-4:], saturated, rtol=1e-9)  # reverse slip on the way back
    assert (result.steps[-1].contact.status == "slip-").all()
    assert max(step.certificate.worst for step in result.steps) < 1e-10


def test_the_dragged_block_dissipates_on_a_closed_cycle():
    """Out and back to the start: the friction work Σ λ_T · Δslip over the cycle is positive (hysteresis)."""
    out = [0.002 * k for k in range(9)]
    result = run(sliding_block(out + out[-2::-1]))
    work = sum(-(step.contact.friction * step.contact.slip * result.steps[0].fem.contact.weights).sum()
               * step.fem.scaling.length for step in result.steps)
    assert work > 0.5 * SLIP_BOUND * WIDTH * 2 * (0.016 - 0.004)  # at least the two fully slipping strokes


def test_each_step_after_the_first_is_a_warm_start():
    """One condensation and one solver session for the whole history: later steps start from the last
    answer and need no interior point (Clarabel's polish from the previous step)."""
    result = run(sliding_block([0.0, 0.002, 0.004, 0.006]), formulation="dual")
    assert all(step.iterations == 0 for step in result.steps[1:])
    assert "condensation" in result.timings and "condensation" not in result.steps[1].timings


def creep_column(viscosity: float, times: list[float]) -> cc.Scene:
    """A column (ν = 0) on a frictionless plane under a constant top pressure from t = 0: uniaxial stress."""
    return cc.Scene(
        name="creep",
        body=cc.Body(cc.Rectangle(width=0.5, height=1.0, nx=2, ny=4), "Q1"),
        materials=cc.Material(1.0, 0.0, viscosity=viscosity),
        dirichlet=(cc.Dirichlet("left", ux=0.0),),
        tractions=(cc.Traction("top", pressure=0.01),),
        contact=cc.Contact("bottom", cc.Obstacle("flat"), cc.Signorini()),
        history=History(times=times, values={"traction[top].pressure": [0.01] * len(times)}),
    )


def test_a_kelvin_voigt_column_creeps_as_backward_euler_says():
    """u_k = u∞ (1 − (1 + Δt/τ)^−k) exactly (the discrete law), and → u∞ (1 − e^{−t/τ}) as Δt → 0;
    the contact pressure balances the load at every step."""
    tau, pressure = 2.0, 0.01
    settled = -pressure * 1.0  # u∞ of the top: −p H / E

    def top(step):
        return step.displacement[step.fem.basis.nodal_dofs[1]][np.isclose(step.fem.mesh.p[1], 1.0)].mean() \
            * step.fem.scaling.length

    for dt in (0.5, 0.05):
        times = list(np.arange(1, round(2.0 / dt) + 1) * dt)
        result = run(creep_column(viscosity=tau * 1.0, times=times))
        assert result.status == "solved"
        k = np.arange(1, len(times) + 1)
        discrete = settled * (1 - (1 + dt / tau) ** -k.astype(float))
        np.testing.assert_allclose([top(s) for s in result.steps], discrete, rtol=1e-8)
        for step in result.steps:
            np.testing.assert_allclose(step.contact.pressure, pressure, rtol=1e-8)
    exact = settled * (1 - np.exp(-2.0 / tau))
    assert abs(top(result.steps[-1]) - exact) < 0.02 * abs(exact)  # first order in Δt: 1.3 % at Δt = τ/40


def test_an_elastic_column_ignores_time():
    """Viscosity 0: every step is the static answer, whatever the times."""
    result = run(creep_column(viscosity=0.0, times=[0.1, 5.0]))
    assert result.status == "solved"
    np.testing.assert_allclose(result.steps[0].displacement, result.steps[1].displacement, rtol=1e-10, atol=1e-15)


@pytest.mark.parametrize("times, values, field", [
    ([0.0, 1.0], {"obstacle.depth": [0.01, 0.02]}, "history.times"),
    ([2.0, 1.0], {"obstacle.depth": [0.01, 0.02]}, "history.times"),
    ([1.0, 2.0], {"obstacle.depth": [0.01]}, "history.obstacle.depth"),
    ([1.0, 2.0], {"obstacle.radius": [1.0, 2.0]}, "history.obstacle.radius"),
    ([1.0, 2.0], {"obstacle.depth": [0.01, float("nan")]}, "history.obstacle.depth[1]"),
    ([1.0], {}, "history"),
])
def test_a_malformed_history_names_its_field(times, values, field):
    with pytest.raises(SceneError) as error:
        History(times=times, values=values)
    assert error.value.field == field


def test_a_history_naming_a_load_the_scene_lacks_says_what_to_add():
    scene = dataclasses.replace(cc.library.tresca_punch(nx=8),
                                history=History(times=[1.0], values={"traction[top].pressure": [0.1]}))
    with pytest.raises(SceneError, match=r"add a \[\[traction\]\] boundary = 'top'"):
        run(scene)


def test_a_coulomb_block_saturates_at_mu_times_the_normal_reaction_both_ways():
    """Coulomb μ = 0.3 on the slip increment: tangential / normal reaction rises while stuck, is exactly
    ∓μ once the whole interface slips, and reverses on the way back; every step a certified fixed point."""
    out = [0.004 * k for k in range(11)]
    result = run(sliding_block(out + out[-2::-1], law=cc.Coulomb(friction=0.3)))
    assert result.status == "solved", result.message
    series = result.series()
    ratio = np.array(series["tangential_force"]) / np.array(series["normal_force"])
    assert abs(ratio[1]) < 0.3 - 1e-3  # partly stuck at first
    np.testing.assert_allclose(ratio[6:11], -0.3, rtol=1e-7)
    np.testing.assert_allclose(ratio[-3:], 0.3, rtol=1e-7)
    assert all(step.extra["picard"]["outcome"] == "converged" for step in result.steps)
    assert max(step.certificate.worst for step in result.steps) < 1e-6


def stick_ratios(friction: float) -> tuple[list[float], float]:
    """c/a of every step of Spence's monotone indentation (depth × 1.25 per step) and of the one-step static
    solve at the final depth."""
    from convexcontact.scene.library import frictional_punch

    def ratio(step):
        s, status = step.contact.coordinate, step.contact.status
        return np.ptp(s[status == "stick"]) / np.ptp(s[status != "open"]) if (status == "stick").any() else 0.0

    scene = frictional_punch(h=0.0025, friction=friction, element="Q1")
    depths = list(0.004 * 1.25 ** np.arange(8))
    result = run(dataclasses.replace(scene, history=History(times=list(range(1, 9)), values={"obstacle.depth": depths})))
    assert result.status == "solved"
    static = cc.solve(dataclasses.replace(scene, contact=dataclasses.replace(
        scene.contact, obstacle=dataclasses.replace(scene.contact.obstacle, depth=depths[-1]))))
    return [ratio(step) for step in result.steps], ratio(static)


def test_spence_indentation_is_self_similar_and_its_stick_zone_grows_with_friction():
    """Case 4 as a process: after the first step c/a stays constant (within a node, h/a ≤ 0.06) while the
    contact zone grows 2.2-fold, and grows with F; the one-step static answer is another problem
    (friction on the total slip from the undeformed state) and its stick zone is far smaller."""
    low, low_static = stick_ratios(0.2)
    high, high_static = stick_ratios(0.6)
    for ratios in (low, high):
        assert np.ptp(ratios[1:]) < 0.08
    assert np.mean(high[1:]) > np.mean(low[1:]) + 0.3
    assert high_static < np.mean(high[1:]) - 0.2 and low_static < np.mean(low[1:]) - 0.2


def test_the_shear_of_a_near_incompressible_punch_comes_from_the_clamped_base():
    """Issue 11's question: why does the one-step static punch at ν = 0.499 (Q2) show tangential traction of
    0.3 F p_max at the contact edge, where a half-plane has none? A clamped base couples the normal and
    tangential response of a finite block: the same block on rollers, 4× wider and deeper, has 2.4× less."""
    from convexcontact.scene.library import frictional_punch, punch_mesh

    def edge_shear(scene):
        result = cc.solve(scene)
        assert result.status == "solved"
        return np.abs(result.contact.friction).max() / (0.6 * result.max_pressure)

    clamped = frictional_punch(h=0.01, nu=0.499, element="Q2")
    rollers = dataclasses.replace(clamped, body=cc.Body(punch_mesh(0.01, width=16.0, depth=8.0, quads=True), "Q2"),
                                  dirichlet=(cc.Dirichlet("bottom", uy=0.0), cc.Dirichlet("left", ux=0.0),
                                             cc.Dirichlet("right", ux=0.0)))
    assert edge_shear(clamped) > 2 * edge_shear(rollers)


def test_a_scene_file_carries_its_history():
    """examples/scenes/sliding_block.toml: the [history] table, solved as a whole history by cc.solve."""
    from pathlib import Path

    from convexcontact.scene.toml import load_scene

    scene = load_scene(Path(__file__).resolve().parents[1] / "examples" / "scenes" / "sliding_block.toml")
    assert len(scene.history) == 13 and scene.history.values["dirichlet[top].ux"][6] == 0.024
    result = cc.solve(scene)
    assert isinstance(result, cc.HistoryResult) and result.status == "solved"
    series = result.series()
    assert series["tangential_force"][-1] == pytest.approx(0.3 * series["normal_force"][-1], rel=1e-7)


@pytest.mark.parametrize("history, field", [
    ({"obstacle.depth": [0.01]}, "history.times"),
    ({"times": [1.0], "obstacle.depth": 0.01}, "history.obstacle.depth"),
    ({"times": [1.0], "obstacle.depthh": [0.01]}, "history.obstacle.depthh"),
    ({"times": [1.0], "traction[top].pressure": [0.1]}, "history.traction[top].pressure"),
])
def test_a_bad_history_table_names_the_key(history, field):
    from convexcontact.scene.toml import scene_from_dict

    data = {"body": {"mesh": "rectangle", "nx": 4, "ny": 4}, "material": {"E": 1.0, "nu": 0.3},
            "dirichlet": [{"boundary": "bottom", "ux": 0.0, "uy": 0.0}],
            "contact": {"boundary": "top"}, "obstacle": {"shape": "flat", "depth": 0.01}, "history": history}
    with pytest.raises(SceneError) as error:
        scene_from_dict(data)
    assert error.value.field == field


def test_the_command_line_runs_a_history_and_benchmarks_one(tmp_path, capsys):
    """`convexcontact run` of a scene with a history prints a row per step and writes the time series;
    `convexcontact bench --history N` times a history against its static solves."""
    from pathlib import Path

    from convexcontact import cli

    scene = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "sliding_block.toml"
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "step 13/13: solved" in printed and "status solved" in printed
    assert (tmp_path / "out" / "solution.pvd").read_text().count("<DataSet") == 13
    assert cli.main(["bench", "--history", "2", "--sizes", "300", "--out", str(tmp_path / "bench")]) == 0
    rows = (tmp_path / "bench" / "history_bench.csv").read_text().splitlines()
    assert len(rows) == 2 and ",solved," in rows[1]


def test_a_history_left_to_auto_runs_newton_cg_as_clarabel_would(monkeypatch):
    """Left to auto, the dense dual's session is newton-cg's, warm-started from step to step: every step
    certified and equal to Clarabel's history; where newton-cg fails (held to one Newton step, on faces not grown:
    with them one step solves each), Clarabel answers that step and the rest, and the steps say why."""
    from convexcontact.drivers import rules
    from convexcontact.solvers import newton_cg

    scene = sliding_block([0.0, 0.002, 0.004, 0.006])
    newton, interior = run(scene, "auto"), run(scene, "clarabel")
    assert [step.solver for step in newton.steps] == ["newton-cg"] * 4
    assert all(step.extra["solver_reason"] == rules.DENSE_NEWTON for step in newton.steps)
    for a, b in zip(newton.steps, interior.steps):
        assert a.status == "solved" and a.certificate.worst < 1e-10
        assert np.abs(a.displacement - b.displacement).max() < 1e-8 * np.abs(b.displacement).max()
    monkeypatch.setattr(rules, "DENSE_NEWTON_STEPS", 1)
    monkeypatch.setattr(newton_cg, "GROW", 0)
    fallback = run(scene, "auto")
    assert fallback.status == "solved" and [step.solver for step in fallback.steps] == ["clarabel"] * 4
    assert fallback.steps[0].extra["solver_reason"].startswith("newton-cg max_iter after 1 Newton steps")


def test_a_rigid_ground_among_pairs_moves_by_its_contact_index():
    """Two unit blocks on rollers, the upper's top held, the ground under the lower raised by d_k through
    ``contact[1].obstacle.depth``: both interfaces carry the uniaxial plane-strain pressure E d/(2(1 − ν²)) (the
    blocks in series each take d/2), at every node and every step. (``obstacle.depth`` here moved nothing.)"""
    material = cc.Material(1.0, 0.3)
    parts = [cc.Part("upper", cc.Rectangle(1.0, 1.0, 3, 3, origin=(0.0, 1.0)), material),
             cc.Part("lower", cc.Rectangle(1.0, 1.0, 4, 4), material)]
    depths = [0.001, 0.002, 0.003]
    scene = cc.bodies_scene(
        parts, [cc.Pair("upper.bottom", master="lower.top"), cc.Contact("lower.bottom", cc.Obstacle("flat"))],
        [cc.Dirichlet("upper.top", uy=0.0), cc.Dirichlet("upper.left", ux=0.0), cc.Dirichlet("lower.left", ux=0.0)],
        history=History([1.0, 2.0, 3.0], {"contact[1].obstacle.depth": depths}))
    result = run(scene)
    assert result.status == "solved"
    for step, depth in zip(result.steps, depths):
        np.testing.assert_allclose(step.contact.pressure, depth / (2 * (1 - 0.3**2)), rtol=1e-8)


def test_the_steps_of_a_history_share_one_stiffness():
    """Each step's model is K's, not a copy of it (a copy per step was 42 of the 57 kB a step held): the
    frictional block's slip offset no longer rebuilds K."""
    result = run(sliding_block([0.0, 0.002, 0.004]))
    assert result.status == "solved"
    assert all(step.fem.K is result.steps[0].fem.K for step in result.steps[1:])


@pytest.mark.parametrize("small, status", [(1e-6, "solved"), (1e-9, "inaccurate"), (1e-12, "inaccurate")])
def test_a_step_far_below_the_history_scale_is_judged_on_its_own(small, status):
    """The pressure patch loaded with ``small``, then 1: the units are the second step's, on which the first step's
    certificate passed while its contact force was 13 % off (10⁻⁹) or 0 (10⁻¹²). On its own scale it is
    "inaccurate", and says why; at 10⁻⁶ it is solved and its force is the load to round-off."""
    scene = dataclasses.replace(cc.library.pressure_patch(nx=3), history=History(
        [1.0, 2.0], {"traction[top].pressure": [small, 1.0]}))
    result = run(scene)
    first = result.steps[0]
    assert first.status == status and result.steps[1].status == "solved"
    if status == "solved":
        assert first.normal_force == pytest.approx(small, rel=1e-12)
    else:
        assert "on its own" in first.message and result.status == "inaccurate" and "step 1" in result.message
