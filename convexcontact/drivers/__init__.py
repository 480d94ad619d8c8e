"""Drivers: the prepared model (:mod:`.prepared`; ``auto``'s formulation and solver rules in :mod:`.rules`) and what
runs it — the Picard map for Coulomb laws, load histories (:mod:`.history_run`), the search for every solution — with
:func:`.solve.solve` choosing among them.

Importing :mod:`.picard` here registers Coulomb's driver with :class:`.prepared.Model`.
"""

from . import picard  # noqa: F401  (registers the Coulomb driver)
