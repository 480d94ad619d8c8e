"""The mortar's clipping by hand (fem/mortar.py, fem/mortar3d.py) against scikit-fem's ``skfem.supermeshing``.

A flat interface, slave and master facets of different sizes: the hand path builds the mortar matrix M (clip and
integrate); the library intersects the two trace meshes (``intersect``: 1-D meshes of a common coordinate, or 2-D
triangle meshes through shapely), and in 2-D the same Gauss rule integrates on its supermesh. Exactness is the
contact patch test, Σ_k M_ik = w_i (a constant gap) and Σ_k M_ik x_k = w_i x_i (a linear one), relative to the
largest w_i; in 3-D the library's supermesh is judged by the area it covers of each slave facet. docs/bodies.md
holds the numbers::

    python -m convexcontact.studies.benchmarks.supermeshing --dim 2 --facets 1000 10000
    python -m convexcontact.studies.benchmarks.supermeshing --dim 3 --facets 1000 2000   # needs shapely
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
import skfem as fe
from skfem.supermeshing import intersect

from ...fem.mortar import Segments, dual_coefficients, gauss, lagrange, mortar
from ...fem.mortar3d import facets_3d, mortar_3d


def timed(build) -> tuple[float, object]:
    """The fastest of three calls of ``build`` [s], after one to warm up, and its answer."""
    build()
    times, answer = [], None
    for _ in range(3):
        start = time.perf_counter()
        answer = build()
        times.append(time.perf_counter() - start)
    return min(times), answer


def patch_errors(entries, slave_nodes, master_nodes, weights, x_slave, x_master) -> tuple[float, float]:
    """Σ_k M_ik − w_i and Σ_k M_ik x_k − w_i x_i, largest over i, relative to the largest w_i."""
    e, a, f, b, values = entries
    M = sp.coo_matrix((values, (slave_nodes[e, a], master_nodes[f, b])), shape=(x_slave.size, x_master.size)).tocsr()
    return (np.abs(M.sum(axis=1).A1 - weights).max() / weights.max(),
            np.abs(M @ x_master - weights * x_slave).max() / weights.max())


def segments_on_a_line(x: np.ndarray, upwards: bool) -> Segments:
    """Facets between the sorted abscissae ``x`` on y = 0, outward normal up (a master below) or down."""
    nodes = np.column_stack([np.arange(x.size - 1), np.arange(1, x.size)])
    nodes = nodes[:, ::-1] if upwards else nodes
    start, end = (np.column_stack([x[nodes[:, k]], np.zeros(len(nodes))]) for k in (0, 1))
    length = np.linalg.norm(end - start, axis=1)
    tangent = (end - start) / length[:, None]
    return Segments(nodes, start, end, length, tangent, np.column_stack([tangent[:, 1], -tangent[:, 0]]))


def by_supermesh(slave: Segments, master: Segments, x_slave: np.ndarray, x_master: np.ndarray) -> list:
    """The entries of :func:`~convexcontact.fem.mortar.mortar` from skfem's 1-D supermesh of the two lines."""
    line_s, line_m = fe.MeshLine(x_slave), fe.MeshLine(x_master)
    supermesh, e, index = intersect((line_s.p, line_s.t), (line_m.p, line_m.t))
    f = np.argsort(np.minimum(master.start[:, 0], master.end[:, 0]))[index]  # the master runs right to left
    lo, hi = supermesh.p[0, supermesh.t[0]], supermesh.p[0, supermesh.t[1]]
    points, fractions = gauss(2)
    x = lo[:, None] + np.outer(hi - lo, points)
    xi = (x - slave.start[e, :1]) / (slave.end[e, :1] - slave.start[e, :1])
    eta = (x - master.start[f, :1]) / (master.end[f, :1] - master.start[f, :1])
    dual = lagrange(1, xi) @ dual_coefficients(1)[0].T
    values = np.einsum("nq,nqa,nqb->nab", np.outer(hi - lo, fractions), dual, lagrange(1, eta))
    a, b = np.indices(values.shape[1:]).reshape(2, -1)
    return [np.repeat(e, a.size), np.tile(a, e.size), np.repeat(f, a.size), np.tile(b, e.size), values.ravel()]


def compare_2d(facets: int) -> None:
    rng = np.random.default_rng(0)
    x_slave = np.sort(np.r_[0.0, rng.uniform(0, 1, facets - 1), 1.0])
    x_master = np.sort(np.r_[-0.01, rng.uniform(-0.01, 1.01, int(0.7 * facets) - 1), 1.01])
    slave, master = segments_on_a_line(x_slave, False), segments_on_a_line(x_master, True)
    weights = np.bincount(slave.nodes.ravel(), weights=np.repeat(slave.measure / 2, 2), minlength=x_slave.size)
    for name, build in (("by hand", lambda: mortar(slave, master, np.array([1.0, 0.0]), 1e-9)[0]),
                        ("skfem.supermeshing", lambda: by_supermesh(slave, master, x_slave, x_master))):
        seconds, entries = timed(build)
        constant, linear = patch_errors(entries, slave.nodes, master.nodes, weights, x_slave, x_master)
        print(f"2-D, {facets} slave facets, {name}: {seconds * 1e3:.0f} ms, patch test {constant:.1e} (constant), "
              f"{linear:.1e} (linear)", flush=True)


def square_face(cells: int, lo: float, hi: float, below: bool, name: str):
    """The face z = 0 of a tetrahedral slab on [lo, hi]², the slab above it (a slave) or below (a master)."""
    x = np.linspace(lo, hi, cells + 1)
    mesh = fe.MeshTet.init_tensor(x, x, np.array([-0.1, 0.0] if below else [0.0, 0.1]))
    return mesh, facets_3d(mesh, mesh.facets_satisfying(lambda p: np.isclose(p[2], 0.0)), name)


def compare_3d(facets: int) -> None:
    cells = round((facets / 2) ** 0.5)
    mesh_s, slave = square_face(cells, 0.0, 1.0, False, "slave")
    mesh_m, master = square_face(round(0.83 * cells), -0.013, 1.017, True, "master")
    weights = np.bincount(slave.nodes.ravel(), weights=np.repeat(slave.measure / 3, 3), minlength=mesh_s.p.shape[1])
    start = time.perf_counter()
    entries, _ = mortar_3d(slave, master, np.array([0.0, 0.0, -1.0]))
    seconds = time.perf_counter() - start
    constant, linear = patch_errors(entries, slave.nodes, master.nodes, weights, mesh_s.p[0], mesh_m.p[0])
    print(f"3-D, {slave.measure.size} slave facets, by hand (clip and integrate): {seconds * 1e3:.0f} ms, patch test "
          f"{constant:.1e} (constant), {linear:.1e} (linear)", flush=True)
    triangles = [(f.points[:, :, :2].reshape(-1, 2).T, np.arange(f.points[:, :, 0].size).reshape(-1, 3).T)
                 for f in (slave, master)]
    start = time.perf_counter()
    supermesh, e, _ = intersect(*triangles)
    seconds = time.perf_counter() - start
    corners = supermesh.p[:, supermesh.t].transpose(2, 1, 0)
    sides = corners[:, 1:] - corners[:, :1]
    area = np.abs(sides[:, 0, 0] * sides[:, 1, 1] - sides[:, 0, 1] * sides[:, 1, 0]) / 2
    covered = np.bincount(e, weights=area, minlength=slave.measure.size) / slave.measure
    print(f"3-D, {slave.measure.size} slave facets, skfem.supermeshing (intersection only): {seconds * 1e3:.0f} ms, "
          f"{supermesh.t.shape[1]} triangles, covered area off by {np.abs(covered - 1).max():.1e}", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--facets", type=int, nargs="+", default=[1000, 10000], help="slave facets per run")
    arguments = parser.parse_args()
    for count in arguments.facets:
        (compare_2d if arguments.dim == 2 else compare_3d)(count)
