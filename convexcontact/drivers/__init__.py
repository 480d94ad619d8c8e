"""Drivers: the prepared model (:mod:`.model`) and what runs it — the Picard map for Coulomb laws, load
histories, the search for every solution — with :func:`.solve.solve` choosing among them.

Importing :mod:`.picard` here registers Coulomb's driver with :class:`.model.Model`, importing
:mod:`.plastic_history` the plastic bodies' steps with :func:`.history.run`.
"""

from . import picard, plastic_history  # noqa: F401  (register the Coulomb driver and the plastic steps)
