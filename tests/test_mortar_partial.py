"""A pair's slave facets partly covered by the master (docs/estimate.md, "Rows on partly covered slave nodes"): the
dual basis of each facet's covered part (mortar3d.on_covered_parts) keeps their nodes' rows consistent."""

import numpy as np
import pytest

import convexcontact as cc
from convexcontact import Pair, Part, bodies_scene
from convexcontact.fem import mortar
from convexcontact.fem.assembly import assemble
from convexcontact.scene.description import Box, Rectangle

STEEL = cc.Material(1.0, 0.3)
CELLS = 4
OVERHANG = 0.5 / (CELLS - 1)  # half a slave facet beyond the master on each side: the end facets half covered
PRESSURE = 0.01
PARTS = ("upper", "lower")
ELEMENTS = [(2, "P1"), (2, "Q1"), (2, "P2"), (2, "Q2"), (3, "P1"), (3, "Q1"), (3, "P2"), (3, "Q2")]


def overhanging(dim: int, element: str) -> cc.Scene:
    """A slave block 1 + 2·OVERHANG wide (CELLS cells across) centred on a unit master block (5 cells), p on top."""
    wide = 1.0 + 2 * OVERHANG
    if dim == 2:
        shapes = (Rectangle(wide, 1.0, CELLS, 2, origin=(-OVERHANG, 1.0)), Rectangle(1.0, 1.0, 5, 2))
        held = [cc.Dirichlet("lower.bottom", uy=0.0)] + [cc.Dirichlet(f"{part}.left", ux=0.0) for part in PARTS]
    else:
        shapes = (Box(size=(wide, wide, 1), cells=(CELLS, CELLS, 2), origin=(-OVERHANG, -OVERHANG, 1)),
                  Box(size=(1, 1, 1), cells=(5, 5, 2)))
        held = [cc.Dirichlet("lower.bottom", uz=0.0)] + [cc.Dirichlet(f"{part}.{side}", **{axis: 0.0}) for part in PARTS
                                                         for side, axis in (("left", "ux"), ("front", "uy"))]
    parts = [Part(name, shape, STEEL, element) for name, shape in zip(PARTS, shapes)]
    return bodies_scene(parts, Pair("upper.bottom", master="lower.top"), dirichlet=held,
                        tractions=[cc.Traction("upper.top", pressure=PRESSURE)])


def field(fem, degree: int) -> np.ndarray:
    """A displacement of both bodies, polynomial of ``degree`` in the interface's coordinates (x, or x and y)."""
    dim = fem.mesh.dim()
    tangential = fem.basis.doflocs[:dim - 1, ::dim].T
    values = [np.ones(len(tangential)), *tangential.T]
    values += [*(tangential**2).T, tangential.prod(axis=1)] if degree == 2 else []
    return (np.column_stack(values) @ np.arange(1.0, dim * len(values) + 1).reshape(len(values), dim)).ravel()


def spied(dim: int, element: str, monkeypatch) -> tuple[np.ndarray, np.ndarray]:
    """Every slave node's covered weight w_i = Σ_e ∫_cov ψ_i (unscaled), whether it keeps its row or not, and which
    nodes the old rule kept (those whose facets are all covered)."""
    found = {}

    def spy(name, build):
        monkeypatch.setattr(mortar, name, lambda *arguments: found.setdefault(name, (arguments, build(*arguments)))[1])

    for name in ("transfer_matrix", "mortar", "mortar_3d"):
        spy(name, getattr(mortar, name))
    fem = assemble(overhanging(dim, element))
    monkeypatch.undo()
    (_, _, _, local, *_), (*_, weights) = found["transfer_matrix"]
    covered = found["mortar_3d" if dim == 3 else "mortar"][1][1]
    old = ~np.isin(np.arange(weights.size), local[covered < 1 - mortar.COVERED])
    return weights * fem.scaling.length ** (dim - 1), old


@pytest.mark.parametrize("dim, element", ELEMENTS)
def test_partly_covered_nodes_keep_consistent_rows(dim, element, monkeypatch):
    """Every slave node the master covers under ≥ KEPT of its weight holds a row; each row still reads no jump
    for a field of the element's degree common to both bodies (the gap's patch test), each row's master entries sum to
    its slave's, and the nodes' covered weights sum to the covered area (1). The old rule kept only the nodes
whose facets are all covered."""
    fem = assemble(overhanging(dim, element))
    trace = fem.contact
    u = field(fem, 2 if element in ("P2", "Q2") else 1)
    # round-off, amplified on Q2 faces by the rows of nodes covered on a few % of their weight (3.7e-11 of 19)
    assert max(np.abs(trace.N_full @ u).max(), np.abs(trace.T_full @ u).max()) < 1e-11 * np.abs(u).max()
    assert trace.imbalance(np.ones(trace.m)) < 1e-13
    weights, old = spied(dim, element, monkeypatch)
    assert weights.sum() == pytest.approx(1.0, rel=1e-12)
    # the negative control: the old rule kept only the nodes whose facets are all covered, a third of the slave's width
    assert old.sum() == {"P1": 1, "Q1": 1, "P2": 3, "Q2": 3}[element] ** (dim - 1) < trace.m


@pytest.mark.parametrize("dim, element", ELEMENTS)
def test_an_overhanging_slave_balances_its_forces(dim, element):
    """Solved with p on the wider slave's top: the pair's forces balance to round-off and carry the whole load (no
    closed-form pressure: the overhang bends); a uniform multiplier loads the master as p on its whole top does."""
    result = cc.solve(overhanging(dim, element))
    assert result.certificate.passes(1e-9) and result.certificate.residuals["pair_balance"] < 1e-12
    wide = 1.0 + 2 * OVERHANG
    assert result.normal_force == pytest.approx(PRESSURE * wide ** (dim - 1), rel=1e-9)
    trace = result.fem.contact
    if dim == 2 and element == "P1":  # every slave node kept: Σ φ*_i = 1, the consistent load p h/2, p h, …, p h/2
        master = trace.forces(PRESSURE * trace.weights)[trace.master_dofs[:, 1]]
        ends = np.isin(np.round(trace.master_coords[:, 0] * result.fem.scaling.length, 12), (0, 1))
        np.testing.assert_allclose(master, -PRESSURE * np.where(ends, 0.1, 0.2) / result.fem.scaling.length,
                                   rtol=1e-12)


def test_a_p2_end_vertex_with_a_negative_covered_weight_keeps_no_row(monkeypatch):
    """2-D P2, the slave's end facets covered on their inner half: the end vertex's ∫_cov ψ = ∫_½¹ (1 − t)(1 − 2t) h
    = −h/24, the edge node's h/3 of 2h/3; the end vertices are left out (their weight is not
    positive), the edge nodes kept."""
    weights = spied(2, "P2", monkeypatch)[0]
    h = (1 + 2 * OVERHANG) / CELLS
    fem = assemble(overhanging(2, "P2"))
    assert np.count_nonzero(weights < 0) == 2 and np.allclose(weights[weights < 0], -h / 24, rtol=1e-12)
    assert fem.contact.m == weights.size - 2 and "2 of" in fem.warnings[0]
    length = fem.scaling.length
    middles = np.abs(np.abs(fem.contact.coords[:, 0] * length - 0.5) - 0.5 - OVERHANG + h / 2) < 1e-12
    assert middles.sum() == 2
    np.testing.assert_allclose(fem.contact.weights[middles] * length, h / 3, rtol=1e-12)
