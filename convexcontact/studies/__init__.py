"""Scripted studies on top of the solve, one folder per thing a user does.

- :mod:`.benchmarks` — what a solve costs (``convexcontact bench``, factorizations, Picard reuse);
- :mod:`.crossvalidation` — another answer against the exact one (``compare``, a peer's file, sfepy, sweeps);
- :mod:`.precision` — error against run time, stiff and extreme cases (``study work-precision``, ``stability``);
- :mod:`.verification` — the theory's own answers (``study uniqueness``, Spence's stick zone);
- :mod:`.parameters` — grids of solves (``study grid``).

:mod:`.arguments` checks the commands' arguments for all of them.
"""
