"""Coarse functions of each body away from its contact face, for the preconditioner of the matrix-free dual.

The slab preconditioner (:func:`~convexcontact.fem.factorization.slab`) clamps the body a few layers from the
contact face, so it has the face's long waves too stiff: on a 2-D strip 124 cells high with a 16-layer slab the
generalized eigenvalues of W against the slab's W spread over [1, 10]. Adding, outside the slab, the bilinear
(trilinear) hats of a regular grid whose spacing is the slab's thickness brings them to [1, 1.07] (1001 bottom
nodes, 1024 extra unknowns on 3.4·10⁴). A grid needs only the DOFs' positions; the functions are FE functions (the
grid's hats interpolated at the DOFs), so K on slab + grid is a Galerkin approximation of K.

Two bodies (the bench's punch on a foundation, graded meshes; generalized eigenvalues of W against the
approximation, Signorini, 2.5·10⁴ / 10⁵ DOFs): one grid over both bodies ties them together, and its spacing, two of
the largest cells, is far coarser than a slab of graded cells is thick: [1, 52] / [1, 208] (the clamped slab at
2.5·10⁴: [1, 60]). Grids per body (K's connected components): [1, 6.7] / [1, 29]. Graded with the cells too, a grid per
octave of cell size from the slab's thickness out: [1, 1.9] / [1, 6.3]; each grid's hats kept over the DOFs of its
octave and the finer ones (there with the finer grids' own nodes only: nested grids' hats are sums of finer ones), so
their span holds the linear fields of the body, up to the hats that only graze its DOFs: a shear of the whole
body among them (kept over its octave alone,
the Tresca dual's tangential rows at 1.6·10⁴ DOFs kept an eigenvalue of 18, now 1.3; docs/performance.md, "The
pair's matrix-free dual at scale").
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

CELLS = 2
"""Least grid spacing, in the cells around the DOFs the grid's hats are kept for."""
KEEP = 0.25
"""A grid function is kept where it reaches this value at some DOF it is kept for: a hat that only grazes them (a
corner of its support) adds a nearly dependent column."""
INDEPENDENT = 1e-10
"""Least pivot of the pivoted Cholesky factorization of the functions' stiffness (unit diagonal) a function must
leave to be kept: the graded grids' hats near the slab and the edges of their levels can be dependent on the DOFs
(the pair at 2.5·10⁴ / 10⁵ DOFs: 12 of 332, 14 of 774; none on the one-body shapes, whose cells are all alike)."""
FILL = 0.9
"""The share of DENSE_COLUMNS a coarsened grid aims at (:func:`coarser`): aiming at all of it, the grids tried crept
up on it from above. 0.95 left the clamped strip 400 : 1 at 10⁵ DOFs 3 Newton steps (its last CG short of the
stopping test: 8.8e-12 against 1e-12), 0.9 and 0.99 2 as before: the steps hang on that edge, not on the grid."""
DENSE_COLUMNS = 4000
"""Most functions of a body (a dense |F|² array for their independence check, 128 MB, and its pivoted Cholesky,
~2·10¹⁰ flops, 0.7 s): its grids are coarsened to stay within it. Unchecked beyond it (before), the pair at 1.4·10⁶
DOFs had 10,092 functions, 1,764 of them dependent (a dense check: 14.6 s, 815 MB); the slab's own check then
dropped them all, and its Tresca dual ran over an hour of products with W."""


def grid_functions(points: np.ndarray, components: np.ndarray, spacing) -> sp.csr_matrix:
    """The hats of a regular grid of ``spacing`` (one number, or one per axis) over the points (dim × n), one column
    per grid node and component, at each point in its own component (``components``, n): n × grid columns, 2^dim
    entries a row. A column is ``node · dim + component``, the nodes numbered in C order, from the points' least
    corner."""
    n = points.shape[1]
    box = points.min(axis=1, keepdims=True), points.max(axis=1, keepdims=True)
    columns, values, shape = _hats(points, components, box, spacing)
    return sp.csr_matrix((values.ravel(), columns.ravel(), np.arange(0, (n + 1) * columns.shape[1], columns.shape[1])),
                         shape=(n, int(shape.prod()) * points.shape[0]))


def _hats(points: np.ndarray, components: np.ndarray, box: tuple, spacing) -> tuple:
    """The grid of ``spacing`` over the ``box`` (its least and greatest corners, dim × 1, holding the points): each
    point's 2^dim columns and hat values (n × 2^dim, as in :func:`grid_functions`) and the grid's nodes along each
    axis (:func:`_corners`)."""
    spacing = _per_axis(spacing, points.shape[0])
    shape = _grid_shape(box, spacing)
    return (*_corners((points - box[0]) / spacing, components, shape), shape)


def _grid_shape(box: tuple, spacing: np.ndarray) -> np.ndarray:
    """The nodes along each axis of the grid of ``spacing`` (dim × 1) over the ``box``: the cells of its farthest
    corner, + 2."""
    low, high = box
    return np.floor((high - low) / spacing).astype(np.int64).ravel() + 2


def _corners(scaled: np.ndarray, components: np.ndarray, shape: np.ndarray) -> tuple:
    """The columns and hat values (n × 2^dim) of points at ``scaled`` (dim × n, in grid cells from the grid's first
    node) on a grid of ``shape`` nodes. A corner's columns are the cell's first node's plus the corner's offset, its
    values a product of the axes' two weights: a loop over corners and axes with n-long temporaries for each took
    1.5 × as long (7·10⁵ points: 27 against 18 ms; the pair's far functions at 1.4·10⁶ DOFs, 54 grids, 2.76–3.33 →
    2.69–3.28 s). A point on the grid's last node (a finer grid's node, :func:`_combination`) is in the last cell,
    its weights there 0 and 1."""
    first, offsets, values = _cells(scaled, components, shape)
    return np.ascontiguousarray((first + offsets[:, None]).T), np.stack(list(values), axis=1)


def _reached(scaled: np.ndarray, components: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """The columns of the hats that reach KEEP at some of the points (as :func:`_corners`, repeated): a corner at a
    time, no n × 2^dim arrays of columns and values transposed (:func:`graded_grids` keeps only these; its tries at
    1.4·10⁶ DOFs, the punch once and the foundation three times, 0.99–1.25 → 0.63–0.84 s, the same masks)."""
    first, offsets, values = _cells(scaled, components, shape)
    return np.concatenate([first[value >= KEEP] + offset for offset, value in zip(offsets, values)])


def _cells(scaled: np.ndarray, components: np.ndarray, shape: np.ndarray) -> tuple:
    """For :func:`_corners` and :func:`_reached`: each point's column at its cell's first node (n), each corner's
    offset from it (2^dim) and, lazily, each corner's hat values at the points (n each, a product of the axes' two
    weights; as one side × axis × point array indexed per corner, _corners took 22 ms on 7·10⁵ 2-D points, now 17)."""
    dim = scaled.shape[0]
    cell = np.minimum(np.floor(scaled), (shape - 2)[:, None])
    weights = (1.0 - (scaled - cell), scaled - cell)  # side: axis × point
    strides = np.cumprod(np.concatenate([[1], shape[:0:-1]]))[::-1]  # C order
    corners = np.array(list(itertools.product((0, 1), repeat=dim)), dtype=np.int64)  # 2^dim × dim
    first = (strides @ cell.astype(np.int64)) * dim + components
    values = (functools.reduce(np.multiply, [weights[side][axis] for axis, side in enumerate(corner)])
              for corner in corners)
    return first, (corners @ strides) * dim, values


def _per_axis(spacing, dim: int) -> np.ndarray:
    """``spacing`` (one number, or one per axis) as a dim × 1 column."""
    return np.broadcast_to(np.asarray(spacing, dtype=float).reshape(-1, 1), (dim, 1))


def fitted_spacing(points: np.ndarray, spacing: float) -> np.ndarray:
    """Per axis, the largest spacing of at most ``spacing`` that puts a whole number of cells across the points'
    bounding box, so that its far sides lie on grid nodes. A side inside a cell (a fraction f past the last node)
    had its points held only by hats reaching f there; KEEP dropped them for f < KEEP, and the grid then missed the
    linear fields of that side: on a strip 20 : 1 clamped at its ends (10⁵ DOFs, its top 5.25 cells above the
    slab) the beam's bending on the slab and grid cost 3·10³ times its true energy, W against the approximation
    had eigenvalues to 2·10³, and CG took up to 32 iterations a Newton system. The largest spacing at least
    ``spacing`` instead (fewer cells) coarsened a grid of 2.47 cells across to 2 (strip 100 : 1 clamped, 2·10⁴
    DOFs: 148 products with W → 194)."""
    extent = np.ptp(points, axis=1)
    cells = np.maximum(np.ceil(extent / spacing * (1 - 1e-9)), 1.0)  # 1e-9: an extent of whole cells, rounded
    return np.where(extent > 0, extent / cells, spacing)


def graded_functions(points: np.ndarray, components: np.ndarray, sizes: np.ndarray, spacing: float) -> Functions:
    """Hats of grids of ``spacing`` · 2^k, k = 0, 1, …: a point's own grid is the finest whose spacing is at least
    CELLS × its cells' size (``sizes``); a grid's hat is kept where it reaches KEEP at a point of that grid or of a
    finer one, and on every grid but the coarsest only at the nodes the next coarser grid lacks (nested grids: a
    coarse hat is a sum of fine ones). The grids' kept columns side by side (:func:`graded_grids`), as
    :class:`Functions`."""
    return _factored(points, components, graded_grids(points, components, sizes, spacing))


def graded_grids(points: np.ndarray, components: np.ndarray, sizes: np.ndarray, spacing: float) -> tuple:
    """The grids of :func:`graded_functions`, before any function is built (a too fine grid is only counted): the
    points' box, each grid's spacing and the mask of its kept columns."""
    dim = points.shape[0]
    octaves = np.log2(np.maximum(CELLS * sizes / spacing, 1.0))
    level = np.ceil(octaves - 1e-9).astype(np.int64)  # sizes of equal cells differ in their last bits
    top = level.max(initial=0)
    fitted = fitted_spacing(points, spacing)  # the finest grid's sides on the body's (the coarser ones nest in it)
    box = points.min(axis=1, keepdims=True), points.max(axis=1, keepdims=True)
    order = np.argsort(level, kind="stable")  # each grid's points (its own and the finer grids') a leading run
    ends = np.searchsorted(level[order], np.arange(top + 1), side="right")
    scaled = np.ascontiguousarray((points[:, order] - box[0]) / _per_axis(fitted, dim))  # in the finest grid's
    # cells, row-major (numpy's advanced index gives it column-major: the pair's four tries at 1.4·10⁶ DOFs
    # 0.49–0.66 → 0.45–0.55 s)
    components = components[order]
    spacings, keeps = [fitted * 2**k for k in range(top + 1)], []
    for k, grid in enumerate(spacings):  # grid k's cells are 2^k of the finest's: the points there scaled exactly
        shape = _grid_shape(box, _per_axis(grid, dim))
        keep = np.zeros(int(shape.prod()) * dim, dtype=bool)
        reached = _reached(scaled[:, :ends[k]] / 2.0**k, components[:ends[k]], shape)
        keep[reached] = True  # a hat's peak over the points reaches KEEP where one value does
        if k < top:  # the nodes of the kept columns only: on a graded body a fine grid's box holds far more
            # nodes than its points reach (the pair at 3.2·10⁵ DOFs: 766,480 columns for 34,508 points)
            kept = np.flatnonzero(keep)
            keep[kept[~(np.stack(np.unravel_index(kept // dim, tuple(shape))) % 2).any(axis=0)]] = False
        keeps.append(keep)
    return box, spacings, keeps


@dataclass(frozen=True)
class Functions:
    """Coarse functions F = ``nodes`` ``combination``: ``nodes`` (n × p) the hats of one grid at each point, the finest
    grid whose kept functions reach it, and ``combination`` (p × c) each function's values at those grids' nodes
    (nested grids: a coarser hat is, on a finer grid's cells, the sum of the finer hats weighted by its values at
    their nodes). A point of a graded body carries its own grid's functions and every coarser one's (the pair at
    1.4·10⁶ DOFs: F 1.77·10⁷ nonzeros, ~19 a row); ``nodes`` 2^dim a row and ``combination`` few, so that K's energy
    on F is ``combinationᵀ (nodesᵀ K nodes) combination``: 0.48 against 2.7 s for Fᵀ K F there. ``values`` and
    ``grids`` give :meth:`localized`, the same span in its nodal basis, for
    :func:`~convexcontact.fem.factorization.slab`'s H."""

    nodes: sp.csr_matrix
    combination: sp.csr_matrix
    values: sp.csr_matrix | None = None  # c × c: each function's values at the functions' own nodes
    grids: np.ndarray | None = None  # c: each function's grid, 0 the finest

    @property
    def shape(self) -> tuple:
        return self.nodes.shape[0], self.combination.shape[1]

    def kept(self, columns: np.ndarray) -> Functions:
        """These ``columns`` of F only."""
        if self.values is None:
            return Functions(self.nodes, self.combination[:, columns])
        return Functions(self.nodes, self.combination[:, columns], sp.csr_matrix(self.values[columns][:, columns]),
                         self.grids[columns])

    def localized(self) -> Functions:
        """The nodal basis of F's span: ψ_j, 1 at function j's node and 0 at every other function's, from the finest
        grid up as ψ_j = F_j − Σ_i F_j(node i) ψ_i over the functions i of finer grids (a function is 0 at the other
        nodes of its grid and of the coarser ones). Where the finer grids' functions around a node are all kept, ψ_j
        is the finest grid's hat there; it never reaches beyond F_j's support."""
        if self.values is None:
            return self
        finer = sp.csc_matrix(self.values - sp.eye(self.values.shape[0]))  # F_j(node i), i of a finer grid
        combination, nodal = sp.csc_matrix(self.combination), sp.csc_matrix(self.combination.shape)
        for grid in np.unique(self.grids):
            mine = np.flatnonzero(self.grids == grid)
            placed = sp.csr_matrix((np.ones(mine.size), (np.arange(mine.size), mine)), shape=(mine.size, nodal.shape[1]))
            nodal = nodal + (combination[:, mine] - nodal @ finer[:, mine]) @ placed
        nodal.eliminate_zeros()  # dyadic values: the cancelled ones are exact zeros
        return Functions(self.nodes, sp.csr_matrix(nodal))


def _factored(points: np.ndarray, components: np.ndarray, grids: tuple) -> Functions:
    """The kept columns of ``grids`` (:func:`graded_grids`) at the points as :class:`Functions`. Building F itself,
    every grid's hats at every point (a matrix per grid, stacked), took 1.45 s of the foundation's coarse functions in
    the pair at 1.4·10⁶ DOFs (12 grids, 3,902 functions on 4.7·10⁵ DOFs), these 0.39 s."""
    box, spacings, keeps = grids
    dim, n = points.shape
    shapes = [_grid_shape(box, _per_axis(grid, dim)) for grid in spacings]
    starts = np.cumsum([0] + [int(shape.prod()) * dim for shape in shapes])  # the grids' columns numbered in a row
    rows, columns, values, used = [], [], [], []
    left = np.arange(n)  # the points no finer grid's kept functions reach
    for k, (grid, keep) in enumerate(zip(spacings, keeps, strict=True)):
        hats, weights, _ = _hats(points[:, left], components[left], box, grid)
        nonzero = weights != 0  # a point on a grid line: a zero weight, not stored
        reached = (keep[hats] & nonzero).any(axis=1)
        hats, nonzero = hats[reached], nonzero[reached]
        rows.append(np.repeat(left[reached], nonzero.sum(axis=1)))
        values.append(weights[reached][nonzero])
        mine = np.zeros(keep.size, dtype=bool)  # the grid's columns used, marked: np.unique of all the grids'
        mine[hats[nonzero]] = True  # (a sort) took 0.22–0.34 s of the foundation's at 1.4·10⁶ DOFs, these 0.03 s
        mine = np.flatnonzero(mine)
        columns.append(sum(map(len, used)) + np.searchsorted(mine, hats[nonzero]))
        used.append(mine + starts[k])
        left = left[~reached]
    used = np.concatenate(used)
    nodes = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                          shape=(n, used.size))
    own = np.concatenate([np.flatnonzero(keep) + start for keep, start in zip(keeps, starts)])  # the functions' nodes
    grids = np.repeat(np.arange(len(keeps)), [int(keep.sum()) for keep in keeps])
    return Functions(nodes, _combination(used, starts, shapes, keeps), _combination(own, starts, shapes, keeps), grids)


def _combination(used: np.ndarray, starts: np.ndarray, shapes: list, keeps: list) -> sp.csr_matrix:
    """The values of the grids' kept functions (numbered as :func:`graded_grids` keeps them) at the ``used`` grid
    columns (numbered from the grids' ``starts``): a column of grid m (a node and component) against the kept columns
    of grid m and the coarser ones, the node in grid k's cells its index over 2^(k − m), exact."""
    dim = shapes[0].size
    kept = [np.flatnonzero(keep) for keep in keeps]  # a function's number: its place among them (a cumulative sum
    # over the grids' columns took 0.27 s at 1.4·10⁶ DOFs: the finest grids' boxes hold far more nodes than are kept)
    firsts = np.cumsum([0] + list(map(len, kept)))
    grid = np.searchsorted(starts, used, side="right") - 1
    rows, columns, values = [], [], []
    for m in np.unique(grid):
        mine = np.flatnonzero(grid == m)
        local = used[mine] - starts[m]
        index = np.stack(np.unravel_index(local // dim, tuple(shapes[m]))).astype(float)
        for k in range(m, len(shapes)):
            hats, weights = _corners(index / 2.0 ** (k - m), local % dim, shapes[k])
            entries = keeps[k][hats] & (weights != 0)
            rows.append(np.repeat(mine, entries.sum(axis=1)))
            columns.append(firsts[k] + np.searchsorted(kept[k], hats[entries]))
            values.append(weights[entries])
    return sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                         shape=(used.size, firsts[-1]))


def far_functions(points: np.ndarray, components: np.ndarray, sizes: np.ndarray, bodies: np.ndarray) -> Callable:
    """``coarse(inside, contact)`` for :func:`~convexcontact.fem.factorization.slab`: on each body (``bodies``: a
    number per DOF) with contact DOFs (``contact``), :func:`graded_functions` on its DOFs outside the slab
    (``inside``, a mask), zero elsewhere, the finest spacing the body's slab's thickness (its farthest slab DOF from
    its contact DOFs) and at least CELLS of the cells there, coarser where that would give a body more than
    DENSE_COLUMNS functions (the slab keeps those independent in K's energy: :func:`independent`)."""

    def coarse(inside: np.ndarray, contact: np.ndarray) -> Functions:
        nodes, combinations, values, levels = [], [], [], []
        for body in np.unique(bodies[contact]):
            mine = bodies == body
            rest = np.flatnonzero(~inside & mine)
            if rest.size == 0:
                continue
            own_contact = contact[bodies[contact] == body]
            thickness = cKDTree(points[:, own_contact].T).query(points[:, inside & mine].T)[0].max()
            far = np.ascontiguousarray(points[:, rest]), components[rest], sizes[rest]  # numpy's advanced index gives
            # the points column-major: the box and fitted spacing of each try read their rows strided (the pair's
            # foundation at 1.4·10⁶ DOFs: 50 ms a try; its four tries 0.87 → 0.67 s)
            spacing = max(thickness, CELLS * far[2].min())
            tried = []  # (spacing, functions) of each grid tried
            while True:  # at most DENSE_COLUMNS functions a body, so that all of them can be checked
                grids = graded_grids(*far, spacing)
                count = sum(int(keep.sum()) for keep in grids[2])
                if count <= DENSE_COLUMNS:
                    break
                tried.append((spacing, count))
                spacing = coarser(tried, points.shape[0])
            functions = _factored(*far[:2], grids)
            own = functions.nodes
            indptr = np.zeros(inside.size + 1, dtype=np.int64)
            indptr[rest + 1] = np.diff(own.indptr)  # the body's rows among all DOFs
            nodes.append(sp.csr_matrix((own.data, own.indices, np.cumsum(indptr)), shape=(inside.size, own.shape[1])))
            combinations.append(functions.combination)
            values.append(functions.values)
            levels.append(functions.grids)
        if not nodes:
            return Functions(sp.csr_matrix((inside.size, 0)), sp.csr_matrix((0, 0)), sp.csr_matrix((0, 0)),
                             np.zeros(0, dtype=np.int64))
        return Functions(sp.hstack(nodes, format="csr"), sp.block_diag(combinations, format="csr"),
                         sp.block_diag(values, format="csr"), np.concatenate(levels))

    return coarse


def coarser(tried: list, dim: int) -> float:
    """The next grid spacing to try, from the (spacing, functions) of those tried (too many each): the functions
    taken to go as spacing^−e, e = dim at first, then the slope of the last two tries in log–log (within [1, dim]),
    aiming at FILL × DENSE_COLUMNS. A strip's grids are a few rows of nodes high, e ≈ 1: with e = dim the strips
    400 : 1 at 10⁵ DOFs tried 15 / 16 grids (free / clamped) creeping up on DENSE_COLUMNS from above (0.5 of the 1.2 s
    of their coarse functions), now 4 / 3. A row of grid nodes more or less is a jump: the free strip's last grid
    has 2,400 functions (3 rows of nodes → 2; 3,996 before), for 52 products with W against 49 with 3,960."""
    exponent = dim
    if len(tried) > 1 and tried[-1][1] != tried[-2][1]:
        (before, many), (spacing, fewer) = tried[-2:]
        exponent = float(np.clip(np.log(many / fewer) / np.log(spacing / before), 1.0, dim))
    spacing, functions = tried[-1]
    return spacing * (functions / (FILL * DENSE_COLUMNS)) ** (1 / exponent)


def independent(stiffness: sp.spmatrix) -> np.ndarray:
    """The columns, in their order, of functions F whose stiffness Fᵀ K F is ``stiffness`` that are independent in
    K's energy. Block by block (its connected components: K couples no two bodies, so a block is at most one body's
    DENSE_COLUMNS functions), scaled to a unit diagonal: all of a block where a sparse LDLᵀ of it
    (:func:`_least_pivot`) has no pivot below INDEPENDENT (the one-body shapes: the dense factorization took 0.4 of
    the 1.25 s of CPU of the free strip 100 : 1's formulation at 10⁵ DOFs), else those a pivoted Cholesky
    factorization (LAPACK's pstrf) keeps with pivots above INDEPENDENT: the block they keep is definite, either
    factorization its check (:func:`~convexcontact.fem.factorization.slab` factorizes it no more). A sparse
    selection (dropping the LDLᵀ's small pivots and factorizing again) was tried on the pair at 7.7·10⁵ DOFs: after
    20 rounds it kept 2,131 of 3,632 functions and a singular set, where pstrf keeps 3,270."""
    scale = 1.0 / np.sqrt(np.maximum(stiffness.diagonal(), np.finfo(float).tiny))
    stiffness = sp.csr_matrix(sp.diags(scale) @ stiffness @ sp.diags(scale))
    blocks = connected_components(stiffness, directed=False)[1]
    order = np.argsort(blocks, kind="stable")
    kept = []
    for columns in np.split(order, np.flatnonzero(np.diff(blocks[order])) + 1):
        block = sp.csc_matrix(stiffness[columns][:, columns])
        if _least_pivot(block) > INDEPENDENT:
            kept.append(columns)
            continue
        _, pivots, rank, _ = lapack.dpstrf(block.toarray(), lower=1, tol=INDEPENDENT, overwrite_a=1)
        kept.append(columns[pivots[:rank] - 1])
    return np.sort(np.concatenate(kept)) if kept else np.zeros(0, dtype=np.int64)


def _least_pivot(stiffness: sp.csc_matrix) -> float:
    """The least pivot of SuperLU's LDLᵀ of a symmetric matrix (symmetric mode, no pivoting), 0 where it stops at
    a zero one."""
    try:
        factors = spla.splu(stiffness, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True})
    except RuntimeError:  # "Factor is exactly singular"
        return 0.0
    return float(factors.U.diagonal().min(initial=np.inf))


def dof_cell_sizes(fem) -> np.ndarray:
    """Each free DOF's largest cell among those holding it (a cell's size: its bounding box's diagonal). A DOF's
    farthest neighbour in K's graph would not do: on a triangulated strip it is an edge, not a diagonal, at some
    nodes, and the finest grid then followed those (strip 100 : 1 clamped, Tresca: 148 products with W → 223).
    An axis and a local DOF at a time: the DOFs × cells copies of the cells' sizes and DOFs, and the corners' dim ×
    corners × cells, took the pair at 1.4·10⁶ DOFs 0.12 s against 0.065 s (the same sizes)."""
    extents = [np.ptp(axis[fem.mesh.t], axis=0) for axis in fem.mesh.p]  # each axis: the cells' extents
    cells = np.sqrt(sum(extent * extent for extent in extents))
    sizes = np.zeros(fem.basis.N)
    for dofs in fem.basis.element_dofs:  # the cells' DOFs of one local number
        np.maximum.at(sizes, dofs, cells)
    return sizes[fem.free]


def body_far_functions(fem) -> Callable:
    """:func:`far_functions` of an assembled model: its free DOFs, their components, the cells around them, its
    bodies (the connected components of K's graph: a pair's meshes share no node)."""
    components = np.zeros(fem.basis.N, dtype=np.int64)
    for component, dofs in enumerate(fem.basis.split_indices()):
        components[dofs] = component
    points = fem.basis.doflocs[:, fem.free]
    return far_functions(points, components[fem.free], dof_cell_sizes(fem), bodies(fem.K))


def bodies(K: sp.spmatrix) -> np.ndarray:
    """Each DOF's body: the connected components of K's graph. K's pattern is symmetric, so they are its strong
    components, which scipy finds without the transpose its undirected search forms (the pair at 1.4·10⁶ DOFs: 0.12
    against 0.94 s), numbered alike (in the order of their first DOFs)."""
    return connected_components(K, directed=True, connection="strong")[1]
