"""The mortar's search for facing facets on graded meshes (fem/mortar.py, ``overlapping``): its margin, twice the
largest facet, takes nearly every pair of facets where the meshes are graded towards the contact, and all of them at
once passed 13 GB on the bench's pair at 1.4·10⁶ DOFs; clipped in chunks, the memory is the chunk's."""

import tracemalloc

import numpy as np

from convexcontact.fem import mortar


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
    whole, covered_whole = mortar.mortar(slave, master, np.array([1.0, 0.0]), margin)
    monkeypatch.setattr(mortar, "CANDIDATES", 5_000)
    tracemalloc.start()
    chunked, covered = mortar.mortar(slave, master, np.array([1.0, 0.0]), margin)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    # ~540 × 420 candidate pairs within the margin: 21 MB clipped at once (the search before), the entries ~0.5 MB
    assert peak < 5e6
    assert all(np.array_equal(a, b) for a, b in zip(whole, chunked, strict=True))
    np.testing.assert_allclose(covered, 1.0, atol=1e-12)  # parallel lines: every slave facet covered once
    np.testing.assert_array_equal(covered_whole, covered)
    # the dual basis and the master's hats each sum to one: the entries sum to the slave's length
    np.testing.assert_allclose(chunked[-1].sum(), 2.0, rtol=1e-12)
