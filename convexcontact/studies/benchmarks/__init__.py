"""Benchmarks: what a solve costs, as ratios measured in one run (DESIGN.md, Performance model).

:mod:`.bench` is ``convexcontact bench`` (a contact solve against one linear solve, per size),
:mod:`.history_bench` its ``--history`` mode, :mod:`.bodies_bench` the two-body costs;
:mod:`.factorizations` measures the sparse direct solvers (docs/factorizations.md) and
:mod:`.picard_reuse` the Picard loop with and without reuse (docs/friction.md), :mod:`.supermeshing` the
mortar's clipping against scikit-fem's supermesh (docs/bodies.md): scripts.
"""
