"""Formulations: pure functions from FE matrices and a contact law to a ConicProgram.

Each returns ``(program, recover, bound_update)``: the program for any solver, the
map from the solver's (x, z, s) back to
:class:`~convexcontact.formulations.fields.ContactFields`, and the data change for
new slip bounds (what a Picard step for Coulomb friction changes).
"""

from .dual import dual
from .fields import ContactFields
from .primal import contact_weights, primal

FORMULATIONS = {"primal": primal, "dual": dual}

__all__ = ["FORMULATIONS", "ContactFields", "contact_weights", "dual", "primal"]
