"""Factorizations and condensations of small 2-D and 3-D elasticity stiffnesses, against dense numpy."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import skfem
from skfem.models.elasticity import lame_parameters, linear_elasticity

from convexcontact.fem.factorization import Condensation, condense, factorize
from convexcontact.scene.description import SceneError

BACKENDS = ["superlu", "pardiso"]


def elasticity(dim: int, cells: int, fixed: str = "bottom"):
    """K on the free DOFs of the unit square/cube and C = the top side's DOFs."""
    x = np.linspace(0.0, 1.0, cells + 1)
    mesh, element = (
        (skfem.MeshTri.init_tensor(x, x), skfem.ElementTriP1()) if dim == 2
        else (skfem.MeshTet.init_tensor(x, x, x), skfem.ElementTetP1())
    )
    basis = skfem.Basis(mesh, skfem.ElementVector(element))
    K = skfem.asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis)
    held = {
        "bottom": basis.get_dofs(lambda p: np.isclose(p[dim - 1], 0.0)).all(),
        "nothing": np.zeros(0, dtype=int),
        "one node": basis.nodal_dofs[:, 0],  # translations held, a rotation free
    }[fixed]
    free = basis.complement_dofs(held)
    number = -np.ones(basis.N, dtype=int)
    number[free] = np.arange(free.size)
    top = number[basis.nodal_dofs[:, np.isclose(mesh.p[dim - 1], 1.0)].ravel()]
    return K[free][:, free].tocsr(), np.sort(top[top >= 0])


@pytest.fixture(scope="module", params=[(2, 30), (3, 8)], ids=["2d", "3d"])
def problem(request):
    dim, cells = request.param
    K, C = elasticity(dim, cells)
    return dim, K, C, np.linalg.inv(K.toarray()), np.setdiff1d(np.arange(K.shape[0]), C)


@pytest.fixture(params=BACKENDS)
def backend(request):
    if request.param == "pardiso":
        pytest.importorskip("pypardiso")
    return request.param


def relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


def contact_rows(C, n, rows=40, seed=1):
    """A B with `rows` rows, each a random combination of 3 DOFs of C."""
    rng = np.random.default_rng(seed)
    cols = rng.choice(C, size=(rows, 3))
    return sp.csr_matrix((rng.standard_normal(3 * rows), (np.repeat(np.arange(rows), 3), cols.ravel())),
                         shape=(rows, n))


def test_factorize_solves_and_builds_delassus(problem, backend):
    dim, K, C, inverse, _ = problem
    factorization = factorize(K, backend, dim)
    assert factorization.backend == backend
    b = np.random.default_rng(0).standard_normal((K.shape[0], 70))  # more columns than one block
    for rhs in (b[:, 0], b):
        assert np.linalg.norm(K @ factorization.solve(rhs) - rhs) <= 1e-10 * np.linalg.norm(rhs)
    B = contact_rows(C, K.shape[0])
    assert relative(factorization.schur(B), B @ (B @ inverse).T) < 1e-10


def test_condensation_matches_dense_algebra(problem, backend):
    dim, K, C, inverse, interior = problem
    condensed = condense(K, C, backend, dim)
    assert isinstance(condensed, Condensation) and condensed.backend == backend
    assert np.array_equal(condensed.C, C) and set(condensed.timings) >= {"factorization", "schur"}
    rng = np.random.default_rng(2)
    f = rng.standard_normal((K.shape[0], 3))
    dense = K.toarray()
    K_II, K_IC = dense[np.ix_(interior, interior)], dense[np.ix_(interior, C)]
    solved = np.linalg.solve(K_II, np.column_stack([K_IC, f[interior]]))
    assert relative(condensed.S, dense[np.ix_(C, C)] - K_IC.T @ solved[:, :C.size]) < 1e-10
    assert np.array_equal(condensed.S, condensed.S.T)

    load = f[C] - K_IC.T @ solved[:, C.size:]
    assert relative(condensed.load(f), load) < 1e-10
    assert relative(condensed.load(f[:, 1]), load[:, 1]) < 1e-10

    u_C = rng.standard_normal((C.size, 3))
    u = condensed.lift(u_C, f)
    assert np.array_equal(u[C], u_C)
    assert np.abs((K @ u - f)[interior]).max() <= 1e-10 * np.abs(f).max()
    assert relative(condensed.lift(u_C[:, 0], f[:, 0]), u[:, 0]) < 1e-12

    assert relative(condensed.solve(f[:, 0]), spla.spsolve(K.tocsc(), f[:, 0])) < 1e-10
    assert relative(condensed.solve(f), inverse @ f) < 1e-10

    B = contact_rows(C, K.shape[0])
    assert relative(condensed.schur(B), B @ (B @ inverse).T) < 1e-10
    outside = sp.csr_matrix(([1.0], ([0], [interior[0]])), shape=(1, K.shape[0]))
    with pytest.raises(ValueError, match="outside"):
        condensed.schur(sp.vstack([B, outside]))


@pytest.mark.parametrize("dim, cells", [(2, 12), (3, 4)])
@pytest.mark.parametrize("fixed", ["nothing", "one node"])
def test_singular_stiffness_is_a_dirichlet_error(backend, dim, cells, fixed):
    K, C = elasticity(dim, cells, fixed)
    for build in (lambda: factorize(K, backend, dim), lambda: condense(K, C, backend, dim)):
        with pytest.raises(SceneError) as error:
            build()
        assert error.value.field == "dirichlet"


def test_a_slender_cantilever_is_not_singular(backend):
    """λ_min/max Kᵢᵢ ≈ 1e-10 here, far below any pivot of a well-held body but above rounding."""
    mesh = skfem.MeshTri.init_tensor(np.linspace(0.0, 100.0, 401), np.linspace(0.0, 1.0, 5))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTriP1()))
    K = skfem.asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis)
    free = basis.complement_dofs(basis.get_dofs(lambda p: np.isclose(p[0], 0.0)).all())
    K = K[free][:, free].tocsr()
    tip = np.arange(K.shape[0] - 10, K.shape[0])
    f = np.zeros(K.shape[0])
    f[-1] = 1.0
    for built in (factorize(K, backend), condense(K, tip, backend)):
        u = built.solve(f)
        assert np.linalg.norm(K @ u - f) < 1e-6 and np.abs(u).max() > 1e6  # it bends: F L³/(3EI) = 4e6


def test_arguments_are_checked():
    K, _ = elasticity(2, 4)
    with pytest.raises(ValueError, match="backend"):
        factorize(K, "cholmod")
    with pytest.raises(ValueError, match="subset"):
        condense(K, np.arange(K.shape[0]), "superlu")
    with pytest.raises(ValueError, match="subset"):
        condense(K, [], "superlu")


def test_auto_takes_pardiso_and_the_import_stays_lazy():
    pytest.importorskip("pypardiso")
    K, C = elasticity(2, 4)
    assert factorize(K).backend == "pardiso" and condense(K, C).backend == "pardiso"
    code = "import sys, convexcontact; assert not {'pypardiso', 'convexcontact.fem.pardiso'} & set(sys.modules)"
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
    subprocess.run([sys.executable, "-c", code], check=True, cwd=root, env=env)



def test_pardiso_takes_the_upper_triangle_as_scipy_s_triu_gives_it():
    """The upper triangle PARDISO factorizes, read off K's rows: scipy's ``triu`` entry for entry (stored zeros, an
    empty row and unsorted columns included), its columns sorted."""
    pytest.importorskip("pypardiso")
    from convexcontact.fem.pardiso import _upper_triangle

    rng = np.random.default_rng(4)
    pattern = rng.random((40, 40)) < 0.2
    pattern[7] = False  # an empty row
    row, column = np.nonzero(pattern)
    data = rng.standard_normal(row.size)
    data[::7] = 0.0  # stored zeros
    order = np.lexsort((rng.random(row.size), row))  # each row's columns shuffled
    K = sp.csr_matrix((data[order], column[order], np.concatenate([[0], np.cumsum(pattern.sum(axis=1))])),
                      shape=pattern.shape)
    assert not K.has_sorted_indices
    U, expected = _upper_triangle(K), sp.triu(K, format="csr")
    expected.sort_indices()
    assert (U.data == 0).any() and U.nnz == expected.nnz
    for got, want in ((U.indptr, expected.indptr), (U.indices, expected.indices), (U.data, expected.data)):
        np.testing.assert_array_equal(got, want)


def _layers(K: sp.csr_matrix, B: sp.csr_matrix, nonzero: bool) -> np.ndarray:
    """The slab's DOFs by its definition: B's columns, grown a layer at a time by the product of K's pattern (its
    nonzero entries, or every stored one) with the mask, up to LAYERS layers while they stay within SLAB of K's."""
    from convexcontact.fem.factorization import LAYERS, SLAB

    graph = sp.csr_matrix(((K.data != 0) | (not nonzero), K.indices, K.indptr), shape=K.shape).astype(np.int32)
    inside = np.zeros(K.shape[0], dtype=bool)
    inside[B.indices] = True
    for _ in range(LAYERS):
        grown = graph @ inside.astype(np.int32) > 0
        if grown.sum() > SLAB * K.shape[0] or grown.sum() == inside.sum():
            break
        inside = grown
    return np.flatnonzero(inside)


def test_the_slab_grows_its_layers_through_k_s_nonzero_entries():
    """The slab (its layers found among the last layer's neighbours) holds the DOFs its definition does, on a K with
    stored zeros that cut links (the same pairs in both triangles): these link nothing, and the slab then differs
    from the one grown through every stored entry."""
    from convexcontact.fem.factorization import slab

    K, top = elasticity(2, 16)
    dense = K.toarray()
    rng = np.random.default_rng(5)
    cut = np.triu(rng.random(dense.shape) < 0.5, k=1) & (dense != 0)
    dense[cut | cut.T] = 0.0
    row, column = K.nonzero()
    K = sp.csr_matrix((dense[row, column], (row, column)), shape=K.shape)
    assert (K.data == 0).any()
    B = sp.csr_matrix((np.ones(top.size), (np.arange(top.size), top)), shape=(top.size, K.shape[0]))
    expected = _layers(K, B, nonzero=True)
    assert not np.array_equal(expected, _layers(K, B, nonzero=False))
    approximation = slab(K, B)
    assert approximation.slab == expected.size
    assert (approximation.H != K[expected][:, expected]).nnz == 0
    assert (approximation.G != B[:, expected]).nnz == 0
