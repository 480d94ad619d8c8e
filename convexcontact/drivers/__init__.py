"""Drivers: the prepared model (:mod:`.prepared`; ``auto``'s formulation and solver rules in :mod:`.rules`) and what
runs it — the Picard map for Coulomb laws, load histories (:mod:`.history_run`), the search for every solution — with
:func:`.solve.solve` choosing among them.

Importing :mod:`.picard` here registers Coulomb's driver with :class:`.prepared.Model`, importing
:mod:`.plastic_history` the plastic bodies' steps with :func:`.history_run.run`.
"""

from . import picard, plastic_history  # noqa: F401  (register the Coulomb driver and the plastic steps)
