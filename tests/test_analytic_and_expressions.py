"""Closed-form references (Hertz, Hild's one-triangle example) and safe scene formulas."""

from __future__ import annotations

import numpy as np
import pytest

from convexcontact.analytic import (
    hertz_plane_strain,
    hertz_pressure,
    hild_critical_friction,
    hild_one_triangle_solutions,
    lame_plane_strain,
)
from convexcontact.scene.description import SceneError
from convexcontact.scene.expressions import compile_expression

FIELD = "obstacle.expression"
E, NU, LENGTH = 2.0, 0.3, 1.5
TOL = 1e-9


# --------------------------------------------------------------------------- formulas


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("x**2/(2*0.5) - 0.01", lambda x, y: x**2 - 0.01),
        ("0.1*sqrt(x**2+y**2)", lambda x, y: 0.1 * np.hypot(x, y)),
        ("-x + 2*pi - e", lambda x, y: -x + 2 * np.pi - np.e),
        ("arctan2(y, x) + hypot(x, y)", lambda x, y: np.arctan2(y, x) + np.hypot(x, y)),
        ("maximum(x, y) - minimum(x, y) + abs(x)", lambda x, y: np.abs(x - y) + np.abs(x)),
        (
            "exp(-x**2) * cos(y) / (1 + tanh(x)**2)",
            lambda x, y: np.exp(-(x**2)) * np.cos(y) / (1 + np.tanh(x) ** 2),
        ),
        (
            "log(2 + sin(x)) + arctan(y) - tan(x/4) + cosh(y) - sinh(x)",
            lambda x, y: np.log(2 + np.sin(x)) + np.arctan(y) - np.tan(x / 4) + np.cosh(y) - np.sinh(x),
        ),
        ("+x - -y", lambda x, y: x + y),
    ],
)
def test_formula_values(text, expected):
    x, y = np.linspace(-1.0, 2.0, 7), np.linspace(0.5, 3.0, 7)
    np.testing.assert_allclose(compile_expression(text, FIELD)(x=x, y=y), expected(x, y), rtol=1e-14)


def test_formula_constant_and_subset_broadcast_to_coordinates():
    x = np.arange(6).reshape(2, 3)
    gap = compile_expression("0.01", FIELD)(x=x, y=x)
    assert gap.shape == (2, 3) and gap.dtype == float
    np.testing.assert_array_equal(gap, 0.01)
    np.testing.assert_array_equal(compile_expression("2*y", FIELD)(x=x, y=x + 1.0), 2 * (x + 1.0))


def test_integer_coordinates_give_float_results():
    assert compile_expression("x/2", FIELD)(x=np.array([1, 3])).tolist() == [0.5, 1.5]


@pytest.mark.parametrize(
    "text",
    [
        "x.real",  # attribute access
        "x[0]",  # subscript
        "lambda: 1",
        "__import__('os')",
        "__import__",
        "'abc'",
        "sqrt(x=1.0)",  # keyword argument
        "sqrt(*x)",
        "sqrt(x, x)",  # a second positional argument would be numpy's `out`
        "arctan2(y)",
        "[v for v in x]",
        "x < 1",
        "open('f')",
        "foo + 1",
        "np.sqrt(x)",
        "sqrt",
        "1j",
        "True",
        "x if y else 1",
        "(x, y)",
        "x // 2",
        "x % 2",
        "(lambda: 1)()",
        "sqrt(x)(1)",
        "None",
        "x == 1",
        "{'a': 1}",
        "f'{x}'",
    ],
)
def test_forbidden_constructs_name_the_field(text):
    with pytest.raises(SceneError) as error:
        compile_expression(text, FIELD)
    assert error.value.field == FIELD and str(error.value).startswith(FIELD + ":")


@pytest.mark.parametrize("text", ["x**", "x +* 2", "import os", "x; y", "", "-" * 5000 + "x"])
def test_syntax_errors_name_the_field(text):
    with pytest.raises(SceneError) as error:
        compile_expression(text, FIELD)
    assert error.value.field == FIELD


def test_non_string_formula_is_refused():
    with pytest.raises(SceneError, match=FIELD):
        compile_expression(3.0, FIELD)


@pytest.mark.parametrize(("text", "where"), [("sqrt(x)", "x=-1"), ("log(x)", "x=0"), ("1/x", "x=0")])
def test_non_finite_values_say_where(text, where):
    gap = compile_expression(text, FIELD)
    assert np.all(np.isfinite(gap(x=np.array([1.0, 2.0]))))
    with pytest.raises(SceneError, match=where) as error:
        gap(x=np.array([1.0, -1.0, 0.0]))
    assert error.value.field == FIELD


def test_non_finite_message_gives_all_coordinates():
    with pytest.raises(SceneError, match=r"x=2, y=-3"):
        compile_expression("sqrt(y)", FIELD)(x=np.array([1.0, 2.0]), y=np.array([4.0, -3.0]))


def test_overflow_is_reported_not_returned():
    with pytest.raises(SceneError, match="not finite"):
        compile_expression("10**(400*x)", FIELD)(x=np.array([1.0]))


def test_formula_using_an_absent_coordinate_names_the_field():
    with pytest.raises(SceneError, match="z") as error:
        compile_expression("x + z", FIELD)(x=np.zeros(3), y=np.zeros(3))
    assert error.value.field == FIELD


def test_coordinates_are_not_modified():
    x = np.array([4.0, 9.0])
    compile_expression("sqrt(x) + abs(-x)", FIELD)(x=x)
    assert x.tolist() == [4.0, 9.0]


# --------------------------------------------------------------------------- Hertz


def test_hertz_reference_numbers():
    a, p0 = hertz_plane_strain(0.0086307, 1.0, 1.0, 0.3)
    assert a == pytest.approx(0.1, rel=1e-5)
    assert p0 == pytest.approx(0.054945, rel=1e-5)


def test_hertz_pressure_profile_carries_the_force():
    force = 0.0086307
    a, p0 = hertz_plane_strain(force, 1.0, 1.0, 0.3)
    x = np.linspace(-2 * a, 2 * a, 400_001)
    pressure = hertz_pressure(x, a, p0)
    assert pressure.max() == pytest.approx(p0, rel=1e-9)
    assert np.all(pressure[np.abs(x) >= a] == 0)
    assert np.trapezoid(pressure, x) == pytest.approx(force, rel=1e-6)


# --------------------------------------------------------------------------- Hild


def stiffness_of_A(E: float, nu: float, length: float) -> np.ndarray:
    """2×2 plane-strain P1 stiffness of the free node A, assembled from scratch."""
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    nodes = np.array([[0.0, 0.0], [length, 0.0], [0.0, length]])
    coefficients = np.linalg.inv(np.column_stack([np.ones(3), nodes]))  # column j: φ_j = c0 + c1 x + c2 y
    gx, gy = coefficients[1:, 0]
    strain = np.array([[gx, 0.0], [0.0, gy], [gy, gx]])  # (ε_xx, ε_yy, γ_xy) per unit (u_x, u_y)
    elasticity = np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])
    return length**2 / 2 * strain.T @ elasticity @ strain


def brute_force_solutions(F1, F2, friction, stiffness, length) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """Every (u, r) at A by enumerating the regimes, each a linear system; None if one is singular."""
    load = np.array([F1, F2]) * length / 2
    scale = max(abs(F1), abs(F2), 1.0)
    found = []
    u = np.linalg.solve(stiffness, load)
    if u[1] >= -TOL * scale:
        found.append((u, np.zeros(2)))
    r = -load
    if r[1] >= -TOL * scale and abs(r[0]) <= friction * r[1] + TOL * scale:
        found.append((np.zeros(2), r))
    for direction in (1.0, -1.0):  # sign of u_x; u_y = 0, r = (−F R direction, R)
        system = np.array([[stiffness[0, 0], friction * direction], [stiffness[1, 0], -1.0]])
        if abs(np.linalg.det(system)) < 1e-12 * np.abs(system).max() ** 2:
            return None
        ux, R = np.linalg.solve(system, load)
        if direction * ux >= -TOL * scale and R >= -TOL * scale:
            found.append((np.array([ux, 0.0]), np.array([-friction * R * direction, R])))
    distinct = []
    for u, r in found:
        if not any(
            np.allclose(u, v, atol=1e-8 * scale) and np.allclose(r, s, atol=1e-8 * scale) for v, s in distinct
        ):
            distinct.append((u, r))
    return distinct


def assert_discrete_coulomb(solution, F1, F2, friction, stiffness, length):
    """The nodal Coulomb conditions at A and the dict's sign conventions."""
    u, r = np.array(solution["displacement"]), np.array(solution["contact_force"])
    scale = max(abs(F1), abs(F2), 1.0)
    np.testing.assert_allclose(stiffness @ u, np.array([F1, F2]) * length / 2 + r, atol=1e-10 * scale)
    normal_force, friction_force, gap, slip = r[1], -r[0], u[1], -u[0]
    assert normal_force >= -TOL * scale, "compressive contact force"
    assert gap >= -TOL * scale, "no penetration"
    assert abs(normal_force * gap) <= TOL * scale**2, "complementarity"
    assert abs(friction_force) <= friction * normal_force + TOL * scale, "friction cone"
    if abs(slip) > TOL * scale:
        assert friction_force == pytest.approx(-friction * normal_force * np.sign(slip), abs=TOL * scale)
    assert solution["U_T"] == pytest.approx(slip) and solution["U_N"] == pytest.approx(-gap)
    assert solution["lambda_N"] == pytest.approx(normal_force) and solution["lambda_T"] == pytest.approx(
        friction_force
    )
    assert solution["Lambda"] == pytest.approx(2 * normal_force / length)
    regime = solution["regime"]
    if regime == "stick":
        assert np.all(u == 0)
    elif regime == "separation":
        assert np.allclose(r, 0, atol=TOL * scale)
    else:
        assert u[1] == 0 and {"right slip": 1, "left slip": -1}[regime] * u[0] >= 0


def assert_same_sets(solutions, brute_force, scale):
    assert len(solutions) == len(brute_force)
    for u, r in brute_force:
        matches = [
            s
            for s in solutions
            if np.allclose(s["displacement"], u, atol=1e-8 * scale)
            and np.allclose(s["contact_force"], r, atol=1e-8 * scale)
        ]
        assert len(matches) == 1


def test_critical_friction_is_the_stiffness_ratio():
    for nu in (0.0, 0.2, 0.3, 0.45, -0.3):
        stiffness = stiffness_of_A(E, nu, LENGTH)
        lam, mu = lame_plane_strain(E, nu)
        assert hild_critical_friction(nu) == pytest.approx(stiffness[0, 0] / stiffness[1, 0])
        assert hild_critical_friction(nu) == pytest.approx((lam + 3 * mu) / (lam + mu))


@pytest.mark.parametrize("friction_factor", [0.0, 0.2, 0.6, 0.95])
def test_unique_solution_below_critical_friction(friction_factor):
    friction = friction_factor * hild_critical_friction(NU)
    stiffness = stiffness_of_A(E, NU, LENGTH)
    rng = np.random.default_rng(1)
    regimes = set()
    for F1, F2 in rng.normal(size=(300, 2)) * 3:
        solutions = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
        assert len(solutions) == 1
        assert not solutions[0]["continuum"]
        assert_discrete_coulomb(solutions[0], F1, F2, friction, stiffness, LENGTH)
        assert_same_sets(solutions, brute_force_solutions(F1, F2, friction, stiffness, LENGTH), 3.0)
        regimes.add(solutions[0]["regime"])
    assert regimes == (
        {"separation", "stick", "right slip", "left slip"}
        if friction
        else {"separation", "right slip", "left slip"}
    )


@pytest.mark.parametrize("friction_factor", [1.05, 1.3, 2.0])
def test_all_solutions_above_critical_friction(friction_factor):
    friction = friction_factor * hild_critical_friction(NU)
    stiffness = stiffness_of_A(E, NU, LENGTH)
    rng = np.random.default_rng(2)
    counts = set()
    for F1, F2 in rng.normal(size=(600, 2)) * 3:
        solutions = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
        for solution in solutions:
            assert_discrete_coulomb(solution, F1, F2, friction, stiffness, LENGTH)
        assert_same_sets(solutions, brute_force_solutions(F1, F2, friction, stiffness, LENGTH), 3.0)
        counts.add(len(solutions))
    assert counts <= {1, 3}  # two solutions only on the lines of Prop. 4.1, tested below


@pytest.mark.parametrize(
    ("where", "regimes"),
    [
        (lambda F, Fc: 0.5 * (F + Fc), {"separation", "stick", "left slip"}),  # −F|F2| < F1 < −Fc|F2|
        (lambda F, Fc: F, {"separation", "stick"}),  # F1 = F F2
        (lambda F, Fc: Fc, {"stick", "left slip"}),  # F1 = Fc F2
        (lambda F, Fc: 0.5 * Fc, {"stick"}),
        (lambda F, Fc: 1.5 * F, {"separation"}),
        (lambda F, Fc: -1.5 * F, {"right slip"}),
    ],
)
def test_proposition_4_1_above_critical_friction(where, regimes):
    critical = hild_critical_friction(NU)
    friction, F2 = 1.4 * critical, -2.0
    F1 = where(friction, critical) * F2
    stiffness = stiffness_of_A(E, NU, LENGTH)
    solutions = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
    assert {s["regime"] for s in solutions} == regimes and len(solutions) == len(regimes)
    for solution in solutions:
        assert_discrete_coulomb(solution, F1, F2, friction, stiffness, LENGTH)
    assert_same_sets(solutions, brute_force_solutions(F1, F2, friction, stiffness, LENGTH), 2.0)


def test_continuum_of_solutions_at_critical_friction():
    friction, F2 = hild_critical_friction(NU), -2.0
    F1 = friction * F2
    stiffness = stiffness_of_A(E, NU, LENGTH)
    assert brute_force_solutions(F1, F2, friction, stiffness, LENGTH) is None  # left slip system singular
    ends = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
    assert [s["regime"] for s in ends] == ["stick", "left slip"] and all(s["continuum"] for s in ends)
    assert ends[0]["Lambda"] == pytest.approx(-F2) and ends[1]["Lambda"] == 0
    for weight in np.linspace(0, 1, 5):  # every point of the segment solves the problem
        point = {
            key: (1 - weight) * ends[0][key] + weight * ends[1][key]
            for key in ("U_T", "U_N", "lambda_N", "lambda_T", "Lambda")
        }
        point.update(
            regime="stick" if weight == 0 else "left slip",
            displacement=(1 - weight) * np.array(ends[0]["displacement"])
            + weight * np.array(ends[1]["displacement"]),
            contact_force=(1 - weight) * np.array(ends[0]["contact_force"])
            + weight * np.array(ends[1]["contact_force"]),
        )
        assert_discrete_coulomb(point, F1, F2, friction, stiffness, LENGTH)


def test_unique_at_critical_friction_off_the_continuum_line():
    friction = hild_critical_friction(NU)
    stiffness = stiffness_of_A(E, NU, LENGTH)
    for F1, F2 in np.random.default_rng(3).normal(size=(200, 2)):
        solutions = hild_one_triangle_solutions(F1, F2, friction, E, NU, LENGTH)
        assert len(solutions) == 1 and not solutions[0]["continuum"]
        assert_discrete_coulomb(solutions[0], F1, F2, friction, stiffness, LENGTH)


def test_paper_closed_forms_in_the_four_regimes():
    lam, mu = lame_plane_strain(E, NU)
    friction = 0.5
    separation = hild_one_triangle_solutions(1.0, 2.0, friction, E, NU, LENGTH)[0]
    assert separation["regime"] == "separation"
    assert separation["U_N"] == pytest.approx(
        LENGTH * ((lam + mu) * 1.0 - (lam + 3 * mu) * 2.0) / (4 * mu * (lam + 2 * mu))
    )
    stick = hild_one_triangle_solutions(0.3, -1.0, friction, E, NU, LENGTH)[0]
    assert (stick["regime"], stick["U_T"], stick["Lambda"]) == ("stick", 0.0, 1.0)
    right = hild_one_triangle_solutions(2.0, -1.0, friction, E, NU, LENGTH)[0]
    assert right["regime"] == "right slip" and right["displacement"][0] > 0
    assert right["U_T"] == pytest.approx(
        -LENGTH * (friction * -1.0 + 2.0) / (lam + 3 * mu + friction * (lam + mu))
    )
    left = hild_one_triangle_solutions(-2.0, -2.0, friction, E, NU, LENGTH)[0]
    assert left["regime"] == "left slip" and left["displacement"][0] < 0
    assert left["U_T"] == pytest.approx(
        LENGTH * (friction * -2.0 + 2.0) / (lam + 3 * mu - friction * (lam + mu))
    )


def test_zero_load_gives_the_rest_state():
    (solution,) = hild_one_triangle_solutions(0.0, 0.0, 5.0, E, NU, LENGTH)
    assert solution["regime"] == "stick" and solution["U_T"] == solution["U_N"] == solution["lambda_N"] == 0
