"""Scene → FE model → formulation → solver → result, with a timing for every stage."""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field

from .. import solvers
from ..conic import ConicProgram, ConicSolution, Recovery
from ..fem.assembly import FEModel, assemble
from ..formulations import contact_weights, signorini
from ..results.certificate import certify
from ..results.result import ContactResult, contact_nodes
from ..scene.model import Scene


@contextmanager
def timed(timings: dict, stage: str):
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


@dataclass
class Model:
    """An assembled and formulated scene, ready to solve with any solver.

    ``program`` is the ConicProgram in scaled units (see ``fem.scaling``);
    :meth:`cvxpy` gives the editable cvxpy model of it.
    """

    fem: FEModel
    program: ConicProgram
    recover: Recovery
    timings: dict = field(default_factory=dict)

    @property
    def contact_weights(self):
        return contact_weights(self.fem.contact, self.fem.scene.contact.law.non_penetration)

    def cvxpy(self) -> solvers.cvxpy_model.CvxpyModel:
        """The cvxpy Problem of this model, to inspect or extend before :meth:`solve`."""
        return solvers.cvxpy_model.model(self.program)

    def solve(self, solver: str = "clarabel", **options) -> ContactResult:
        """Solve with ``solver`` (clarabel, osqp, cvxpy, cvxpy:NAME) and certify the answer.

        ``options`` go to the solver adapter (``tol``, ``max_iter``, ``verbose``,
        native settings; ``cvxpy_model`` for an extended cvxpy model).
        """
        timings = dict(self.timings)
        with timed(timings, "solve"):
            solution = solvers.solve(self.program, solver, **options)
        with timed(timings, "postprocess"):
            result = self.result(solution, timings)
        return result

    def result(self, solution: ConicSolution, timings: dict) -> ContactResult:
        fem, C = self.fem, self.contact_weights
        common = {
            "fem": fem,
            "solver": solution.solver,
            "solver_status": solution.solver_status,
            "iterations": solution.iterations,
            "timings": timings,
            "contact_weights": C,
        }
        if not solution.solved:
            return ContactResult(
                status=solution.status,
                certificate=None,
                displacement=None,
                contact=None,
                message=failure_message(solution),
                **common,
            )
        fields = self.recover(solution)
        certificate = certify(fem.K, fem.f, fem.contact, C, fields)
        scaling = fem.scaling
        return ContactResult(
            status=solution.status,
            certificate=certificate,
            displacement=fem.full(fields.u) * scaling.displacement,
            contact=contact_nodes(fem, fields),
            obstacle_advance=fields.obstacle_advance * scaling.displacement
            if fem.contact.obstacle_coupling is not None
            else None,
            **common,
        )


def failure_message(solution: ConicSolution) -> str:
    hints = {
        "infeasible": "the obstacle penetrates nodes whose displacement is prescribed: "
        "check the gap against the Dirichlet data on the contact boundary",
        "unbounded": "the body can move rigidly along a direction the contact does not hold: add Dirichlet conditions",
    }
    hint = hints.get(solution.status, "try another solver, a looser tol, or more iterations (max_iter)")
    return f"{solution.solver} returned {solution.solver_status}: {hint}"


def prepare(scene: Scene) -> Model:
    """Assemble and formulate ``scene``."""
    timings: dict = {}
    with timed(timings, "assembly"):
        fem = assemble(scene)
    with timed(timings, "formulation"):
        law = scene.contact.law
        program, recover = signorini(fem.K, fem.f, fem.contact, law.non_penetration)
    return Model(fem, program, recover, timings)


def solve(scene: Scene, solver: str = "clarabel", **options) -> ContactResult:
    """Solve ``scene`` exactly with ``solver``; see :meth:`Model.solve`."""
    solvers.check_name(solver)
    return prepare(scene).solve(solver, **options)
