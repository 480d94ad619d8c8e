"""The mortar's search for facing facets on graded meshes (fem/mortar.py, ``overlapping``): its margin, twice the
largest facet, takes nearly every pair of facets where the meshes are graded towards the contact, and all of them at
once passed 13 GB on the bench's pair at 1.4·10⁶ DOFs; clipped in chunks, the memory is the chunk's."""

import tracemalloc

import numpy as np
import pytest
import skfem as fe

from convexcontact.fem import mortar, mortar3d


def graded_line(fine: float, height: float, normal: float) -> mortar.Segments:
    """Facets along y = ``height`` over [−1, 1]: ``fine`` long on [−0.05, 0.05], 0.05 beyond; outward normal
    (0, ``normal``) (the tangent turned clockwise)."""
    x = np.unique(np.r_[np.arange(-1.0, -0.05, 0.05), np.linspace(-0.05, 0.05, round(0.1 / fine) + 1),
                        np.arange(0.1, 1.0 + 1e-12, 0.05)])
    points = np.column_stack([x, np.full(x.size, height)])
    k = np.arange(x.size - 1)
    start, end = (points[k + 1], points[k]) if normal > 0 else (points[k], points[k + 1])
    measure = np.linalg.norm(end - start, axis=1)
    tangent = (end - start) / measure[:, None]
    return mortar.Segments(nodes=np.column_stack([k, k + 1]), start=start, end=end, measure=measure, tangent=tangent,
                           normal=np.column_stack([tangent[:, 1], -tangent[:, 0]]))


def test_graded_pair_is_clipped_in_chunks(monkeypatch):
    slave, master = graded_line(2e-4, 0.0, 1.0), graded_line(2.6e-4, 1e-3, -1.0)
    margin = 2.0 * max(slave.size.max(), master.size.max())
    whole, covered_whole = mortar.mortar(slave, master, np.array([0.0, 1.0]), margin)
    monkeypatch.setattr(mortar, "CANDIDATES", 5_000)
    tracemalloc.start()
    chunked, covered = mortar.mortar(slave, master, np.array([0.0, 1.0]), margin)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # ~540 × 420 candidate pairs within the margin: 21 MB clipped at once (the search before), the entries ~0.5 MB
    assert peak < 5e6
    assert all(np.array_equal(a, b) for a, b in zip(whole, chunked, strict=True))
    np.testing.assert_allclose(covered, 1.0, atol=1e-12)  # parallel lines: every slave facet covered once
    np.testing.assert_array_equal(covered_whole, covered)
    # the dual basis and the master's hats each sum to one: the entries sum to the slave's length
    np.testing.assert_allclose(chunked[-1].sum(), 2.0, rtol=1e-12)


def polyline(x: np.ndarray, y: np.ndarray) -> mortar.Segments:
    """Facets between consecutive points, start → end as given (the outward normal: the tangent turned clockwise)."""
    points = np.column_stack([x, y])
    start, end = points[:-1], points[1:]
    measure = np.linalg.norm(end - start, axis=1)
    tangent = (end - start) / measure[:, None]
    k = np.arange(x.size - 1)
    return mortar.Segments(nodes=np.column_stack([k, k + 1]), start=start, end=end, measure=measure, tangent=tangent,
                           normal=np.column_stack([tangent[:, 1], -tangent[:, 0]]))


def triangles(x: np.ndarray, height, outward: float) -> mortar3d.Facets:
    """The triangles of a tensor grid over ``x`` × ``x`` lifted to z = ``height(x, y)``, their normals' z of the sign of
    ``outward``."""
    flat = fe.MeshTri.init_tensor(x, x)
    points = np.vstack([flat.p, height(*flat.p)])[:, flat.t].transpose(2, 1, 0)  # (facets, 3, 3)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    flip = turned[:, 2] * outward < 0
    nodes = np.where(flip[:, None], flat.t.T[:, ::-1], flat.t.T)
    points = np.where(flip[:, None, None], points[:, ::-1], points)
    turned = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    normal = turned / np.linalg.norm(turned, axis=1, keepdims=True)
    first = (points[:, 1] - points[:, 0]) / np.linalg.norm(points[:, 1] - points[:, 0], axis=1, keepdims=True)
    return mortar3d.Facets(nodes, points, np.linalg.norm(turned, axis=1) / 2,
                           np.linalg.norm(points - np.roll(points, 1, axis=1), axis=2).max(axis=1), normal,
                           np.stack([first, np.cross(normal, first)], axis=1))


def test_a_tilted_slave_is_covered_across_a_wide_gap():
    """A roof-shaped slave (slopes ±0.6, 1 to 1.3 above a wide flat master): each slave facet's normal meets the master
    0.6–0.8 aside of it, beyond twice the largest facet (0.12), which bounded the search; the facets there were left
    out, so on a curved pair the covered part of Γ_C, and the Tresca nodes tied across its gap, changed with the mesh
    (docs/estimate.md, "Tresca pairs tied across their gap: the cause"). Every slave facet is covered once, in 2-D
    (mortar and node-to-segment) and 3-D."""
    x = np.linspace(-0.5, 0.5, 21)
    slave, master = polyline(x, 1 + 0.6 * np.abs(x)), polyline(np.linspace(3, -3, 121), np.zeros(121))
    mean_normal = np.array([0.0, -1.0])  # the slave's
    entries, covered = mortar.mortar(slave, master, mean_normal, 2.0 * max(slave.size.max(), master.size.max()))
    np.testing.assert_allclose(covered, 1.0, atol=1e-12)
    np.testing.assert_allclose(entries[-1].sum(), slave.measure.sum(), rtol=1e-12)
    nodes, _, _, normals = mortar.slave_nodes(slave)
    node, _, _, values = mortar.node_to_segment(np.column_stack([x, 1 + 0.6 * np.abs(x)])[nodes], normals, master,
                                                mean_normal, 0.12)
    np.testing.assert_array_equal(np.unique(node), nodes)
    np.testing.assert_allclose(np.bincount(node, values), 1.0, rtol=1e-12)
    grid = np.linspace(-0.5, 0.5, 11)
    roof = triangles(grid, lambda x, y: 1 + 0.6 * np.abs(x), -1.0)
    floor = triangles(np.linspace(-3, 3, 31), lambda x, y: 0 * x, 1.0)
    entries, covered = mortar3d.mortar_3d(roof, floor, np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(covered, 1.0, atol=1e-12)
    np.testing.assert_allclose(entries[-1].sum(), roof.measure.sum(), rtol=1e-12)


def test_the_search_window_is_each_facet_s_own_and_misses_no_pair(monkeypatch):
    """The candidates of a slave facet (node) lie within its own size plus :func:`~convexcontact.fem.mortar.across`
    along Γ_C: on the bench's graded pair (a cylindrical punch on a foundation, both meshes graded towards the
    contact) the rows equal, to the bit, those of a window as wide as the whole interface, with a few candidates per
    slave facet (363 for 78 here; the former window, twice the largest facet, 1,807; 3.6·10⁶ at 3.2·10⁵ DOFs)."""
    import dataclasses

    from convexcontact.fem.assembly import assemble
    from convexcontact.scene.bodies_library import punch_on_foundation

    clipped, searched = mortar.clipped, []

    def counted(slave, master, e, f):
        searched.append(e.size)
        return clipped(slave, master, e, f)

    def widened(lo_s, hi_s, lo_m, hi_m, margin):  # the bodies are 2 across: every pair a candidate
        return overlapping(lo_s, hi_s, lo_m, hi_m, margin + 10.0)

    monkeypatch.setattr(mortar, "clipped", counted)
    overlapping = mortar.overlapping
    for method in ("mortar", "node_to_segment"):
        scene = punch_on_foundation(0.01)
        scene = dataclasses.replace(scene, contact=dataclasses.replace(scene.contact, method=method))
        searched.clear()
        local = assemble(scene).contact
        facets = local.facets.shape[-1]
        candidates = sum(searched)
        if method == "mortar":
            assert candidates <= 10 * facets
        with monkeypatch.context() as wide:
            wide.setattr(mortar, "overlapping", widened)
            searched.clear()
            everything = assemble(scene).contact
            assert method != "mortar" or sum(searched) > 10 * candidates
        for name in ("N_full", "T_full"):
            assert abs(getattr(local, name) - getattr(everything, name)).max() == 0.0
        np.testing.assert_array_equal(local.gap, everything.gap)


@pytest.mark.parametrize("shape", ["convex cylinders", "sheared cylinders", "P2 cylinders", "flat patch",
                                   "node-to-segment cylinders"])
def test_the_own_size_window_misses_no_pair_on_other_shapes(shape, monkeypatch):
    """Beyond the bench's punch: two convex faces (a gap widening to their open ends, where ``across`` is largest),
    a sheared pair, quadratic facets, a flat non-matching patch and node-to-segment: the rows equal, to the bit, those
    of a window as wide as the interface."""
    from convexcontact.fem.assembly import assemble
    from convexcontact.scene.bodies_library import patch_pair, two_cylinders

    scene = {"convex cylinders": lambda: two_cylinders(0.05, radii=(1.0, 1.5), master_h=0.07),
             "sheared cylinders": lambda: two_cylinders(0.05, shift=0.02),
             "P2 cylinders": lambda: two_cylinders(0.08, element="P2"),
             "flat patch": lambda: patch_pair(7, 11),
             "node-to-segment cylinders": lambda: two_cylinders(0.05, method="node_to_segment")}[shape]()
    local = assemble(scene).contact
    overlapping = mortar.overlapping
    monkeypatch.setattr(mortar, "overlapping", lambda lo_s, hi_s, lo_m, hi_m, margin: overlapping(
        lo_s, hi_s, lo_m, hi_m, margin + 10.0))  # the bodies are at most 2.4 across: every pair a candidate
    everything = assemble(scene).contact
    for name in ("N_full", "T_full"):
        assert getattr(local, name).shape == getattr(everything, name).shape
        assert abs(getattr(local, name) - getattr(everything, name)).max() == 0.0
    np.testing.assert_array_equal(local.gap, everything.gap)
