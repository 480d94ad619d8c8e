"""Precision and stability: how accurate each way of solving is, and that stiff or extreme cases answer or refuse.

:mod:`.work_precision` measures error against run time for every method × solver × tolerance (``study
work-precision``), :mod:`.stability` runs the stiff and extreme cases against references (``study stability``).
"""
