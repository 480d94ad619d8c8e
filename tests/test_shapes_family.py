"""The bench's family of shapes (``bench --scenario shapes [--dim 3]``, studies/benchmarks/shapes.py; issue 25) at small
sizes: every shape, 2-D and 3-D, one body and two, under Signorini, Tresca and Coulomb, with ``auto`` and forced
matrix-free, is solved and certified with no fallback — no sparse primal in place of the formulation the model was
given (``auto``'s way out where newton-cg fails on a matrix-free dual), no Clarabel after newton-cg on a dense dual, no
Picard attempt after the first. Where the family misses that today, the case is a strict xfail naming what was
measured (docs/performance.md, "The family in 3-D and with Coulomb")."""

import functools

import pytest

import convexcontact as cc
from convexcontact.drivers.rules import DENSE_NEWTON, MATRIX_FREE
from convexcontact.solvers import newton_cg
from convexcontact.studies.benchmarks.bench import LAWS, scene_of
from convexcontact.studies.benchmarks.shapes import SHAPES

SIZES = {2: 1.5e3, 3: 1e3}
"""Target free DOFs (the thinnest shapes have more: a 2-D strip is at least 2 cells high, a 3-D plate 1 cell)."""
CERTIFIED = {"signorini": 1e-10, "tresca": 1e-10, "coulomb": cc.Coulomb(friction=0.3).tol}
"""The issue's certificates: 1e-10 for Signorini and Tresca, Coulomb's own tolerance (1e-8)."""

FAILING: dict = {}
"""Cases that are not solved today, and why: none since newton-cg damps its Newton systems after a far point (the
3-D pair's Coulomb row, matrix-free; docs/performance.md, "The 3-D pair from the stick start"). That row hangs on the
local diagonal's estimates of near-null rows: with one layer of patches on 3-D faces it stalled again."""
UNCERTIFIED: dict = {}
"""Cases solved short of the issue's certificate today, and why: none since auto condenses 3-D friction where the
contact nodes carry over a quarter of the DOFs (the flat block and the plates here, Tresca and Coulomb: the sparse
primal's cones are not in the polish's bound form and Clarabel alone left 6e-9–3.4e-7; rules.choose_formulation)."""


def cases(known: dict):
    """Every (dim, shape, law, formulation) of the family, those in ``known`` a strict xfail with its reason."""
    return [pytest.param(*case, marks=pytest.mark.xfail(reason=known[case], strict=True)) if case in known else case
            for case in ((dim, shape, law, formulation) for dim in SHAPES for shape in SHAPES[dim] for law in LAWS
                         for formulation in ("auto", MATRIX_FREE))]


@functools.cache
def solve(dim: int, shape: str, law: str, formulation: str):
    """The model of the family's ``shape`` at the test's size and its result (solved once for all tests)."""
    model = cc.prepare(scene_of(shape, dim, law, SIZES[dim]), formulation)
    return model, model.solve()


def fallbacks(model, result) -> list[str]:
    """What answered other than the model's own formulation and first solver: the sparse primal for a dual,
    Clarabel after newton-cg on a dense dual, a Picard attempt after the first (another formulation or solver)."""
    found = []
    if result.formulation != model.formulation:
        found.append(f"the {result.formulation} answered the {model.formulation}: {result.extra['formulation_reason']}")
    if result.extra.get("solver_reason", DENSE_NEWTON) != DENSE_NEWTON:
        found.append(result.extra["solver_reason"])
    attempts = result.extra.get("picard", {}).get("attempts", [])
    found += [f"Picard attempt {k + 1}: {a['formulation']}/{a['solver']} after {attempts[k - 1]['outcome']}"
              for k, a in enumerate(attempts) if k > 0]
    return found


def check_answered_without_fallback(model, result):
    assert result.status == "solved", (result.status, result.message)
    assert fallbacks(model, result) == []


@pytest.mark.parametrize("dim, shape, law, formulation", cases(FAILING))
def test_every_shape_is_solved_by_the_formulation_it_was_given(dim, shape, law, formulation):
    """Solved, by the model's formulation (the dual where it was given one: newton-cg on a dense or matrix-free W),
    and for Coulomb in the Picard driver's first attempt (Newton's solve of the Coulomb problem, or the map)."""
    model, result = solve(dim, shape, law, formulation)
    if formulation == MATRIX_FREE:
        assert model.formulation == "dual" and result.solver == "newton-cg"
    check_answered_without_fallback(model, result)


@pytest.mark.parametrize("dim, shape, law, formulation", cases({**FAILING, **UNCERTIFIED}))
def test_every_shape_is_certified_as_the_issue_asks(dim, shape, law, formulation):
    """The certificate's worst residual (natural maps: normal law, friction law, equilibrium) within the issue's
    bound: 1e-10 for Signorini and Tresca, Coulomb's tolerance 1e-8."""
    _, result = solve(dim, shape, law, formulation)
    assert result.certificate is not None and result.certificate.worst <= CERTIFIED[law]


@pytest.mark.parametrize("formulation, dofs", [("auto", 5e3), (MATRIX_FREE, 2e3)])
def test_the_check_catches_newton_cg_without_grown_faces(monkeypatch, formulation, dofs):
    """The regression these tests guard: newton-cg without Newton's point on grown faces (GROW = 0) nor the face step
    (FACE, which alone finds it too) finds Tresca's slip zone on the tall 2-D block a node every few steps —
    matrix-free at 2·10³ DOFs no answer after 100 steps; on the dense W that auto picks at 5·10³ DOFs, Clarabel after
    newton-cg's 50 steps — and the check above says so."""
    monkeypatch.setattr(newton_cg, "GROW", 0)
    monkeypatch.setattr(newton_cg, "FACE", False)
    model = cc.prepare(scene_of("tall", 2, "tresca", dofs), formulation)
    with pytest.raises(AssertionError):
        check_answered_without_fallback(model, model.solve())
