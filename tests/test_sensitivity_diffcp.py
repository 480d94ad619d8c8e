"""Exact sensitivities against diffcp (docs/sensitivity.md): the primal conic program the project builds, posed
in cvxpy with its parameter-dependent data as Parameters (DPP), solved by SCS through diffcp and differentiated
by ``Problem.derivative``; the displacement's derivative agrees with ``cc.sensitivity``'s.

The data q and b are affine in the parameters here (a slip bound, the obstacle's depth), so their derivatives are
exact differences of the programs at θ ± h; the recovery of u from x is affine too, so u's derivative is the
difference of two recoveries. Tolerance: SCS is asked for 1e-12 (absolute and relative) and reached it on these
programs (the answers agree with the polished dual's to ≤ 1e-12, asserted); diffcp's dense derivative is then that
of the KKT system at an answer that close, so agreement to DERIVATIVE (1e-8; measured 2e-13 – 1.3e-11) leaves
three orders for the solver's error without hiding an error of the derivative (a wrong active set or a missing
term moves it by O(1)). diffcp's default LSQR derivative (cvxpy's without ``mode``) was off by 6e-3 – 0.12 on
the same programs; SCS stalled at 2–3e-10 (optimal_inaccurate after 10⁵ iterations) on the 8 × 4 mesh."""

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.conic import ConicSolution
from convexcontact.drivers.prepared import formulate

cp = pytest.importorskip("cvxpy")
pytest.importorskip("diffcp")

SCS = {"eps_abs": 1e-12, "eps_rel": 1e-12, "max_iters": 10_000, "mode": "dense"}
"""SCS's tolerances through diffcp (reached in 100–300 iterations here), and diffcp's direct (dense) derivative
rather than LSQR's iterative one."""

ANSWER = 1e-10
"""Largest difference of SCS's displacement from the polished dual's, over its largest component."""

DERIVATIVE = 1e-8
"""Largest difference of diffcp's derivative of the displacement from cc.sensitivity's, over its largest
component (see the module's docstring)."""


CONES = {"zero": lambda part: part == 0, "nonnegative": lambda part: part >= 0,
         "soc": lambda part: cp.SOC(part[0], part[1:])}
"""The constraint s ∈ K of each cone kind the primal programs here use, for the slack s = b − Ax."""


def cvxpy_problem(program):
    """The conic program min ½xᵀPx + qᵀx, b − Ax ∈ K as a DPP cvxpy problem with q and b Parameters; ½xᵀPx as
    ½‖Lx‖² with LᵀL = P (P is only positive semidefinite: its friction epigraph variables carry no stiffness)."""
    x = cp.Variable(program.q.size)
    q, b = cp.Parameter(program.q.size, value=program.q), cp.Parameter(program.b.size, value=program.b)
    eigenvalues, vectors = np.linalg.eigh(program.P.toarray())
    kept = eigenvalues > 1e-12 * eigenvalues.max()
    L = np.sqrt(eigenvalues[kept])[:, None] * vectors[:, kept].T
    slack = b - program.A @ x
    constraints = [CONES[cone.kind](slack[rows]) for cone, rows in program.blocks()]
    return cp.Problem(cp.Minimize(0.5 * cp.sum_squares(L @ x) + q @ x), constraints), x, q, b


def data_rates(model, parameter: str, value: float, step: float):
    """(dq, db) per unit of the parameter: central differences of the programs at the model's units (a scene of its
    own would scale them by its own data), exact for data affine in it (asserted: P and A do not move)."""
    fem = model.fem
    ends = [formulate(fem.at(cc.with_parameter(fem.scene, parameter, value + sign * step)), "primal", {}).program
            for sign in (1, -1)]
    assert abs(ends[0].P - ends[1].P).max() == 0 and abs(ends[0].A - ends[1].A).max() == 0
    return (ends[0].q - ends[1].q) / (2 * step), (ends[0].b - ends[1].b) / (2 * step)


def displacement_rate(model, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """du (free DOFs, scaled) of the solver's dx: the recovery is affine in x, so a difference of two is exact."""
    zeros = np.zeros(model.program.b.size)

    def u(at):
        return model.recover(ConicSolution(at, zeros, zeros, "solved", "", 0, 0.0, "scs")).u

    return (u(x + dx) - u(x - dx)) / 2


def block(law, ux: float):
    """A 2 × 1 block (6 × 3 cells) held at its top, moved sideways by ux, pressed from below by a parabolic rigid
    obstacle (R = 8, depth 0.05): 3 of its 7 contact nodes closed, 4 open."""
    return cc.Scene(name="block", body=cc.Body(cc.Rectangle(width=2.0, height=1.0, nx=6, ny=3)),
                    materials=cc.Material(E=1.0, nu=0.3), dirichlet=(cc.Dirichlet("top", ux=ux, uy=0.0),),
                    contact=cc.Contact("bottom", cc.Obstacle("parabolic", radius=8.0, depth=0.05), law))


@pytest.mark.parametrize("law, ux, statuses, parameters", [
    (cc.Signorini(), 0.0, {"closed", "open"}, {"obstacle.depth": 1e-3, "dirichlet[top].uy": 1e-3}),
    (cc.Tresca(slip_bound=0.01), 0.01, {"slip-", "stick", "open"}, {"slip_bound": 1e-4, "dirichlet[top].ux": 1e-3})],
    ids=["signorini", "tresca"])
def test_derivatives_agree_with_diffcp(law, ux, statuses, parameters):
    scene = block(law, ux)
    result = cc.solve(scene, formulation="dual", solver="newton-cg")
    assert result.certificate.worst < 1e-12
    assert set(result.contact.status) == statuses  # an active set with a node of every kind
    model = cc.prepare(scene, "primal")
    problem, x, q, b = cvxpy_problem(model.program)
    problem.solve(requires_grad=True, **SCS)
    assert problem.status == "optimal"
    fem = result.fem
    polished = result.displacement[fem.free] / fem.scaling.displacement
    answer = model.recover(ConicSolution(x.value, np.zeros(b.size), np.zeros(b.size), "solved", "", 0, 0.0, "scs")).u
    assert np.abs(answer - polished).max() <= ANSWER * np.abs(polished).max()
    found = cc.sensitivity(result, list(parameters))
    for parameter, step in parameters.items():
        q.delta, b.delta = data_rates(model, parameter, found[parameter].value, step)
        problem.derivative()
        rate = displacement_rate(model, x.value, x.delta)
        exact = found[parameter].derivative.displacement[fem.free] / fem.scaling.displacement
        assert np.abs(rate - exact).max() <= DERIVATIVE * np.abs(exact).max(), parameter
