"""The prepared model: scene → FE model → formulation, ready for any solver; a timing for every stage.

The drivers build on it: :mod:`.picard` (Coulomb), :mod:`.history_run` (load histories),
:mod:`.solutions` (every solution); :mod:`.solve` is the entry point that picks one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..conic import ConicProgram, ConicSolution, Recovery
from ..fem.assembly import FEModel, assemble
from ..fem.coarse import body_far_functions
from ..fem.factorization import Condensation, Delassus, Factorization, condense, dual_factors, factorize
from ..fem.friction import FrictionPoints, friction_points
from ..formulations import FORMULATIONS, contact_weights
from ..formulations.dual import contact_rows, stick_guess
from ..results.certificate import certify
from ..results.result import ContactResult, contact_nodes, not_unique
from ..scene.description import (
    Coulomb,
    PerPair,
    Scene,
    SceneError,
    Tresca,
    compliance_of,
    evaluate_field,
    field_at_nodes,
    has_friction,
    of_type,
)
from .rules import DENSE_NEWTON, MATRIX_FREE, choose_formulation, contact_columns, dense_newton, matrix_free_obstruction
from .scales import check_force, check_gap_scale, check_law_scales

LAW_DRIVERS: dict[type, Callable] = {}
"""Drivers of the laws that are no single convex program, registered by their modules (:mod:`.picard`
registers Coulomb's Picard map): :meth:`Model.solve` hands such a law to its driver."""


@contextmanager
def timed(timings: dict, stage: str):
    start = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def field_at_points(value, name: str, fem: FEModel, friction: FrictionPoints) -> np.ndarray:
    """A law's field (constant, formula, callable, nodal array, or one of these per contact pair) at the
    friction points, user units."""
    if isinstance(value, (np.ndarray, PerPair)):
        nodal = field_at_nodes(value, name, fem.contact.coords * fem.scaling.length, getattr(fem.contact, "pieces", ()))
        return friction.interpolation @ nodal
    return evaluate_field(value, name, friction.coords * fem.scaling.length)  # x, y[, z] columns


def law_fields(law, fem: FEModel, friction: FrictionPoints | None, slip_bound) -> dict[str, np.ndarray]:
    """The friction law's fields at the friction points for :func:`check_law_scales`: Tresca's slip bound and
    Coulomb's initial pressure over the pressure scale, Coulomb's coefficient as it is."""
    if isinstance(law, Tresca):
        return {"slip_bound": slip_bound}
    if not isinstance(law, Coulomb):
        return {}
    fields = {"friction": field_at_points(law.friction, "contact.friction", fem, friction)}
    if law.initial_pressure is not None:
        fields["initial_pressure"] = field_at_points(law.initial_pressure, "contact.initial_pressure", fem,
                                                     friction) / fem.scaling.pressure
    return fields


def frictional_rows(law, contact) -> np.ndarray | None:
    """The contact nodes that carry friction: those of the frictional pairs when pairs have laws of their own
    (a :class:`PerPair` field), every node (None) otherwise."""
    value = law.friction if isinstance(law, Coulomb) else law.slip_bound
    if not isinstance(value, PerPair):
        return None
    return np.concatenate([np.arange(contact.m)[rows] for (rows, *_), part in zip(contact.pieces, value.values)
                           if part is not None])


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
    reason: str = "chosen by the user"  # why this formulation runs (see choose_formulation)
    condensation: Reused | None = None  # K condensed onto Γ_C (dual), kept for with_law
    cache: dict = field(default_factory=dict)  # results that do not depend on the law's coefficients

    @property
    def law(self):
        return self.fem.scene.contact.law

    def with_law(self, law) -> Model:
        """This model under another contact law, for sweeps (F, slip bounds, ε): the assembly,
        the contact trace and K's condensation are reused; only the program is rebuilt."""
        formulation = MATRIX_FREE if solvers.matrix_free(self.program) else self.formulation
        model = formulate(self.fem.with_law(law), formulation, {}, self.condensation, self.reason)
        model.cache = self.cache  # shared: the frictionless first Picard step is the same for every law
        return model

    def cvxpy(self) -> solvers.cvxpy_model.CvxpyModel:
        """The cvxpy Problem of this model, to inspect or extend before :meth:`solve`."""
        if solvers.matrix_free(self.program):
            raise SceneError("formulation", f"{MATRIX_FREE!r} applies W = B K⁻¹ Bᵀ through K's factorization and never "
                             "forms it, and a cvxpy model needs the matrix",
                             "prepare(scene, 'dual') (W formed) or prepare(scene, 'primal') for the cvxpy model")
        return solvers.cvxpy_model.model(self.program)

    def solve(self, solver: str = "auto", progress: Callable | None = None, **options) -> ContactResult:
        """Solve with ``solver`` (auto, clarabel, osqp, cvxpy, cvxpy:NAME, newton-cg) and certify the answer;
        "auto" is newton-cg on a matrix-free program, clarabel on any other, after newton-cg on a dense dual in its
        bound form (see :func:`dense_newton`; ``result.extra["solver_reason"]`` says which answered).

        ``options`` go to the solver adapter (``tol``, ``max_iter``, ``verbose``,
        native settings; ``cvxpy_model`` for an extended cvxpy model). Coulomb laws
        run the Picard map; ``progress(iteration, change)`` is called after each step.
        """
        solvers.check_options({**options, "progress": progress}, solvers.check_name(solver))
        driver = LAW_DRIVERS.get(type(self.law))
        if driver is not None:
            return driver(self, solver, progress, **options)
        timings = dict(self.timings)
        gauss = getattr(self.law, "non_penetration", None) == "gauss" and compliance_of(self.law) is None
        if gauss and solver in ("auto", "clarabel") and "tol" not in options:  # auto: Clarabel here (P is a matrix)
            # more touching points than nodes: an active set the polish cannot settle (dependent rows), so
            # the interior point must be accurate on its own (1e-10: certificate 1e-6; 1e-12: 1e-15)
            options = {**options, "tol": GAUSS_TOL}
        result = ProgramSession(solver, options).solve(self, timings, extended=options.get("cvxpy_model") is not None)
        if not result.solved and solver == "auto" and solvers.matrix_free(self.program) and self.reason != CHOSEN:
            # newton-cg converges, but its step bound can exceed max_iter (the two-body Tresca dual at 10⁵ DOFs
            # applied matrix-free: 100 steps, residual 9e-5; docs/performance.md): what auto chose gives way to
            # the sparse primal, which Clarabel solves
            reason = f"{self.reason}; newton-cg failed ({result.solver_status}), so the sparse primal instead"
            return formulate(self.fem, "primal", dict(self.timings), reason=reason).solve(solver, progress, **options)
        return result

    def frictionless(self, solver: str, options: dict) -> tuple[ConicSolution, Recovery]:
        """The answer of this model's frictionless program and its recovery map, kept in the cache:
        the same for every friction law of a sweep (:meth:`with_law`)."""
        key = ("frictionless", solver, repr(sorted(options.items())))
        if key not in self.cache:
            program, recover, _ = self.build(None, None, None, replace(self.fem.contact, tangential_coupling=None))
            self.cache[key] = (solvers.solve(program, solver, **options), recover)
        return self.cache[key]

    def seed(self, session, solver: str, options: dict, start: dict | None = None):
        """Start a friction solve from the frictionless answer (every point sticking): the polish's
        rounds from there replace an interior point on m·d unknowns by one on m (a 3-D Tresca punch,
        1452 unknowns: 0.17 + 0.72 s against 2.06 s), and an interior point still runs if they fail.
        ``start``: options of a frictionless solve made only for a start (any solver is then seeded).
        Dual only, whose layout the guess needs."""
        if self.formulation != "dual" or self.friction is None:
            return
        if start is not None or solvers.seedable(solver, options, self.program):
            frictionless, _ = self.frictionless(solver, options if start is None else start)
            if frictionless.solved:
                session.seed(stick_guess(self.program, frictionless, self.fem.contact))

    def result(
        self, solution: ConicSolution, timings: dict, slip_bound, fields=None, extra=None, extended=False
    ) -> ContactResult:
        """Certified result of a solution (``fields`` when already recovered).

        ``extended``: the user added to the cvxpy model, so the certificate (which checks
        the scene's own contact conditions) may rightly fail; the status is left as is.
        """
        fem = self.fem
        if self.formulation == "dual":  # by weak duality an unbounded dual is an infeasible primal, and back
            swapped = {"unbounded": "infeasible", "infeasible": "unbounded"}
            solution = replace(solution, status=swapped.get(solution.status, solution.status))
        common = {
            "fem": fem,
            "solver": solution.solver,
            "solver_status": solution.solver_status,
            "iterations": solution.iterations,
            "timings": timings,
            "formulation": self.formulation,
            "extra": {"formulation_reason": self.reason, **(extra or {})},
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
            condensation=kept_for(self.condensation, fem),
            not_unique=not_unique(fem, fields, self.friction, self.law),
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
    if solution.status == "inaccurate" and passes:
        return "inaccurate", (f"{solution.solver} stopped short of its own tolerance ({solution.solver_status} after "
                              f"{solution.iterations} iterations); the certificate passes (worst "
                              f"{certificate.worst:.1e} ≤ {CERTIFIED:g})")
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


GAUSS_TOL = 1e-12
"""Clarabel's default tolerance for Gauss-point non-penetration (see :meth:`Model.solve`)."""


class ProgramSession:
    """The solver session of a model's program, kept across updates of its q and b (a load history's steps): the
    named solver's, seeded from the frictionless answer; left to ``auto`` on a dense dual, newton-cg's until it
    does not answer (:func:`dense_newton`), Clarabel's from then on."""

    def __init__(self, solver: str, options: dict):
        self.solver, self.options = solver, options
        self.session, self.newton, self.reason = None, False, None
        self.newton_allowed = solver == "auto" and not options

    def solve(self, model: Model, timings: dict, extended: bool = False) -> ContactResult:
        """The certified result of the model's program, from the last answer where the session is kept."""
        while True:
            with timed(timings, "solve"):
                if self.session is None:
                    self._open(model)
                else:
                    self.session.update(q=model.program.q, b=model.program.b)
                solution = self.session.solve()
            with timed(timings, "postprocess"):
                result = model.result(solution, timings, model.slip_bound, extra=self.reason, extended=extended)
            if result.solved or not self.newton:
                return result
            self.session, self.newton_allowed = None, False
            self.reason = {"solver_reason": f"newton-cg {solution.solver_status} after {solution.iterations} Newton "
                                            f"steps on the dense dual, so Clarabel"}

    def _open(self, model: Model):
        newton = dense_newton(model.formulation, model.program, model.law) if self.newton_allowed else None
        self.newton = newton is not None
        if self.newton:
            self.session, self.reason = newton, {"solver_reason": DENSE_NEWTON}
        else:
            self.session = solvers.session(model.program, self.solver, **self.options)
            model.seed(self.session, self.solver, self.options)


def check_formulation(scene: Scene, formulation: str, solver: str = "auto") -> None:
    """Refuse, before any assembly, a formulation the scene (or the ``solver``) cannot have, naming the ones it can."""
    check_formulation_name(formulation)
    if scene.history is None and any(getattr(m, "plastic", False) for m in (
            scene.materials.values() if isinstance(scene.materials, dict) else (scene.materials,))):
        raise SceneError("history", "a plastic body (a material with yield_stress) has no static answer: its state "
                         "depends on the loading path", "give the scene a history (one step loads it at once) and "
                         "run it with cc.run_history (docs/plasticity.md), or drop yield_stress")
    if formulation == MATRIX_FREE and solver.partition(":")[0] not in ("auto", "newton-cg"):
        raise SceneError("formulation", f"{MATRIX_FREE!r} applies W as an operator, which only newton-cg solves, "
                         f"and solver = {solver!r} needs it as a matrix",
                         f"use formulation='dual', 'primal' or 'auto' with {solver}, or solver='newton-cg'")
    law = scene.contact.law
    if formulation == "dual" and compliance_of(law) is not None:
        raise SceneError("formulation", "'dual': normal compliance is posed in the primal only",
                         "use formulation='primal' or 'auto'")
    obstruction = matrix_free_obstruction(scene.contact.obstacle, law) if formulation == MATRIX_FREE else None
    if obstruction is not None:
        usable = "'primal' or 'auto'" if compliance_of(law) is not None else "'dual', 'primal' or 'auto'"
        raise SceneError("formulation", f"{MATRIX_FREE!r} takes the dual in newton-cg's bound form, and {obstruction}",
                         f"use formulation={usable}")


def prepare(scene: Scene, formulation: str = "auto") -> Model:
    """Assemble and formulate ``scene``.

    ``formulation``: "primal" (the sparse program over all DOFs), "dual" (condensed onto
    the contact multipliers with the Delassus operator), "dual-matrix-free" (the same dual with
    W applied through K's factorization, never formed; solved by newton-cg) or "auto", which
    picks one from the problem's shape and records why in ``Model.reason``.
    """
    of_type(scene, Scene, "scene", "build cc.Scene(...) or read a file with cc.load_scene(path)")
    check_formulation(scene, formulation)
    timings: dict = {}
    with timed(timings, "assembly"):
        fem = assemble(scene)
    return formulate(fem, formulation, timings)


def check_formulation_name(formulation, allowed=(*FORMULATIONS, MATRIX_FREE, "auto"), what: str = "") -> str:
    """Return ``formulation`` if it is one of ``allowed``, else a SceneError naming them (``what``: for which use)."""
    if not isinstance(formulation, str) or formulation not in allowed:
        known = isinstance(formulation, str) and formulation in (*FORMULATIONS, MATRIX_FREE, "auto")
        raise SceneError("formulation", f"{'' if known else 'unknown '}{formulation!r:.60}{what}",
                         f"use one of {', '.join(map(repr, allowed))}")
    return formulation


CHOSEN = "chosen by the user"
"""The reason of a formulation the user named (what the drivers never change)."""


def formulate(fem: FEModel, formulation: str, timings: dict, condensation=None, reason: str = CHOSEN):
    """The Model of an assembled scene (``condensation``: K's, when already built)."""
    if reason == CHOSEN:  # the user's choice, whichever driver passes it on (a history's too)
        check_formulation(fem.scene, formulation)
    with timed(timings, "formulation"):
        law = fem.scene.contact.law
        C = contact_weights(fem.contact, law.non_penetration)
        friction = slip_bound = epsilon = None
        if has_friction(law):
            friction = friction_points(fem.contact, fem.mesh, fem.basis, law.quadrature, law.non_penetration,
                                       frictional_rows(law, fem.contact))
            epsilon = None if law.regularization is None else law.regularization / fem.scaling.displacement
            slip_bound = (
                field_at_points(law.slip_bound, "contact.slip_bound", fem, friction) / fem.scaling.pressure
                if isinstance(law, Tresca) else np.zeros(friction.count)
            )
        compliance = None
        if compliance_of(law) is not None:
            c_N, p = compliance_of(law).stiffness, compliance_of(law).exponent
            compliance = (c_N * fem.scaling.displacement**p / fem.scaling.pressure, p)
        check_force(fem)
        check_gap_scale(fem)
        check_law_scales(fem, law, law_fields(law, fem, friction, slip_bound), compliance)

    def factored():  # K's condensation or factorization for the dual formulation chosen
        return condensation or condensed(fem, timings, formulation == MATRIX_FREE, contact_rows(fem.contact, C, friction))

    if formulation == "auto":
        unknowns = fem.contact.m + (friction.R.shape[0] if friction is not None else 0)
        formulation, reason = choose_formulation(fem, law, unknowns)
        if formulation != "primal":
            try:
                condensation = factored()
            except SceneError as error:
                if error.field != "dirichlet":
                    raise
                formulation, reason = "primal", "K is singular (the contact holds a rigid motion): nothing to condense"
    elif formulation != "primal":
        condensation = factored()
    options = {"factorization": condensation if isinstance(condensation, Reused) else Reused(condensation, fem.K),
               "matrix_free": formulation == MATRIX_FREE} if formulation != "primal" else {}
    if formulation == MATRIX_FREE:
        options["coarse"] = body_far_functions(fem)
    formulation = "dual" if formulation == MATRIX_FREE else formulation
    with timed(timings, "formulation"):

        def build(friction, slip_bound, epsilon, contact=fem.contact):
            return FORMULATIONS[formulation](fem.K, fem.f, contact, C, friction, slip_bound, epsilon, compliance,
                                             **options)

        program, recover, bound_update = build(friction, slip_bound, epsilon)
    return Model(fem, formulation, C, friction, slip_bound, program, recover, bound_update, build, epsilon,
                 compliance, timings, reason, options.get("factorization"))


class Reused:
    """K's factorization or condensation, keeping the last W = B K⁻¹ Bᵀ (dense, or as an operator with its slab
    approximation): a sweep over the law's coefficients rebuilds the dual program with the same B, and W is then not
    recomputed; nor is it for the frictionless program that seeds a friction solve, whose B = C N is the friction
    program's first rows (its W is the leading block, its slab approximation the same with G's first rows)."""

    def __init__(self, factorization: Factorization, K: sp.spmatrix):
        self.factorization, self.K = factorization, K  # K: the matrix factorized, by identity (kept_for)
        self._B, self._W, self._delassus = None, None, None

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.factorization.solve(b)

    def delassus(self, B: sp.spmatrix, K: sp.spmatrix | None = None, coarse=None) -> Delassus:
        kept = self._delassus
        if kept is not None and _leading(kept.B, B) and (K is None or kept.approximation is not None):
            m, approximation = B.shape[0], kept.approximation
            return Delassus(kept.B[:m], self.factorization.solve,
                            approximation and replace(approximation, G=approximation.G[:m]))
        self._delassus = self.factorization.delassus(B, K, coarse)
        return self._delassus

    def schur(self, B: sp.spmatrix) -> np.ndarray:
        B = sp.csr_matrix(B)
        if self._B is not None and _leading(self._B, B):
            if B.shape[0] == self._B.shape[0]:
                return self._W
            block = self._W[:B.shape[0], :B.shape[0]]
            block.flags.writeable = False  # a view of the kept W
            return block
        self._B, self._W = B, self.factorization.schur(B)
        return self._W


def kept_for(reused: Reused | None, fem: FEModel) -> Condensation | None:
    """The condensation of ``fem``'s own K that a dual solve built (what a result keeps for its derivatives), or
    None: no condensation (the primal; the matrix-free dual, whose factors of all of K are the large ones a result
    should not hold), or one of another K."""
    if reused is None or reused.K is not fem.K or not isinstance(reused.factorization, Condensation):
        return None
    return reused.factorization


def _leading(kept: sp.csr_matrix, B: sp.spmatrix) -> bool:
    """Whether ``B`` is the first rows of ``kept``."""
    B, m = sp.csr_matrix(B), B.shape[0]
    return B.shape[1] == kept.shape[1] and m <= kept.shape[0] and (kept[:m] != B).nnz == 0


def condensed(fem: FEModel, timings: dict, matrix_free: bool = False, rows: sp.spmatrix | None = None):
    """K condensed onto the contact DOFs (one sparse factorization; see :func:`~convexcontact.fem.factorization.condense`),
    or, given the dual's ``rows`` B, what :func:`~convexcontact.fem.factorization.dual_factors` forms W from; or only
    factorized for the matrix-free dual."""
    columns = contact_columns(fem)
    with timed(timings, "condensation"):
        if 0 < columns.size < fem.n_free and not matrix_free:
            return condense(fem.K, columns, dim=fem.dim) if rows is None else dual_factors(fem.K, columns, rows, fem.dim)
        return factorize(fem.K, dim=fem.dim)  # nothing to condense from or onto: W from K's factors
