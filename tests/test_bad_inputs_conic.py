"""A ConicProgram built by hand (the one interface a user can feed to the solvers directly) refuses data that is not
a convex program in Clarabel's form, naming the field and the fix, before any solver sees it."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from hypothesis import given
from hypothesis import strategies as st

import convexcontact as cc
from convexcontact.conic import Cone, ConicProgram, dense_matrix, nonnegative, soc

SURFACES = ("cc.ConicProgram",)  # and convexcontact.conic.dense_matrix, which ConicProgram's message names


def program(**fields) -> ConicProgram:
    """A sound program (min ½‖x‖² − x₁ over x ≥ 0) with ``fields`` replaced."""
    data = {"P": sp.eye(2, format="csc"), "q": np.array([-1.0, 0.0]), "A": -sp.eye(2, format="csc"),
            "b": np.zeros(2), "cones": (nonnegative(2),)}
    return ConicProgram(**(data | fields))


def test_the_sound_program_is_solved_to_its_closed_form():
    solution = cc.solvers.solve(program(), "clarabel")
    assert solution.status == "solved" and np.allclose(solution.x, [1.0, 0.0], atol=1e-8)


@pytest.mark.parametrize("fields, message", [
    ({"q": [-1.0, 0.0]}, "ConicProgram.q: expected a 1-D numpy array"),
    ({"q": np.zeros((2, 1))}, "ConicProgram.q: expected a 1-D numpy array"),
    ({"q": np.array(["a", "b"])}, "ConicProgram.q: expected a 1-D numpy array"),
    ({"b": 0.0}, "ConicProgram.b: expected a 1-D numpy array"),
    ({"P": np.eye(2)}, "ConicProgram.P: expected a scipy.sparse matrix"),
    ({"A": -np.eye(2)}, "ConicProgram.A: expected a scipy.sparse matrix"),
    ({"P": sp.eye(3, format="csc")}, "ConicProgram: shapes P (3, 3)"),
    ({"A": -sp.eye(3, 2, format="csc")}, "ConicProgram: shapes"),
    ({"cones": [nonnegative(2)]}, "ConicProgram.cones: expected a tuple of Cone"),
    ({"cones": ("nonnegative",)}, "ConicProgram.cones: expected a tuple of Cone"),
    ({"cones": (nonnegative(1),)}, "ConicProgram.cones: dimensions add up to 1, not to the 2 rows"),
    ({"q": np.array([np.nan, 0.0])}, "ConicProgram.q: holds NaN or inf"),
    ({"b": np.array([0.0, np.inf])}, "ConicProgram.b: holds NaN or inf"),
    ({"P": sp.csc_matrix(np.array([[1.0, np.nan], [np.nan, 1.0]]))}, "ConicProgram.P: holds NaN or inf"),
    ({"A": sp.csc_matrix(np.array([[-np.inf, 0.0], [0.0, -1.0]]))}, "ConicProgram.A: holds NaN or inf"),
    ({"P": sp.csc_matrix(np.array([[1.0, 0.5], [0.0, 1.0]]))}, "ConicProgram.P: not symmetric"),
    ({"P": dense_matrix(np.array([[1.0, 0.5], [0.0, 1.0]]))}, "ConicProgram.P: not symmetric"),
    ({"P": dense_matrix(np.array([[1.0, np.inf], [np.inf, 1.0]]))}, "ConicProgram.P: holds NaN or inf"),
    ({"gradient": np.zeros(2)}, "ConicProgram.gradient: expected a function"),
])
def test_a_program_that_is_not_one_is_refused_by_name(fields, message):
    with pytest.raises(ValueError) as error:
        program(**fields)
    assert str(error.value).startswith(message), error.value


@pytest.mark.parametrize("build, message", [
    (lambda: Cone("cone", 2), "Cone.kind: must be one of"),
    (lambda: Cone("soc", 1), "Cone.dim: a soc cone has dimension ≥ 2"),
    (lambda: Cone("nonnegative", 0), "Cone.dim: a nonnegative cone has dimension ≥ 1"),
    (lambda: Cone("nonnegative", 2.0), "Cone.dim: expected an integer"),
    (lambda: Cone("zero", True), "Cone.dim: expected an integer"),
    (lambda: Cone("power", 3, 1.5), "a power cone has dimension 3 and 0 < alpha < 1"),
])
def test_a_cone_that_is_not_one_is_refused_by_name(build, message):
    with pytest.raises(ValueError, match=message):
        build()


@given(st.floats(min_value=1e-6, max_value=1e6), st.integers(min_value=2, max_value=30), st.integers(0, 2**31))
def test_any_asymmetry_above_round_off_is_found(skew, size, seed):
    """The randomized test of symmetry finds a skew part of any size and pattern, and passes symmetric matrices."""
    rng = np.random.default_rng(seed)
    S = sp.random(size, size, density=0.5, random_state=rng)
    P = (S @ S.T + sp.eye(size)).tocsc()
    i, j = rng.choice(size, 2, replace=False)
    E = sp.csc_matrix(([skew * max(abs(P).max(), 1.0)], ([i], [j])), shape=(size, size))
    assert ConicProgram(P, np.zeros(size), sp.csc_matrix((0, size)), np.zeros(0), ()).n_variables == size
    with pytest.raises(ValueError, match="not symmetric"):
        ConicProgram(P + E, np.zeros(size), sp.csc_matrix((0, size)), np.zeros(0), ())


@pytest.mark.parametrize("W", [[[1.0, 0.0], [0.0, 1.0]], np.ones(4), np.ones((2, 3)),
                               np.array([["1", "0"], ["0", "1"]]), sp.eye(2)])
def test_a_dense_p_that_is_not_a_square_array_is_refused_by_name(W):
    with pytest.raises(ValueError, match="dense_matrix: expected a square 2-D numpy array of numbers"):
        dense_matrix(W)


@pytest.mark.parametrize("solver", ["clarabel", "osqp", "cvxpy", "newton-cg"])
def test_a_dense_p_is_solved_to_the_closed_form_by_every_solver(solver):
    """P held as one dense block (the dual's W) is read by each adapter as the matrix it is."""
    solution = cc.solvers.solve(program(P=dense_matrix(np.eye(2))), solver)
    assert solution.status == "solved" and solution.x == pytest.approx([1.0, 0.0], abs=1e-8)


def test_an_operator_for_p_is_a_program():
    """P may be an operator (matrix-free duals): products only, so it is taken as given."""
    operator = program(P=spla.aslinearoperator(sp.eye(2)))
    assert cc.solvers.solve(operator, "newton-cg").x == pytest.approx([1.0, 0.0], abs=1e-10)


def test_a_second_order_cone_program_with_sound_data_is_solved():
    """min t subject to (t, 3, 4) ∈ SOC: t = ‖(3, 4)‖ = 5."""
    A = sp.csc_matrix(np.array([[-1.0], [0.0], [0.0]]))
    solution = cc.solvers.solve(ConicProgram(sp.csc_matrix((1, 1)), np.array([1.0]), A, np.array([0.0, 3.0, 4.0]),
                                             (soc(3),)), "clarabel")
    assert solution.status == "solved" and solution.x[0] == pytest.approx(5.0, rel=1e-8)


@pytest.mark.parametrize("data, message", [
    ({"q": np.array([np.nan, 0.0])}, "ConicProgram.q: holds NaN or inf"),
    ({"q": np.zeros(3)}, "ConicProgram: shapes"),
    ({"b": [0.0, 0.0]}, "ConicProgram.b: expected a 1-D numpy array"),
])
def test_updated_data_is_checked_as_new_data(data, message):
    """``ConicProgram.updated`` (a session's new load) refuses what the constructor refuses."""
    with pytest.raises(ValueError) as error:
        program().updated(**data)
    assert str(error.value).startswith(message), error.value


def test_updated_keeps_the_own_gradient_for_its_q_only():
    """The formulation's gradient holds for the program's own q: kept with the same q or a new b, dropped with a new
    q (else a solver would read the gradient of another load)."""
    sound = program(gradient=lambda x: x + np.array([-1.0, 0.0]))
    assert sound.updated(b=np.ones(2)).gradient is sound.gradient
    assert sound.updated(q=sound.q.copy()).gradient is sound.gradient
    assert sound.updated(q=np.array([0.0, -1.0])).gradient is None
