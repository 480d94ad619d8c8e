"""Exact sensitivities (docs/sensitivity.md): central finite differences of whole solves where the active set
holds, one-sided differences across a change of status, the adjoint against the forward derivatives."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.drivers.active_set import NotDifferentiable

TIGHT = {"formulation": "dual", "solver": "newton-cg"}
"""Answers polished to round-off (certificates ≤ 1e-13), so that differences of solves are derivatives to 1e-8."""


def block(law, ux=0.02, uy=-0.01, nx=8, pressure=0.001):
    """A 2 × 1 block pressed on a flat rigid foundation by its top, moved sideways by ux, pushed from the right."""
    return cc.Scene(name="block", body=cc.Body(cc.Rectangle(width=2.0, height=1.0, nx=nx, ny=nx // 2)),
                    materials=cc.Material(E=1.0, nu=0.3), dirichlet=(cc.Dirichlet("top", ux=ux, uy=uy),),
                    tractions=(cc.Traction("right", pressure=pressure),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), law))


def box(law):
    """A 2 × 1 × 1 box of Q1 cells pressed down and moved along x and y: every contact point slips obliquely
    (the projector term of 3-D friction)."""
    return cc.Scene(name="box", body=cc.Body(cc.Box(size=(2.0, 1.0, 1.0), cells=(4, 2, 2)), element="Q1"),
                    materials=cc.Material(E=1.0, nu=0.3),
                    dirichlet=(cc.Dirichlet("top", ux=0.02, uy=0.01, uz=-0.01),),
                    contact=cc.Contact("bottom", cc.Obstacle("flat", gap=0.0), law))


def fields(result, derivative=None) -> np.ndarray:
    """Displacement, pressure, friction and resultants of a result (or of a Derivative) in one vector."""
    source = derivative or result
    friction = source.friction if derivative else result.contact.friction
    pressure = source.pressure if derivative else result.contact.pressure
    motions = [source.obstacle_advance or 0.0, source.obstacle_shift or 0.0]
    return np.concatenate([source.displacement, pressure, np.ravel(friction if friction is not None else []),
                           motions, np.atleast_1d(source.contact_force)])


def central(scene, parameter, value, step, options=TIGHT):
    """(x(θ + h) − x(θ − h)) / 2h of whole tight solves."""
    ends = [cc.solve(cc.with_parameter(scene, parameter, value + sign * step), **options) for sign in (1, -1)]
    assert all(end.certificate.worst < 1e-12 for end in ends)
    return (fields(ends[0]) - fields(ends[1])) / (2 * step)


def assert_agrees(scene, parameters, rel=1e-6, options=TIGHT):
    """The sensitivity of every parameter equals the central difference of solves within ``rel`` of its scale."""
    result = cc.solve(scene, **options)
    assert result.certificate.worst < 1e-12
    found = cc.sensitivity(result, parameters)
    for parameter, sensitivity in found.items():
        assert sensitivity.differentiable and sensitivity.margin > 1e-4
        exact = fields(result, sensitivity.derivative)
        difference = central(scene, parameter, sensitivity.value, 1e-4 * max(abs(sensitivity.value), 0.01), options)
        assert np.abs(exact - difference).max() <= rel * np.abs(difference).max(), parameter
    return result, found


def test_signorini_2d_agrees_with_finite_differences():
    assert_agrees(block(cc.Signorini()), ["dirichlet[top].uy", "E", "nu", "obstacle.gap", "traction[right].pressure"])


@pytest.mark.parametrize("non_penetration", ["nodal", "weak"])
def test_tresca_2d_agrees_with_finite_differences(non_penetration):
    """Node-wise contact and Hild's weak form (C = M, R = M T: rows coupling neighbouring nodes)."""
    law = cc.Tresca(slip_bound=0.004, non_penetration=non_penetration)
    result, found = assert_agrees(block(law), ["dirichlet[top].ux", "slip_bound", "E"],
                                  options={"formulation": "dual", "solver": "clarabel"})
    slipping = np.char.startswith(result.contact.status.astype(str), "slip")
    # every slipping node's traction is the bound: its derivative along the bound is the sign of the traction
    assert np.allclose(found["slip_bound"].derivative.friction[slipping], np.sign(result.contact.friction[slipping]))


@pytest.fixture(params=["kept", "condensed", "sparse"])
def system(request, monkeypatch):
    """The derivative system condensed onto the contact DOFs by the dual solve's own condensation (kept with its
    result), by one of its own (the default from 2·10⁴ DOFs where the solve kept none), or over every DOF."""
    if request.param != "kept":
        monkeypatch.setattr("convexcontact.drivers.prepared.kept_for", lambda reused, fem: None)
        monkeypatch.setattr(f"convexcontact.drivers.linearized.{'CONDENSED_DOFS' if request.param == 'condensed' else 'CONDENSED'}", 0)
    return request.param


def test_coulomb_2d_differentiates_the_coulomb_law(system):
    """s = μ λ_N of the same answer: dλ_T = d(μ λ_N) at slipping nodes, including μ's own term."""
    result, found = assert_agrees(block(cc.Coulomb(friction=0.3)), ["friction", "dirichlet[top].uy", "nu"])
    derivative = found["friction"].derivative
    sign = np.sign(result.contact.friction)
    assert np.allclose(np.abs(derivative.friction), np.abs(result.contact.pressure + 0.3 * derivative.pressure),
                       rtol=1e-9)
    assert np.all(sign != 0)


def test_nonlocal_coulomb_differentiates_its_mollified_law():
    """s = μ G S λ_N (S the mollifier of the pressure, Oden–Duvaut): an open edge node slips under the smoothed
    pressure of its neighbours."""
    result, _ = assert_agrees(block(cc.Coulomb(friction=0.3, smoothing_radius=0.3), nx=12),
                              ["friction", "dirichlet[top].uy"])
    assert result.contact.status[0] == "open"


@pytest.mark.parametrize("law, parameters", [
    (cc.NormalCompliance(stiffness=5.0), ["stiffness", "dirichlet[top].uy", "E"]),
    (cc.Tresca(slip_bound=0.004, compliance=cc.NormalCompliance(stiffness=5.0)), ["stiffness", "slip_bound"])])
def test_normal_compliance_along_its_stiffness(law, parameters):
    """The penalty law λ = c_N e (p = 1): its rows keep A du − (w/c_N) dλ = dh, and dλ/dc_N = e at fixed u."""
    assert_agrees(block(law), parameters, options={"formulation": "primal", "solver": "clarabel"})


def test_tresca_punch_partial_contact_along_depth():
    """A parabolic punch with Tresca friction: a closed zone, open nodes, stick and slip, along the depth."""
    assert_agrees(cc.library.tresca_punch(nx=16), ["obstacle.depth", "slip_bound", "E"])


def test_force_controlled_punch_pulled_sideways(system):
    """Hertz's punch pressed by P and pulled by Q (Tresca): the obstacle's advance and shift are unknowns, whose
    derivatives along P, Q and E agree with differences too."""
    law = cc.Tresca(slip_bound=0.002)
    punch = cc.Obstacle("parabolic", radius=1.0, force=0.0086307, tangential_force=0.001)
    scene = dataclasses.replace(cc.library.hertz_punch(nx=16, law=law), contact=cc.Contact("top", punch, law))
    result, found = assert_agrees(scene, ["obstacle.force", "obstacle.tangential_force", "E"],
                                  options={"formulation": "dual", "solver": "clarabel"})
    # the resultants are the loads: dP/dP = 1, dQ/dQ = 1 (Q along the mean tangent, pulling the body)
    assert found["obstacle.force"].derivative.normal_force == pytest.approx(1.0, rel=1e-9)
    assert abs(found["obstacle.tangential_force"].derivative.tangential_force) == pytest.approx(1.0, rel=1e-9)
    advance = cc.gradient(result, ["obstacle.force", "E"], obstacle_advance=1.0)
    assert advance["E"] == pytest.approx(found["E"].derivative.obstacle_advance, rel=1e-9)


@pytest.mark.parametrize("law, parameters", [(cc.Tresca(slip_bound=0.004), ["dirichlet[top].ux", "slip_bound"]),
                                             (cc.Coulomb(friction=0.3), ["dirichlet[top].uy", "friction"])])
def test_3d_oblique_slip_agrees_with_finite_differences(law, parameters, system):
    result, _ = assert_agrees(box(law), parameters)
    assert set(result.contact.status) == {"slip"}


@pytest.mark.parametrize("law, options", [(cc.Signorini(), TIGHT),
                                          (cc.NormalCompliance(stiffness=5.0), {"formulation": "primal"})])
def test_grazing_contact_gives_both_one_sided_derivatives(law, options):
    """A block touching its foundation without load (every node grazing): lifting the top opens every node
    (right derivative: no force), pressing closes them (left: the closed block's stiffness, or the penalty's in
    series with it). One-sided differences of solves are these derivatives; the central difference lies between."""
    scene = block(law, ux=0.0, uy=0.0, pressure=0.0)
    result = cc.solve(scene, **options)
    found = cc.sensitivity(result, "dirichlet[top].uy")
    assert list(found.degenerate["grazing"]) == list(range(result.fem.contact.m))
    with pytest.raises(NotDifferentiable, match="grazing"):
        _ = found.derivative
    step = 1e-4
    up, down = (cc.solve(cc.with_parameter(scene, "dirichlet[top].uy", sign * step), **options) for sign in (1, -1))
    assert found.right.normal_force == pytest.approx(0.0, abs=1e-12)
    assert found.left.normal_force < -0.1  # pressing: the force grows as uy decreases
    for side, difference in ((found.right, fields(up) - fields(result)), (found.left, fields(result) - fields(down))):
        assert np.abs(fields(result, side) - difference / step).max() <= 1e-8 * np.abs(difference / step).max()
    middle = (up.normal_force - down.normal_force) / (2 * step)
    assert found.left.normal_force < middle < found.right.normal_force


def test_stick_slip_boundary_gives_both_one_sided_derivatives():
    """Tresca with the bound set to the largest sticking traction: that node sits at the stick/slip boundary.
    A larger bound changes nothing (right derivative 0); a smaller one lets it slip (left derivative)."""
    sticking = cc.solve(block(cc.Tresca(slip_bound=1.0), ux=0.002), **TIGHT)
    assert set(sticking.contact.status) == {"stick"}
    bound = float(np.abs(sticking.contact.friction).max())
    scene = block(cc.Tresca(slip_bound=bound), ux=0.002)
    result = cc.solve(scene, **TIGHT)
    found = cc.sensitivity(result, ["slip_bound", "dirichlet[top].ux"])
    edge = int(np.argmax(np.abs(sticking.contact.friction)))
    assert [list(s.degenerate["stick_slip"]) for s in found.values()] == [[edge], [edge]]
    assert np.abs(fields(result, found["slip_bound"].right)).max() == 0.0
    step = 1e-6 * bound
    below = cc.solve(cc.with_parameter(scene, "slip_bound", bound - step), **TIGHT)
    assert below.contact.status[edge].startswith("slip")
    difference = (fields(result) - fields(below)) / step
    assert np.abs(fields(result, found["slip_bound"].left) - difference).max() <= 1e-6 * np.abs(difference).max()
    # along ux the node slips either way, but at different rates: both one-sided derivatives, each a difference
    sliding = found["dirichlet[top].ux"]
    for sign, side in ((1, sliding.right), (-1, sliding.left)):
        moved = cc.solve(cc.with_parameter(scene, "dirichlet[top].ux", 0.002 + sign * 1e-6), **TIGHT)
        difference = sign * (fields(moved) - fields(result)) / 1e-6
        assert np.abs(fields(result, side) - difference).max() <= 1e-6 * np.abs(difference).max()
    assert sliding.right.tangential_force != pytest.approx(sliding.left.tangential_force, rel=1e-3)


def two_blocks(law):
    """A block (E = 1) pressed on another (E = 2, ν = 0.25, clamped below) and moved sideways: mortar contact."""
    from convexcontact.scene.bodies import Pair, Part

    parts = [Part("upper", cc.Rectangle(1.0, 0.5, 4, 2, origin=(0.0, 1.0)), cc.Material(E=1.0, nu=0.3), "P1"),
             Part("lower", cc.Rectangle(1.0, 1.0, 5, 5), cc.Material(E=2.0, nu=0.25), "P1")]
    return cc.bodies_scene(parts, Pair("upper.bottom", master="lower.top", law=law), name="two_blocks",
                           dirichlet=[cc.Dirichlet("lower.bottom", ux=0.0, uy=0.0),
                                      cc.Dirichlet("upper.top", ux=0.01, uy=-0.01)])


@pytest.mark.parametrize("law, parameters, options", [
    (cc.Tresca(slip_bound=0.003), ["dirichlet[upper.top].ux", "slip_bound", "materials[upper].nu"],
     {"formulation": "primal", "solver": "clarabel"}),
    (cc.Coulomb(friction=0.2), ["friction", "dirichlet[upper.top].uy", "materials[lower].E"], TIGHT)])
def test_two_bodies_agree_with_finite_differences(law, parameters, options):
    """Two bodies in mortar contact (rows over both bodies' DOFs), each body's own material a parameter."""
    result, _ = assert_agrees(two_blocks(law), parameters, options=options)
    assert {"stick", "slip+"} <= set(result.contact.status)


@pytest.mark.parametrize("law, parameters", [(cc.Tresca(slip_bound=0.004), ["slip_bound", "E", "dirichlet[top].uy"]),
                                             (cc.Coulomb(friction=0.3), ["friction", "traction[right].pressure"])])
def test_through_the_steps_of_a_history(law, parameters):
    """A block moved right, further right, then back (friction acts on each step's slip increment): every step's
    derivative carries the earlier steps' through the slip it starts from, and agrees with differences of whole
    histories (without the carried slip they were 16–100 % off at steps 2 and 3)."""
    history = cc.History(times=[1.0, 2.0, 3.0], values={"dirichlet[top].ux": [0.001, 0.004, -0.002]})
    scene = dataclasses.replace(block(law, ux=0.0), history=history)
    answer = cc.solve(scene, **TIGHT)
    assert answer.status == "solved"
    for parameter, steps in cc.sensitivity(answer, parameters).items():
        step = 1e-4 * max(abs(steps[0].value), 0.01)
        ends = [cc.solve(cc.with_parameter(scene, parameter, steps[0].value + sign * step), **TIGHT) for sign in (1, -1)]
        for k, found in enumerate(steps):
            difference = (fields(ends[0].steps[k]) - fields(ends[1].steps[k])) / (2 * step)
            exact = fields(answer.steps[k], found.derivative)
            assert np.abs(exact - difference).max() <= 1e-6 * np.abs(difference).max(), (parameter, k)


def oblique_box(law):
    return dataclasses.replace(box(law), dirichlet=(cc.Dirichlet("top", ux=0.002, uy=0.001, uz=-0.01),))


@pytest.mark.parametrize("scene, bound", [(lambda law: block(law, ux=0.002), "friction"),
                                          (oblique_box, "slip_bound")])
def test_the_bound_at_the_largest_sticking_traction(scene, bound):
    """2-D Coulomb (the unsymmetric coupling s = μ λ_N) and 3-D Tresca (the disc's rim: one row switches) with the
    bound at the largest sticking traction: a larger bound changes nothing, a smaller one lets that node slip,
    both one-sided derivatives equal one-sided differences of solves."""
    law = cc.Coulomb if bound == "friction" else cc.Tresca
    sticking = cc.solve(scene(law(**{bound: 10.0})), **TIGHT)
    assert set(sticking.contact.status) == {"stick"}
    strength = np.linalg.norm(np.reshape(sticking.contact.friction, (sticking.fem.contact.m, -1)), axis=1)
    if bound == "friction":
        strength = strength / sticking.contact.pressure
    value, edge = float(strength.max()), int(np.argmax(strength))
    at_edge = scene(law(**{bound: value}))
    result = cc.solve(at_edge, **TIGHT)
    found = cc.sensitivity(result, bound)
    assert list(found.degenerate["stick_slip"]) == [edge]
    assert np.abs(fields(result, found.right)).max() <= 1e-9 * np.abs(fields(result, found.left)).max()
    below = cc.solve(cc.with_parameter(at_edge, bound, value * (1 - 1e-6)), **TIGHT)
    assert below.contact.status[edge].startswith("slip")
    difference = (fields(result) - fields(below)) / (value * 1e-6)
    assert np.abs(fields(result, found.left) - difference).max() <= 1e-6 * np.abs(difference).max()


def test_adjoint_gradient_is_the_forward_derivatives_contracted(system):
    """One transposed solve gives dJ/dθ of every parameter: J weighs displacements, pressures, friction and
    the resultants at once."""
    result = cc.solve(block(cc.Coulomb(friction=0.3)), **TIGHT)
    rng = np.random.default_rng(1)
    weights = {"displacement": rng.standard_normal(result.displacement.size),
               "pressure": rng.standard_normal(result.contact.pressure.size),
               "friction": rng.standard_normal(result.contact.friction.shape),
               "contact_force": rng.standard_normal(2), "normal_force": 0.7, "tangential_force": -1.3}
    parameters = ["friction", "E", "nu", "dirichlet[top].ux", "dirichlet[top].uy", "traction[right].pressure"]
    gradient = cc.gradient(result, parameters, **weights)
    for parameter, sensitivity in cc.sensitivity(result, parameters).items():
        d = sensitivity.derivative
        forward = (weights["displacement"] @ d.displacement + weights["pressure"] @ d.pressure
                   + np.sum(weights["friction"] * d.friction) + weights["contact_force"] @ d.contact_force
                   + 0.7 * d.normal_force - 1.3 * d.tangential_force)
        assert gradient[parameter] == pytest.approx(forward, rel=1e-9, abs=1e-12 * np.abs(forward)), parameter


def test_adjoint_is_refused_at_a_degenerate_answer():
    result = cc.solve(block(cc.Signorini(), ux=0.0, uy=0.0, pressure=0.0), **TIGHT)
    with pytest.raises(NotDifferentiable, match="result: 9 grazing nodes.*cc.sensitivity"):
        cc.gradient(result, ["E"], normal_force=1.0)


def test_identify_friction_example_recovers_the_truth_within_the_noise():
    """examples/identify_friction.py: μ and E from 8 noisy forces, by L-BFGS-B on the adjoint gradient, each
    within three Gauss–Newton standard errors of the truth, the errors a few per cent."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "identify_friction.py"
    spec = importlib.util.spec_from_file_location("identify_friction", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    estimate, errors, fit, _ = example.main(points=4, nx=6)
    assert fit.success
    for name, truth in example.TRUTH.items():
        assert abs(estimate[name] - truth) <= 3 * errors[name] and errors[name] <= 0.03 * truth, name


def test_the_degenerate_rows_complementarity_problem():
    """Every branch tried (≤ 12 rows) and Murty's pivoting find the one solution of an SPD problem; a problem with
    two solutions (w = 0, z = 1 and w = 1, z = 0) or none gives None, never one of them."""
    from convexcontact.drivers.active_set import complementary, pivoting

    rng = np.random.default_rng(0)
    for size in (3, 8, 15):
        for _ in range(20):
            B = rng.standard_normal((size, size))
            Q, q = B @ B.T + 0.1 * np.eye(size), rng.standard_normal(size)
            w = complementary(Q, q)
            z = q + Q @ w
            assert w.min() >= 0 and z.min() >= -1e-10 and abs(w @ z) <= 1e-10
            assert np.allclose(pivoting(Q, q), w)
    assert complementary(np.array([[-1.0]]), np.array([1.0])) is None
    assert complementary(np.array([[-1.0]]), np.array([-1.0])) is None


def test_the_solves_condensation_is_reused_not_saved(monkeypatch):
    """A dual-solved result keeps K's condensation: its derivatives and gradient factorize nothing of K's size and
    equal those of a fresh factorization (SuperLU over every DOF) to round-off; pickling drops it, and the
    unpickled result is differentiated afresh to the same numbers."""
    import pickle

    import scipy.sparse.linalg as spla

    result = cc.solve(block(cc.Coulomb(friction=0.3), nx=12), **TIGHT)
    assert result.condensation is not None
    parameters, weights = ["friction", "E", "dirichlet[top].ux"], {"tangential_force": 1.0, "normal_force": 0.5}
    fresh = dataclasses.replace(result, condensation=None)
    expected = cc.sensitivity(fresh, parameters), cc.gradient(fresh, parameters, **weights)
    sizes = []

    def counted(matrix, *args, **kwargs):
        sizes.append(matrix.shape[0])
        return splu(matrix, *args, **kwargs)

    def refused(*args, **kwargs):
        raise AssertionError("K factorized again")

    splu = spla.splu
    monkeypatch.setattr("convexcontact.drivers.active_set.spla.splu", counted)
    for where in ("convexcontact.drivers.linearized.condense", "convexcontact.fem.factorization.condense",
                  "convexcontact.fem.factorization.factorize", "convexcontact.fem.factorization._superlu",
                  "convexcontact.fem.factorization._pardiso_factors"):
        monkeypatch.setattr(where, refused)
    found, gradient = cc.sensitivity(result, parameters), cc.gradient(result, parameters, **weights)
    assert sizes and max(sizes) < result.ndof  # the condensed system only: contact DOFs and multipliers
    for parameter in parameters:
        new, old = fields(result, found[parameter].derivative), fields(result, expected[0][parameter].derivative)
        assert np.abs(new - old).max() <= 1e-10 * np.abs(old).max(), parameter
        assert gradient[parameter] == pytest.approx(expected[1][parameter], rel=1e-10, abs=1e-14)
    monkeypatch.undo()
    restored = pickle.loads(pickle.dumps(result))
    assert restored.condensation is None and result.condensation is not None
    again = cc.gradient(restored, parameters, **weights)
    assert all(again[name] == pytest.approx(gradient[name], rel=1e-10, abs=1e-14) for name in parameters)
