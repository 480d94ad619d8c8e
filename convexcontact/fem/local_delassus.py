"""The diagonal of the Delassus operator W = B K⁻¹ Bᵀ from the body near each row, without forming W.

W_jj is mostly local: a row's multiplier loads a few nodes, and the displacement it makes there is set by the cells
around them. So d_j = b_jᵀ K_Ω⁻¹ b_j, Ω the DOFs within LAYERS layers of b_j's support (the body clamped beyond),
has W_jj's scale: it follows the cell size of a graded mesh and the stiffness of the body (each side of a pair), which
one step length for all rows cannot (two bodies on graded meshes: W_jj over [2e-5, 4e-2]). d_j ≤ W_jj (a clamped
patch is stiffer); the ratio varies slowly along the face. Rows whose patches neither overlap nor touch have a block
diagonal K on the union of their patches: one solve per colour of a colouring of the rows gives every d_j exactly.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..arrays import group_ranks
from .coarse import bodies

LAYERS = 2
"""Layers of cells around a row's support (patches of ~24 DOFs on a 2-D P1 face, ~220 on a 3-D Q1 face). One layer
on 3-D faces made the diagonal of a plate 20 : 20 : 1 five times cheaper (3.3·10⁴ DOFs: 6.5 → 1.3 s) for the same
Newton steps there, but its cruder step lengths c_j = 0.1 / d_j on the near-null rows of the 3-D pair of spheres
(tangential multipliers of the nodes on its symmetry planes) left its Tresca row at 10⁵ DOFs `inaccurate` after 100
Newton steps (6 steps with two layers) and its Coulomb row matrix-free stalled (docs/performance.md, "Thin bodies")."""

BATCH = 2**20
"""Entries of the dense blocks :func:`_solved` stacks at once (8 MB)."""
DENSE = 256
"""The largest block of a patch :func:`_solved` solves dense: 3-D Q1 faces' patches (225 DOFs, rows of single DOFs)
took 0.64 s dense against 0.70 s by SuperLU, Q2 hexahedra's (735–1215 DOFs) 2.15 s against 1.17 s."""

QUANTUM = 2.0 ** -32
"""Patches whose entries agree to this fraction of their largest are solved once (see :func:`local_diagonal`)."""


def local_diagonal(K: sp.spmatrix, B: sp.spmatrix, layers: int = LAYERS) -> np.ndarray:
    """d_j = b_jᵀ K_Ω⁻¹ b_j for each row b_j of B, Ω_j its support grown through K's graph ``layers`` times. Rows
    whose supports grown once are alike (a node's normal and tangential rows, whose own supports are a component
    each) share their patch: the patches are coloured, and each colour is one factorization with a right-hand side
    per row of a patch (3-D: a third of the factorizations of a colouring by the rows' own supports). A patch the
    same as one solved before (its K block and its rows' loads, numbered in the patch, equal to :data:`QUANTUM`: a
    regular mesh's patches, translated) takes that one's d_j instead of being solved again. Patches are matched by a
    64-bit hash (a collision's odds: patches² / 2⁶⁵); a wrong d_j would only set a step length and a shift of the
    preconditioner, never the answer, which the certificate judges."""
    K, B = sp.csr_matrix(K), sp.csr_matrix(B)
    twins = _twins(K)  # the patches grown on K's nodes, not its DOFs (see _twins)
    heads = np.flatnonzero(np.diff(twins.indices, prepend=-1))  # each node's first DOF, whose row is its node's
    node_graph = _pattern(_ones(K[heads]) @ twins)
    rows = _ones(B) @ twins  # each row's nodes
    reach = sp.csr_matrix(_pattern(rows @ node_graph)) if layers else B  # its support grown once (on nodes)
    support, slot = supports(reach)
    first = np.flatnonzero(slot == 0)  # a row of each patch, in the order of the patches
    nodes = _pattern(reach[first].T if layers else rows[first].T)  # nodes × patches
    for _ in range(layers - 1):
        nodes = _pattern(node_graph @ nodes)
    conflict = _pattern(nodes.T @ _pattern(node_graph @ nodes))  # patches that overlap or touch
    patch = _pattern(twins @ nodes if layers else B[first].T)  # DOFs × patches: a support grown is whole nodes
    rows_of = np.full((first.size, slot.max(initial=0) + 1), -1)  # each patch's rows by slot
    rows_of[support, slot] = np.arange(B.shape[0])
    B_first = _per_row(np.minimum, B.indices, B.indptr)
    inside = np.unique(patch.indices)  # the DOFs of some patch: only their rows are hashed
    K_rows, B_rows = _row_hashes(K, np.arange(K.shape[0]), rows=inside), _row_hashes(B, B_first)
    diagonal, solved = np.zeros(B.shape[0]), {}  # solved: a patch's key -> the patch solved for it
    colours = colouring(conflict)
    for colour in range(colours.max(initial=-1) + 1):
        members = np.flatnonzero(colours == colour)
        members_patch = patch[:, members]
        owner = np.full(K.shape[0], -1)
        owner[members_patch.indices] = np.repeat(np.arange(members.size), np.diff(members_patch.indptr))
        region = np.flatnonzero(owner >= 0)
        owner = owner[region]  # each DOF's member: the patches of a colour do not overlap
        rows = np.flatnonzero(np.isin(support, members))
        of_row = np.searchsorted(members, support[rows])
        base = np.zeros(members.size, dtype=np.int64)
        base[owner[::-1]] = region[::-1]  # each member's first DOF (of repeated writes, the last)
        K_keys = _sums(_mix(K_rows[region] ^ _mix(region - base[owner])), owner, members.size)
        B_keys = _sums(_mix(B_rows[rows] ^ _mix((B_first[rows] - base[of_row]) << 16 | slot[rows])), of_row,
                       members.size)
        sizes = np.bincount(owner, minlength=members.size)
        twin = np.array([solved.setdefault(key, p) for p, key in zip(members, zip(K_keys, B_keys, sizes))])
        fresh = twin == members
        region, rows = region[fresh[owner]], rows[fresh[of_row]]
        if rows.size:
            diagonal[rows] = _solved(K[region][:, region], B[rows][:, region], slot[rows])
        copies, originals = rows_of[members[~fresh]].ravel(), rows_of[twin[~fresh]].ravel()
        diagonal[copies[copies >= 0]] = diagonal[originals[copies >= 0]]  # twins: the same slots
    return diagonal


def _twins(graph: sp.csr_matrix) -> sp.csr_matrix:
    """The DOFs × nodes map of ``graph`` (a symmetric pattern): runs of consecutive rows with one pattern, a node's DOFs
    in a vector field's numbering. A DOF's neighbours are then its node's, and so are the neighbours' nodes: a patch
    grown, and whether two patches touch, are the same on nodes, with d² fewer entries to multiply: grown and coloured
    on DOFs, the patches of a plate 20 : 20 : 1 at 2.6·10⁵ DOFs took 1.3 of the 1.6–2.1 s of its diagonal, which now
    takes 0.85–0.89 s (the same d_j, bit for bit)."""
    n, indptr, indices = graph.shape[0], graph.indptr, graph.indices
    length = np.diff(indptr)
    same = np.zeros(n, dtype=bool)  # row i's pattern is row i − 1's
    candidates = np.flatnonzero(length[1:] == length[:-1]) + 1
    step = max(1, candidates.size * (1 << 16) // max(graph.nnz, 1))
    for start in range(0, candidates.size, step):  # by rows of about 2¹⁶ entries: an index per entry is K-sized
        rows = candidates[start:start + step]
        count = length[rows]
        at = np.repeat(indptr[rows] - np.cumsum(count) + count, count) + np.arange(count.sum())
        differ = indices[at] != indices[at - np.repeat(count, count)]
        same[rows] = np.add.reduceat(differ, np.cumsum(count) - count) == 0 if differ.size else True
    node = np.cumsum(~same) - 1
    return sp.csr_matrix((np.ones(n, dtype=np.int32), (np.arange(n), node)), shape=(n, node[-1] + 1 if n else 0))


def _solved(K_region: sp.csr_matrix, load: sp.csr_matrix, slot: np.ndarray) -> np.ndarray:
    """b_jᵀ K_region⁻¹ b_j for the rows b_j of ``load``, K_region block diagonal (a colour's patches, each one block
    or a few: a mortar row's patch holds a slave and a master part): with blocks of at most DENSE DOFs, the blocks of
    one size stacked dense and solved together (numpy's batched LU), a right-hand side per slot, at most BATCH entries
    at a time; else one sparse factorization (:func:`_factorized`). SuperLU's factorization of each colour's K_region
    took 0.45 s of the 0.8 s of the pair's diagonal at 1.4·10⁶ DOFs (9,816 patches, 60 colours; blocks of 24, 36 and
    42 DOFs); the diagonal now 0.65–0.94 s against 0.81–1.19 (d the same to 5e-16); a 3-D whole face (1.5·10⁴ DOFs in
    the slab) 0.23–0.26 s either way."""
    block = bodies(K_region)  # its blocks: K_region's pattern is symmetric
    size, position = np.bincount(block), group_ranks(block)  # each block's DOFs, each DOF's place in its block
    if size.max(initial=0) > DENSE:
        return _factorized(K_region, load, slot)
    rank = group_ranks(size)  # each block's place among the blocks of its size
    order = np.argsort(size[block] * size.size + block, kind="stable")  # the DOFs by their block's size, block, place
    K = K_region[order]
    row, column = order[np.repeat(np.arange(order.size), np.diff(K.indptr))], K.indices  # each entry's, in K_region
    load = load.tocoo()
    of = block[load.col]
    slots, diagonal, start = slot.max(initial=0) + 1, np.zeros(load.shape[0]), 0
    for n in np.unique(size):
        count = int((size == n).sum())
        step = max(1, BATCH // (n * (n + slots)))
        for first in range(0, count, step):  # blocks first … last of n DOFs: rows start + first·n … start + last·n
            last = min(first + step, count)
            entries = slice(K.indptr[start + first * n], K.indptr[start + last * n])
            A = np.zeros((last - first, n, n))
            A[rank[block[row[entries]]] - first, position[row[entries]], position[column[entries]]] = K.data[entries]
            mine = (size[of] == n) & (rank[of] >= first) & (rank[of] < last)
            at = (rank[of[mine]] - first, position[load.col[mine]], slot[load.row[mine]])
            rhs = np.zeros((last - first, n, slots))
            rhs[at] = load.data[mine]  # a block has one row of each slot at most (one patch's)
            diagonal += np.bincount(load.row[mine], weights=load.data[mine] * np.linalg.solve(A, rhs)[at],
                                    minlength=diagonal.size)
        start += count * n
    return diagonal


def _factorized(K_region: sp.csr_matrix, load: sp.csr_matrix, slot: np.ndarray) -> np.ndarray:
    """:func:`_solved` by one SuperLU factorization of K_region and a right-hand side per slot."""
    by_slot = sp.csr_matrix((np.ones(slot.size), (slot, np.arange(slot.size))))
    response = spla.splu(sp.csc_matrix(K_region)).solve((by_slot @ load).T.toarray())
    # b_j · (the response of row j's slot): other rows of a slot act on other blocks of K_region. Picked from the
    # rows × slots products; the rows × region array of each row's slot's response this replaces was the contact
    # solve's peak on thin bodies (strip 400 : 1 clamped, 3.4·10⁴ DOFs: 67 of 97 MB)
    return (load @ response)[np.arange(slot.size), slot]


def supports(B: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """For each row of ``B``: the index of its support (the set of its stored columns, numbered in order of first
    appearance) and its rank among the rows of that support."""
    numbers: dict = {}
    support = np.array([numbers.setdefault(B.indices[B.indptr[j]:B.indptr[j + 1]].tobytes(), len(numbers))
                        for j in range(B.shape[0])], dtype=int)
    return support, group_ranks(support)


def colouring(conflict: sp.csr_matrix) -> np.ndarray:
    """Colours of the rows of a symmetric ``conflict`` pattern such that no two conflicting rows share one: greedy
    first fit, each row the least colour none of its coloured neighbours has (at most its degree + 1 colours).

    A loop over the rows (scipy has no graph colouring), O(nnz) in all: the rounds of Luby's rule it replaces each
    scanned the whole pattern, one round per colour and more, and on 3-D faces (~250 neighbours a row) took 31 of
    the 38 s of a Tresca solve on a 1.3·10³-DOF plate and 80 of 117 s at 10⁴ DOFs."""
    conflict = sp.csr_matrix(_pattern(conflict))
    m, indptr, indices = conflict.shape[0], conflict.indptr, conflict.indices
    colours = np.full(m, -1)
    taken = np.zeros(int(np.diff(indptr).max(initial=0)) + 2, dtype=bool)  # the colours of one row's neighbours
    for row in range(m):
        around = colours[indices[indptr[row]:indptr[row + 1]]]
        around = around[around >= 0]
        taken[around] = True
        colours[row] = np.argmin(taken)
        taken[around] = False
    return colours


def _row_hashes(A: sp.csr_matrix, reference: np.ndarray, chunk: int = 1 << 14, rows: np.ndarray | None = None
                ) -> np.ndarray:
    """A 64-bit hash of each row of ``A`` (of ``rows``, if given; 0 for the others): its stored columns less the row's
    ``reference`` column, and its entries rounded to QUANTUM of the row's largest. Rows alike up to a shift of the
    numbering hash alike. By rows of about ``chunk`` entries: a few arrays of A's entries at once held ~5 × K's bytes
    (the diagonal's peak)."""
    hashes = np.zeros(A.shape[0], dtype=np.uint64)
    rows = np.arange(A.shape[0]) if rows is None else rows
    step = max(1, rows.size * chunk // max(A.nnz, 1))
    for start in range(0, rows.size, step):
        taken = rows[start:start + step]
        block = A[taken]
        row = np.repeat(np.arange(taken.size), np.diff(block.indptr))
        largest = _per_row(np.maximum, np.abs(block.data), block.indptr)
        level = np.rint(block.data / np.where(largest > 0, largest, 1.0)[row] / QUANTUM).astype(np.int64)
        hashed = _mix(_mix(block.indices - reference[taken[row]]) ^ level.view(np.uint64))
        hashes[taken] = _sums(hashed, row, taken.size)
    return hashes


def _per_row(ufunc: np.ufunc, values: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """``ufunc`` reduced over each row's ``values`` (CSR ``indptr``), 0 for an empty row."""
    out = np.zeros(indptr.size - 1, dtype=values.dtype)
    stored = np.diff(indptr) > 0
    if stored.any():  # reduceat over the rows that store: an empty row's start is the next row's
        out[stored] = ufunc.reduceat(values, indptr[:-1][stored])
    return out


def _sums(hashed: np.ndarray, group: np.ndarray, groups: int) -> np.ndarray:
    """The sum of the ``hashed`` of each group (wrapping): a hash of the group's items whatever their order."""
    total = np.zeros(groups, dtype=np.uint64)
    np.add.at(total, group, hashed)
    return total


def _mix(x: np.ndarray) -> np.ndarray:
    """splitmix64's finalizer on integers as uint64s (wrapping): numpy has no vectorized hash."""
    x = np.asarray(x).astype(np.int64).view(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _ones(A: sp.csr_matrix) -> sp.csr_matrix:
    """The stored entries of a CSR matrix as ones, on its own index arrays (no conversion)."""
    return sp.csr_matrix((np.ones(A.nnz, dtype=np.int32), A.indices, A.indptr), shape=A.shape)


def _pattern(A: sp.spmatrix) -> sp.csc_matrix:
    """The stored entries of A as ones (a new matrix)."""
    A = sp.csc_matrix(A)
    return sp.csc_matrix((np.ones(A.nnz, dtype=np.int32), A.indices, A.indptr), shape=A.shape)
