"""Scripted studies on top of the solve: cross-validation of two solutions (:mod:`.compare`)."""
