"""Coulomb friction on elasto-viscoplastic bodies: within each step, the Picard map over the step's normal pressures
(:mod:`.picard`, as for elastic bodies), each inner problem the exact plastic Tresca step (docs/plasticity.md).

With the plastic state at the step's start fixed (α^old) and the slip measured from the last step (as the elastic
Coulomb histories do), the step is a quasi-variational inequality: the plastic Tresca step whose slip bound is
s = F λ_N of its own answer. :class:`PlasticTresca` gives the map that inner step — by Newton's method from the last
iterate where it applies, else by the conic program (:meth:`.plastic_history.PlasticStepper.answer`) — and the whole
certificate, the Coulomb law's (s = F λ_N at the answer) with the material's residuals.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..conic import ConicSolution
from ..formulations.fields import ContactFields
from .picard import InnerStep, coulomb
from .prepared import Model


class PlasticTresca(InnerStep):
    """The plastic Tresca step of a Coulomb step's ``model`` for given slip bounds, solved by ``stepper``."""

    name = "plastic"

    def __init__(self, stepper, model: Model, timings: dict):
        self.stepper, self.model, self.timings = stepper, model, timings
        self.start = stepper.start(model)  # the first inner step's guess: the last step's answer moved on
        self.fields: ContactFields | None = None
        self.paths: list[dict] = []  # each inner step's path ("newton" or "conic") and Newton steps

    def tresca(self, s: np.ndarray) -> Model:
        """The step's program under the slip bounds ``s`` (scaled)."""
        model = self.model
        return replace(model, slip_bound=s, program=replace(model.program, **model.bound_update(s)))

    def solve(self, s: np.ndarray) -> ConicSolution:
        model = self.tresca(s)
        _, solution, self.fields = self.stepper.answer(model, self.timings, *self.start)
        self.paths.append(solution.info["plastic"])
        if self.fields is not None:  # the next inner step starts from this one
            self.start = self.fields.u, self.stepper.multipliers(model, self.fields)
        return solution

    def open(self) -> None:
        """Nothing to open: each inner step poses its own plastic program."""

    def recover(self, solution: ConicSolution) -> ContactFields:
        return self.fields  # the inner step's own (Newton's, or the conic program's recovered)

    def residual(self, model: Model, fields: ContactFields, bound: np.ndarray) -> float:
        return self.stepper.residual(model, fields, bound)

    def result(self, solution: ConicSolution, timings: dict, bound: np.ndarray, fields, extra: dict):
        self.fields = fields
        return self.stepper.result(self.tresca(bound), solution, fields, timings, bound, extra)


def coulomb_step(stepper, model: Model, timings: dict):
    """The certified result of a plastic Coulomb step (``extra["picard"]`` the map's record, ``extra["history"]``
    every iterate's inner path and Newton steps beside the elastic map's entries)."""
    inner = PlasticTresca(stepper, model, timings)
    result = coulomb(model, stepper.solver, inner=inner, **stepper.options)
    for entry, path in zip(result.extra["history"], inner.paths):
        entry.update(path)
    return stepper.kept(result, inner.fields if result.status == "solved" else None)
