"""Scripted studies on top of the solve.

:mod:`.compare` cross-validates two solutions, :mod:`.work_precision` measures error
against run time for every method × solver × tolerance, :mod:`.sweeps` follows the
penalty and ε errors over decades, :mod:`.stability` runs stiff and extreme cases.
"""
