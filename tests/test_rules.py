"""``auto``'s choice of a dense W by its predicted memory (drivers/rules.py, SADDLE_MEMORY; docs/performance.md, "The
dense W's memory on the pair"): where W comes from the saddle its peak grows as the rows squared, the linear solve's
as K's entries, so the pair's friction rows go matrix-free from ~1.4·10⁵ DOFs while one body's punch keeps its W."""

import functools

import pytest

import convexcontact as cc
from convexcontact.drivers import rules
from convexcontact.drivers.rules import MATRIX_FREE, choose_formulation, contact_columns, saddle_memory
from convexcontact.fem import factorization
from convexcontact.fem.assembly import assemble
from convexcontact.fem.factorization import saddle_applies
from convexcontact.studies.benchmarks.bench import punch_scene, two_body_scene

pytestmark = pytest.mark.skipif(factorization._pardiso() is None, reason="the saddle needs PARDISO")


@functools.cache
def pair(dofs: float):
    """The bench's 2-D pair with Tresca, assembled (its rows: m normal, m tangential)."""
    return assemble(two_body_scene("tresca", dofs))


def test_the_pairs_friction_goes_matrix_free_where_its_dense_w_would_pass_twice_the_memory():
    """The 2-D pair at 2.6·10⁵ DOFs: 3,628 Tresca rows, under MATRIX_FREE_COLUMNS, were kept dense before and peaked at
    2.19–2.22× the linear solve's memory (Coulomb 2.44×); now matrix-free (1.56–1.61×), saying it is for memory. Its
    1,814 Signorini rows keep their dense W (1.49×)."""
    fem = pair(2.3e5)
    m = fem.contact.m
    assert saddle_applies(contact_columns(fem).size, 2 * m) and 2 * m <= rules.MATRIX_FREE_COLUMNS  # dense before
    formulation, reason = choose_formulation(fem, fem.scene.contact.law, 2 * m)
    assert formulation == MATRIX_FREE and "the memory of a linear solve" in reason
    assert saddle_memory(fem, 2 * m) > rules.SADDLE_MEMORY > saddle_memory(fem, m)
    assert choose_formulation(fem, cc.Signorini(), m)[0] == "dual"


def test_the_pair_at_1e5_dofs_keeps_its_dense_w():
    """At 10⁵ DOFs the pair's friction keeps its dense W (1.68–1.71× the memory): matrix-free its contact ratio read
    12.7 (Tresca) and 7.2 (Coulomb) against the issue's 3 and 4 there."""
    fem = pair(1e5)
    m = fem.contact.m
    assert choose_formulation(fem, fem.scene.contact.law, 2 * m)[0] == "dual"


@pytest.mark.parametrize("law", ["signorini", "tresca"])
def test_the_punch_keeps_its_dense_w_through_the_saddle(monkeypatch, law):
    """One body pressed by a rigid punch: few rows against K's entries, so the memory rule keeps its dense W even
    where the saddle forms it (SADDLE_COLUMNS at 0; at 10⁶ DOFs the 2-D punch's Signorini rows take the saddle)."""
    monkeypatch.setattr(factorization, "SADDLE_COLUMNS", 0)
    fem = assemble(punch_scene(2, law, 1e5))
    unknowns = fem.contact.m * (1 if law == "signorini" else 2)
    assert choose_formulation(fem, fem.scene.contact.law, unknowns)[0] == "dual"
    assert saddle_memory(fem, unknowns) < (rules.SADDLE_BASE + rules.SADDLE_MEMORY) / 2  # W in under half the room
