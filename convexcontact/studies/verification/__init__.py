"""Verification against the theory's own answers.

:mod:`.uniqueness` counts the solutions of Hild's one-triangle problem against Prop. 4.1 (``study uniqueness``),
:mod:`.spence` the self-similar stick zone of Spence's monotone indentation.
"""
