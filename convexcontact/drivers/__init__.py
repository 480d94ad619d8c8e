"""Drivers: the prepared model (:mod:`.model`) and what runs it — the Picard map for Coulomb laws, load
histories, the search for every solution — with :func:`.solve.solve` choosing among them.

Importing :mod:`.picard` here registers Coulomb's driver with :class:`.model.Model`.
"""

from . import picard  # noqa: F401  (registers the Coulomb driver)
