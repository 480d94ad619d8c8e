"""The entry point: one call that picks the driver a scene needs.

A static scene is prepared (:mod:`.prepared`) and solved — Coulomb laws through the Picard map of
:mod:`.picard`; a scene with a history runs it step by step (:mod:`.history_run`); ``solutions="all"``
lists every solution of a Coulomb scene (:mod:`.solutions`).
"""

from __future__ import annotations

from .. import solvers
from ..scene.description import Scene, SceneError, of_type
from .history_run import run
from .prepared import check_formulation, prepare
from .solutions import all_solutions


def solve(scene: Scene, solver: str = "auto", formulation: str = "auto", solutions: str = "one", confirm: bool = False,
          **options):
    """Solve ``scene`` exactly with ``solver``; see :meth:`~convexcontact.drivers.prepared.Model.solve`.

    Returns a :class:`~convexcontact.results.result.ContactResult`; for a scene with a history a
    :class:`~convexcontact.drivers.history_run.HistoryResult`; with ``solutions="all"`` (Coulomb) a
    :class:`~convexcontact.drivers.solutions.SolutionSet`: every solution, or as many as a search
    finds, each certified (docs/uniqueness.md). ``confirm=True`` runs a history or a search for every solution that
    is estimated to take long (both are refused otherwise, with the estimate).
    """
    of_type(scene, Scene, "scene", "build cc.Scene(...) or read a file with cc.load_scene(path)")
    solvers.check_name(solver)
    solvers.check_options(options, solver)  # before any assembly
    if solutions not in ("one", "all"):
        raise SceneError("solutions", f"got {solutions!r}", "use 'one' (the default) or 'all'")
    of_type(confirm, bool, "confirm", "give confirm=True to run a long history or search, else leave it out")
    if solutions == "all":
        if scene.history is not None:
            raise SceneError("solutions", "'all' lists the solutions of one static problem, not of a history",
                             "leave solutions to 'one' to run the history, or drop the history to list the solutions "
                             "of the static problem")
        return all_solutions(scene, solver, formulation, confirm, **options)
    if scene.history is not None:
        return run(scene, solver, formulation, confirm=confirm, **options)
    check_formulation(scene, formulation, solver)  # each driver above checks the formulations it takes
    return prepare(scene, formulation).solve(solver, **options)
