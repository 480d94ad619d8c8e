"""Scene → FE model → formulation → solver → result, with a timing for every stage."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..conic import ConicProgram, ConicSolution, Recovery
from ..fem.assembly import FEModel, assemble
from ..fem.factorization import StiffnessFactorization
from ..fem.friction import FrictionPoints, friction_points
from ..formulations import FORMULATIONS, contact_weights
from ..results.certificate import certify
from ..results.result import ContactResult, contact_nodes
from ..scene.model import Coulomb, Scene, SceneError, Tresca, compliance_of, evaluate_field, has_friction


@contextmanager
def timed(timings: dict, stage: str):
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def field_at_points(value, name: str, fem: FEModel, friction: FrictionPoints) -> np.ndarray:
    """A law's field (constant, formula, callable or nodal array) at the friction points, user units."""
    if isinstance(value, np.ndarray):
        nodal = evaluate_field(value, name, fem.contact.coords[:, 0], fem.contact.coords[:, 1])
        return friction.interpolation @ nodal
    x, y = (friction.coords * fem.scaling.length).T
    return evaluate_field(value, name, x, y)


@dataclass
class Model:
    """An assembled and formulated scene, ready to solve with any solver.

    ``program`` is the ConicProgram in scaled units (see ``fem.scaling``), built for
    ``slip_bound`` (Tresca's bound; for Coulomb, re-set by every Picard step through
    ``bound_update``). :meth:`cvxpy` gives the editable cvxpy model of it.
    """

    fem: FEModel
    formulation: str
    C: sp.spmatrix
    friction: FrictionPoints | None
    slip_bound: np.ndarray | None
    program: ConicProgram
    recover: Recovery
    bound_update: Callable
    build: Callable  # formulation with the FE data bound: (friction, slip_bound, epsilon, contact) → triple
    epsilon: float | None = None  # regularization of the friction term (scaled), None = exact
    compliance: tuple[float, float] | None = None  # (c_N, p) scaled, None = non-penetration
    timings: dict = field(default_factory=dict)

    @property
    def law(self):
        return self.fem.scene.contact.law

    def cvxpy(self) -> solvers.cvxpy_model.CvxpyModel:
        """The cvxpy Problem of this model, to inspect or extend before :meth:`solve`."""
        return solvers.cvxpy_model.model(self.program)

    def solve(self, solver: str = "clarabel", progress: Callable | None = None, **options) -> ContactResult:
        """Solve with ``solver`` (clarabel, osqp, cvxpy, cvxpy:NAME) and certify the answer.

        ``options`` go to the solver adapter (``tol``, ``max_iter``, ``verbose``,
        native settings; ``cvxpy_model`` for an extended cvxpy model). Coulomb laws
        run the Picard map; ``progress(iteration, change)`` is called after each step.
        """
        if isinstance(self.law, Coulomb):
            from .picard import coulomb

            return coulomb(self, solver, progress, **options)
        timings = dict(self.timings)
        with timed(timings, "solve"):
            solution = solvers.solve(self.program, solver, **options)
        with timed(timings, "postprocess"):
            result = self.result(solution, timings, self.slip_bound, extended=options.get("cvxpy_model") is not None)
        return result

    def result(
        self, solution: ConicSolution, timings: dict, slip_bound, fields=None, extra=None, extended=False
    ) -> ContactResult:
        """Certified result of a solution (``fields`` when already recovered).

        ``extended``: the user added to the cvxpy model, so the certificate (which checks
        the scene's own contact conditions) may rightly fail; the status is left as is.
        """
        fem = self.fem
        common = {
            "fem": fem,
            "solver": solution.solver,
            "solver_status": solution.solver_status,
            "iterations": solution.iterations,
            "timings": timings,
            "formulation": self.formulation,
            "extra": extra or {},
        }
        usable = solution.solved or (solution.status == "failed" and np.isfinite(solution.x).all()
                                     and np.isfinite(solution.z).all())
        if not usable:
            return ContactResult(status=solution.status, certificate=None, displacement=None, contact=None,
                                 message=failure_message(solution), **common)
        fields = fields or self.recover(solution)
        certificate = certify(fem.K, fem.f, fem.contact, self.C, fields, self.friction, slip_bound, self.epsilon,
                              self.compliance)
        status, message = judge(solution, certificate, extended)
        if status is None:
            return ContactResult(status=solution.status, certificate=certificate, displacement=None, contact=None,
                                 message=message, **common)
        scaling, contact = fem.scaling, fem.contact
        return ContactResult(
            status=status,
            message=message,
            certificate=certificate,
            displacement=fem.full(fields.u) * scaling.displacement,
            contact=contact_nodes(fem, fields, self.C, self.friction),
            obstacle_advance=fields.obstacle_advance * scaling.displacement
            if contact.obstacle_coupling is not None else None,
            obstacle_shift=fields.obstacle_shift * scaling.displacement
            if contact.tangential_coupling is not None else None,
            **common,
        )


CERTIFIED = 1e-6
"""A solve whose certificate is worse than this is reported as inaccurate, whatever the solver said."""


def judge(solution: ConicSolution, certificate, extended: bool) -> tuple[str | None, str]:
    """Our status and message from the solver's word and the certificate (None: no usable answer).

    A solver that stopped early (iterations, progress) is judged by its last iterate; a
    "solved" whose certificate fails is inaccurate; a user-extended model is a different
    problem than the scene's, so its certificate is reported but does not judge it.
    """
    passes = certificate.passes(CERTIFIED)
    if not solution.solved:
        if not passes:
            return None, failure_message(solution)
        return "inaccurate", (f"{solution.solver} stopped with {solution.solver_status}; its last iterate passes "
                              f"the certificate (worst {certificate.worst:.1e} ≤ {CERTIFIED:g})")
    if extended:
        return solution.status, "solved a user-extended cvxpy model: the certificate checks the scene's own conditions"
    if not passes:
        return "inaccurate", (f"{solution.solver} reported {solution.solver_status}, but the certificate's worst "
                              f"residual is {certificate.worst:.1e} > {CERTIFIED:g}: tighten tol, raise max_iter "
                              "or try another solver")
    return solution.status, ""


def failure_message(solution: ConicSolution) -> str:
    hints = {
        "infeasible": "the obstacle penetrates nodes whose displacement is prescribed: "
        "check the gap against the Dirichlet data on the contact boundary",
        "unbounded": "the body can move rigidly along a direction the contact does not hold: add Dirichlet conditions",
    }
    hint = hints.get(solution.status, "try another solver, a looser tol, or more iterations (max_iter)")
    return f"{solution.solver} returned {solution.solver_status}: {hint}"


def prepare(scene: Scene, formulation: str = "primal") -> Model:
    """Assemble and formulate ``scene``; ``formulation`` is "primal" or "dual" (Delassus)."""
    if formulation not in FORMULATIONS:
        raise SceneError("formulation", f"unknown {formulation!r}", f"use one of {sorted(FORMULATIONS)}")
    timings: dict = {}
    with timed(timings, "assembly"):
        fem = assemble(scene)
    with timed(timings, "formulation"):
        law = scene.contact.law
        C = contact_weights(fem.contact, law.non_penetration)
        friction = slip_bound = epsilon = None
        if has_friction(law):
            friction = friction_points(fem.contact, fem.mesh, fem.basis, law.quadrature, law.non_penetration)
            epsilon = None if law.regularization is None else law.regularization / fem.scaling.displacement
            slip_bound = (
                field_at_points(law.slip_bound, "contact.slip_bound", fem, friction) / fem.scaling.pressure
                if isinstance(law, Tresca) else np.zeros(friction.count)
            )
        compliance = None
        if compliance_of(law) is not None:
            c_N, p = compliance_of(law).stiffness, compliance_of(law).exponent
            compliance = (c_N * fem.scaling.displacement**p / fem.scaling.pressure, p)
        options = {"factorization": StiffnessFactorization(fem.K)} if formulation == "dual" else {}

        def build(friction, slip_bound, epsilon, contact=fem.contact):
            return FORMULATIONS[formulation](fem.K, fem.f, contact, C, friction, slip_bound, epsilon, compliance,
                                             **options)

        program, recover, bound_update = build(friction, slip_bound, epsilon)
    return Model(fem, formulation, C, friction, slip_bound, program, recover, bound_update, build, epsilon,
                 compliance, timings)


def solve(scene: Scene, solver: str = "clarabel", formulation: str = "primal", **options) -> ContactResult:
    """Solve ``scene`` exactly with ``solver``; see :meth:`Model.solve`."""
    solvers.check_name(solver)
    return prepare(scene, formulation).solve(solver, **options)
