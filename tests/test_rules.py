"""``auto``'s dense W on the pair and the punch where W comes from the saddle (drivers/rules.py; docs/performance.md,
"The dense W's memory on the pair"): the 2-D pair at 10⁵ DOFs and one body's punch keep their dense W, which meets
their time targets where the matrix-free dual does not."""

import pytest

from convexcontact.drivers.rules import choose_formulation
from convexcontact.fem import factorization
from convexcontact.fem.assembly import assemble
from convexcontact.studies.benchmarks.bench import punch_scene, two_body_scene

pytestmark = pytest.mark.skipif(factorization._pardiso() is None, reason="the saddle needs PARDISO")


def test_the_pair_at_1e5_dofs_keeps_its_dense_w():
    """At 10⁵ DOFs the pair's friction keeps its dense W (1.68–1.71× the memory): matrix-free its contact ratio read
    12.7 (Tresca) and 7.2 (Coulomb) against the issue's 3 and 4 there."""
    fem = assemble(two_body_scene("tresca", 1e5))
    m = fem.contact.m
    assert choose_formulation(fem, fem.scene.contact.law, 2 * m)[0] == "dual"


@pytest.mark.parametrize("law", ["signorini", "tresca"])
def test_the_punch_keeps_its_dense_w_through_the_saddle(monkeypatch, law):
    """One body pressed by a rigid punch: few rows against K's entries, so it keeps its dense W even where the
    saddle forms it (SADDLE_COLUMNS at 0; at 10⁶ DOFs the 2-D punch's Signorini rows take the saddle)."""
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)
    fem = assemble(punch_scene(2, law, 1e5))
    unknowns = fem.contact.m * (1 if law == "signorini" else 2)
    assert choose_formulation(fem, fem.scene.contact.law, unknowns)[0] == "dual"
