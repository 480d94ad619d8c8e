"""Formulations: pure functions from FE matrices and a contact law to a ConicProgram.

Each returns ``(program, recover)``: the program for any solver, and the map from
the solver's (x, z, s) back to :class:`~convexcontact.formulations.fields.ContactFields`.
"""

from .fields import ContactFields
from .signorini import contact_weights, signorini

__all__ = ["ContactFields", "contact_weights", "signorini"]
