"""FClib's HDF5 format (Siconos' frictional-contact problem library), read and written with h5py.

The layout is the one of ``src/fclib.h`` of FrictionalContactLibrary/fclib:

- ``/fclib_local/{spacedim, W, [V, R], vectors/{q, mu, [s]}, info}``: find u = W r + q and r with
  C*_μ ∋ û ⊥ r ∈ C_μ, û = u + [μ‖u_T‖, 0, 0] per contact (De Saxcé's form of Coulomb's law);
- ``/fclib_global/{spacedim, M, H, [G], vectors/{f, w, mu, [b]}, info}``: M v = H r + G λ + f,
  Gᵀ v + b = 0, u = Hᵀ v + w, and the same law on (u, r);
- a matrix is a group ``nzmax, m, n, nz, p, i, x``, integers as int32 arrays of one entry: nz ≥ 0 a
  triplet with the ROW indices in ``i`` and the COLUMN indices in ``p`` (see :func:`read_matrix`: fclib.h's
  comment says the opposite, fclib's and Siconos' code do this); −1 compressed columns; −2 compressed rows;
- each contact's unknowns are ordered [N, T1(, T2)]; ``spacedim`` is 2 or 3;
- ``/solution/{v, u, r, [l]}`` and ``/guesses/{number_of_guesses, 1/…, 2/…}``.

Every dataset is checked where it is read, and a bad one is refused with a ValueError that starts with
its path in the file (``fclib_local/vectors/q: missing; …``). Everything here is data: no mechanics,
no solver.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

INFO = ("title", "description", "math_info")
LOCAL = "an FClib local problem needs W, q and mu (fclib.h)"
GLOBAL = "an FClib global problem needs M, H, f, w and mu (fclib.h)"
MATRIX = "an FClib matrix is a group of m, n, nz, p, i and x (fclib.h)"
SYMMETRY = 1e-10
"""An M with max |M − Mᵀ| above this × max |M| is reported not symmetric (below: assembly round-off)."""


def _h5py():
    try:
        import h5py
    except ImportError:
        raise ImportError("FClib files need h5py: pip install 'convexcontact[fclib]' (or pip install h5py)") from None
    return h5py


@dataclass
class LocalProblem:
    """FClib's local (Delassus) problem FC(W, q, μ); ``V``, ``R``, ``s`` are its optional equalities.
    ``warnings`` says what the reader did to the file's data (e.g. a matrix stored as one triangle)."""

    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    spacedim: int
    info: dict = field(default_factory=dict)
    V: sp.csr_matrix | None = None
    R: sp.csr_matrix | None = None
    s: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)

    def __post_init__(self):
        check_finite("fclib_local", {"W/x": self.W, "vectors/q": self.q, "V/x": self.V, "R/x": self.R,
                                     "vectors/s": self.s})
        check_contacts(self.W.shape[0], self.spacedim, self.mu, "fclib_local/W")
        if self.W.shape != (self.q.size, self.q.size):
            raise ValueError(f"fclib_local/W: {self.W.shape[0]} × {self.W.shape[1]} but vectors/q has {self.q.size} "
                             "entries; W must be square, of q's size")
        if self.V is not None or self.R is not None or self.s is not None:
            p = -1 if self.s is None else self.s.size
            if self.V is None or self.R is None or self.V.shape != (self.q.size, p) or self.R.shape != (p, p):
                raise ValueError("fclib_local/V, R, vectors/s: the equalities Vᵀ r + R λ + s = 0 need all three, "
                                 f"V ({self.q.size} × p), R (p × p), s (p)")


@dataclass
class GlobalProblem:
    """FClib's global problem: M v = H r + G λ + f, Gᵀ v + b = 0, u = Hᵀ v + w, Coulomb on (u, r)."""

    M: sp.csr_matrix
    H: sp.csr_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    spacedim: int
    info: dict = field(default_factory=dict)
    G: sp.csr_matrix | None = None
    b: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)

    def __post_init__(self):
        check_finite("fclib_global", {"M/x": self.M, "H/x": self.H, "vectors/f": self.f, "vectors/w": self.w,
                                      "G/x": self.G, "vectors/b": self.b})
        check_contacts(self.H.shape[1], self.spacedim, self.mu, "fclib_global/H")
        if self.M.shape != (self.f.size, self.f.size) or self.H.shape[0] != self.f.size or self.w.size != self.H.shape[1]:
            raise ValueError(f"fclib_global/M, H: M {self.M.shape}, H {self.H.shape}, f ({self.f.size}) and w "
                             f"({self.w.size}) do not fit together; M is n × n, H n × m, f of n and w of m entries")


@dataclass
class Solution:
    """A solution or a guess: contact forces r, local velocities u, [global velocities v, multipliers l]."""

    r: np.ndarray
    u: np.ndarray
    v: np.ndarray | None = None
    l: np.ndarray | None = None  # multipliers of FClib's equalities (its name)


def check_finite(top: str, arrays: dict) -> None:
    """Refuse NaN or ±inf in a problem's vectors and matrices (None: absent)."""
    for name, value in arrays.items():
        values = value.data if sp.issparse(value) else value
        if values is not None and not np.all(np.isfinite(values)):
            raise ValueError(f"{top}/{name}: not finite (NaN or ±inf); an FClib problem holds finite numbers")


def check_contacts(size: int, spacedim: int, mu: np.ndarray, where: str) -> None:
    top = where.split("/")[0]
    if spacedim not in (2, 3):
        raise ValueError(f"{top}/spacedim: must be 2 or 3, got {spacedim}")
    if size % spacedim or mu.size != size // spacedim:
        raise ValueError(f"{where}: {size} contact unknowns are not {mu.size} contacts (vectors/mu) of {spacedim}; "
                         f"{top}/vectors/mu needs one coefficient per contact")
    if not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise ValueError(f"{top}/vectors/mu: friction coefficients must be finite and ≥ 0")


# --- datasets, each checked where it is read -------------------------------------------------------------------

def _where(node, name: str = "") -> str:
    return f"{node.name.strip('/')}/{name}".strip("/")


def _child(parent, name: str, group: bool, need: str | None = None):
    """``parent[name]``, a group or a dataset as asked; None when absent and ``need`` is None (optional)."""
    h5py = _h5py()
    where = _where(parent, name)
    if name not in parent:
        if need is None:
            return None
        raise ValueError(f"{where}: missing; {need}")
    node = parent.get(name)
    kind = h5py.Group if group else h5py.Dataset
    if isinstance(node, kind):
        return node
    found = "a broken link" if node is None else f"a {type(node).__name__.lower()}"
    raise ValueError(f"{where}: expected a{' group' if group else ' dataset'}, found {found}")


def _values(dataset, kinds: str, expected: str) -> np.ndarray:
    """A dataset's values as a flat array, refused unless its type is one of numpy's ``kinds``."""
    where = _where(dataset)
    if dataset.dtype.kind not in kinds:
        raise ValueError(f"{where}: expected {expected}, got HDF5 type {dataset.dtype}")
    if dataset.shape is None:
        raise ValueError(f"{where}: an empty (null) dataset; expected {expected}")
    try:
        return np.asarray(dataset[()]).ravel()
    except (OSError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: unreadable ({error})") from None


def _vector(group, name: str, need: str | None = None) -> np.ndarray | None:
    """A vector of finite floats (None when optional and absent)."""
    dataset = _child(group, name, False, need)
    if dataset is None:
        return None
    values = _values(dataset, "iuf", "numbers (float64 as fclib writes)").astype(float)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise ValueError(f"{_where(dataset)}: entry {bad[0]} is {values[bad[0]]} ({bad.size} not finite); "
                         "an FClib problem holds finite numbers")
    return values


def _integer(group, name: str, need: str) -> int:
    """One integer (fclib writes int32 arrays of one entry)."""
    dataset = _child(group, name, False, need)
    values = _values(dataset, "iu", "one integer (int32 as fclib writes)")
    if values.size != 1:
        raise ValueError(f"{_where(dataset)}: expected one integer, got {values.size} entries")
    return int(values[0])


def _integers(group, name: str) -> np.ndarray:
    dataset = _child(group, name, False, MATRIX)
    return _values(dataset, "iu", "integer indices (int32 as fclib writes)").astype(np.int64)


def _indices(group, name: str, count: int, bound: int, what: str) -> np.ndarray:
    """The first ``count`` entries of an index array, each in [0, bound)."""
    values, where = _integers(group, name), _where(group, name)
    if values.size < count:
        raise ValueError(f"{where}: {values.size} entries, the matrix needs {count}")
    values = values[:count]
    outside = np.flatnonzero((values < 0) | (values >= bound))
    if outside.size:
        raise ValueError(f"{where}: entry {outside[0]} is {values[outside[0]]}, outside the {bound} {what} "
                         f"[0, {bound}); the file is damaged or not in FClib's layout")
    return values


def _pointers(group, count: int, length: int) -> np.ndarray:
    """Compressed storage's ``p``: count + 1 nondecreasing offsets from 0 to at most ``length``."""
    p, where = _integers(group, "p"), _where(group, "p")
    if p.size != count + 1:
        raise ValueError(f"{where}: {p.size} pointers; compressed storage of {count} columns (nz = −1) or rows "
                         f"(nz = −2) needs {count + 1}")
    if p[0] != 0 or np.any(np.diff(p) < 0):
        raise ValueError(f"{where}: not nondecreasing from 0 (got {p[:6].tolist()}…); the file is damaged")
    if p[-1] > length:
        raise ValueError(f"{where}: ends at {p[-1]}, but i and x hold {length} entries; the file is damaged")
    return p


def read_matrix(group, shape: tuple[int, int] | None = None) -> sp.csr_matrix:
    """A sparse matrix from an FClib matrix group, checked before scipy sees it (``shape``: the one the vectors
    give it, refused otherwise before anything is allocated).

    Triplets (nz ≥ 0) hold each entry's ROW index in ``i`` and its COLUMN index in ``p``. fclib.h's struct
    comment says the opposite ("triplet: row indices" for p), but fclib's own code and Siconos' use CSparse's
    convention, which is this one: fclib's ``fclib_merit_local`` hands its matrices to CSparse as ``(cs *)`` casts
    of ``struct fclib_matrix`` (the same fields in the same order), and CSparse's ``cs`` says "p: column pointers
    (size n+1) or col indices (size nzmax); i: row indices" (``cs_entry`` stores ``T->i = i`` the row and
    ``T->p = j`` the column; ``cs_compress`` counts columns on ``T->p``); Siconos' ``fclib_interface.c`` copies ``p``
    to ``p`` and ``i`` to ``i`` between fclib's struct and its CSparse triplets, both ways; and every triplet H in
    Siconos' test data (n ≠ m) has its ``p`` below n and its ``i`` below m, impossible the other way round.
    Duplicate entries are summed (CSparse's ``cs_dupl``, scipy alike).
    """
    where = _where(group)
    m, n, nz = (_integer(group, key, MATRIX) for key in ("m", "n", "nz"))
    if m < 0 or n < 0:
        raise ValueError(f"{where}/{'m' if m < 0 else 'n'}: {min(m, n)} rows or columns; sizes are ≥ 0")
    if shape is not None and (m, n) != tuple(shape):
        raise ValueError(f"{where}/m, n: {m} × {n}, but the problem's vectors make it {shape[0]} × {shape[1]}")
    if nz < -2:
        raise ValueError(f"{where}/nz: {nz} is no FClib storage (≥ 0 triplet, −1 compressed columns, −2 rows)")
    if nz >= 0:
        rows, columns = _indices(group, "i", nz, m, "rows"), _indices(group, "p", nz, n, "columns")
        x = _entries(group, nz)
        return sp.csr_matrix(sp.coo_matrix((x, (rows, columns)), shape=(m, n)))
    outer, inner = (n, m) if nz == -1 else (m, n)
    p = _pointers(group, outer, min(_integers(group, "i").size, _vector(group, "x", MATRIX).size))
    i = _indices(group, "i", int(p[-1]), inner, "rows" if nz == -1 else "columns")
    x = _entries(group, int(p[-1]))
    build = sp.csc_matrix if nz == -1 else sp.csr_matrix
    return sp.csr_matrix(build((x, i, p), shape=(m, n)))


def _entries(group, count: int) -> np.ndarray:
    x = _vector(group, "x", MATRIX)
    if x.size < count:
        raise ValueError(f"{_where(group, 'x')}: {x.size} values, the matrix needs {count}")
    return x[:count]


def one_triangle(A: sp.csr_matrix, where: str) -> tuple[sp.csr_matrix, str | None]:
    """A square matrix FClib declares symmetric, stored as one triangle (every off-diagonal entry on one side of
    the diagonal, some there): the symmetric matrix it stands for, A + Aᵀ − diag A, and a warning; else A, None.

    LMGC90's dumps through Siconos (``gfc3d_LmgcDriver.c``) hold M's upper triangle only. Siconos' reader
    (``from_fclib_global``) keeps the triplet as it is and its solvers then disagree: ``NM_LU_solve`` factors
    the literal triangle, ``gfc3d_ipm`` "symmetrizes" it to ½(A + Aᵀ), MUMPS in symmetric mode would read the
    triangle as the whole. fclib.h says M is symmetric positive definite; a triangle with entries off the
    diagonal is not symmetric, and the only symmetric matrix it determines is the expansion. Read once, here,
    every backend and every certificate use that matrix.
    """
    A = sp.csr_matrix(A)
    upper, lower = sp.triu(A, 1).count_nonzero(), sp.tril(A, -1).count_nonzero()
    if A.shape[0] != A.shape[1] or (upper == 0) == (lower == 0):
        return A, None
    full = sp.csr_matrix(A + A.T - sp.diags(A.diagonal()))
    return full, (f"{where}: stored as its {'upper' if upper else 'lower'} triangle only ({upper or lower} entries "
                  f"off the diagonal, none {'below' if upper else 'above'} it); read as the symmetric matrix it stands "
                  "for, the triangle plus its transpose (fclib.h: M is symmetric positive definite)")


def _definite(M: sp.csr_matrix, where: str) -> tuple[sp.csr_matrix, list[str]]:
    """M as FClib's symmetric positive definite matrix: one stored triangle expanded (warned), a diagonal entry
    ≤ 0 refused (xᵀ M x > 0 needs them all > 0: an all-zero M is refused here), a non-symmetric M kept as stored
    (the file's problem) and warned of."""
    M, warning = one_triangle(M, where)
    warnings = [warning] if warning else []
    diagonal = M.diagonal()
    if diagonal.size and diagonal.min() <= 0:
        k = int(np.argmin(diagonal))
        raise ValueError(f"{where}: diagonal entry {k} is {diagonal[k]:.3g}; M is positive definite (fclib.h), so "
                         "every diagonal entry is > 0")
    asymmetry = abs(M - M.T).max() if M.nnz else 0.0
    if asymmetry > SYMMETRY * abs(M).max():
        warnings.append(f"{where}: not symmetric (max |M − Mᵀ| = {asymmetry:.3g}, max |M| = {abs(M).max():.3g}) "
                        "although fclib.h says it is; kept as stored")
    return M, warnings


def _semidefinite_diagonal(W: sp.csr_matrix, where: str) -> None:
    diagonal = W.diagonal()
    if diagonal.size and diagonal.min() < 0:
        k = int(np.argmin(diagonal))
        raise ValueError(f"{where}: diagonal entry {k} is {diagonal[k]:.3g} < 0; W is positive semi-definite "
                         "(fclib.h), so its diagonal is ≥ 0")


def _info(group) -> dict:
    info = _child(group, "info", True)
    if info is None:
        return {}
    found = {}
    for name in INFO:
        dataset = _child(info, name, False)
        if dataset is not None:
            value = dataset[()]
            found[name] = value.decode(errors="replace") if isinstance(value, bytes) else str(value)
    return found


def _spacedim(group, need: str) -> int:
    spacedim = _integer(group, "spacedim", need)
    if spacedim not in (2, 3):
        raise ValueError(f"{_where(group, 'spacedim')}: must be 2 or 3, got {spacedim}")
    return spacedim


def _matrix(group, name: str, shape: tuple[int, int], need: str | None = None) -> sp.csr_matrix | None:
    node = _child(group, name, True, need)
    return None if node is None else read_matrix(node, shape)


def _local(g) -> LocalProblem:
    vectors = _child(g, "vectors", True, LOCAL)
    q, mu, s = _vector(vectors, "q", LOCAL), _vector(vectors, "mu", LOCAL), _vector(vectors, "s")
    spacedim = _spacedim(g, LOCAL)
    m, p = q.size, 0 if s is None else s.size
    W = _matrix(g, "W", (m, m), LOCAL)
    _semidefinite_diagonal(W, _where(g, "W"))
    V, R = _matrix(g, "V", (m, p)), _matrix(g, "R", (p, p))
    return LocalProblem(W, q, mu, spacedim, _info(g), V, R, s)


def _global(g) -> GlobalProblem:
    vectors = _child(g, "vectors", True, GLOBAL)
    f, w, mu = (_vector(vectors, name, GLOBAL) for name in ("f", "w", "mu"))
    b = _vector(vectors, "b")
    spacedim = _spacedim(g, GLOBAL)
    M, warnings = _definite(_matrix(g, "M", (f.size, f.size), GLOBAL), _where(g, "M"))
    H = _matrix(g, "H", (f.size, w.size), GLOBAL)
    G = _matrix(g, "G", (f.size, 0 if b is None else b.size))
    if (G is None) != (b is None):
        raise ValueError(f"{_where(g, 'G' if b is not None else 'vectors/b')}: missing; the equalities Gᵀ v + b = 0 "
                         "need both G and b (fclib.h)")
    return GlobalProblem(M, H, f, w, mu, spacedim, _info(g), G, b, warnings)


def _solution(group, sizes: dict) -> Solution:
    """A /solution or guess: r and u of the contact unknowns' size, v of M's, l of the equalities'."""
    found = {}
    for name, size in sizes.items():
        value = _vector(group, name)
        if value is not None and size is not None and value.size != size:
            raise ValueError(f"{_where(group, name)}: {value.size} entries, the problem needs {size}")
        found[name] = value
    return Solution(**found)


def _answers(file, problem) -> tuple[Solution | None, list[Solution]]:
    local = isinstance(problem, LocalProblem)
    equalities = (problem.s if local else problem.b)
    sizes = {"r": problem.mu.size * problem.spacedim, "u": problem.mu.size * problem.spacedim,
             "v": None if local else problem.f.size, "l": 0 if equalities is None else equalities.size}
    group = _child(file, "solution", True)
    solution = None if group is None else _solution(group, sizes)
    guesses = _child(file, "guesses", True)
    if guesses is None:
        return solution, []
    count = _integer(guesses, "number_of_guesses", "/guesses holds number_of_guesses and groups 1, 2, … (fclib.h)")
    if count < 0:
        raise ValueError(f"guesses/number_of_guesses: {count} < 0")
    need = f"number_of_guesses is {count}, so groups 1 … {count} (fclib.h)"
    return solution, [_solution(_child(guesses, str(k), True, need), sizes) for k in range(1, count + 1)]


def read(path) -> tuple[LocalProblem | GlobalProblem, Solution | None, list[Solution]]:
    """The problem stored in ``path``, its ``/solution`` (None when absent) and its ``/guesses``.

    Every dataset is checked as it is read; a bad one raises a ValueError starting with its path in the file.
    What the reader changes in the data (a symmetric matrix stored as one triangle) is listed in
    ``problem.warnings``."""
    h5py = _h5py()
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: {'a folder' if path.is_dir() else 'no such file'}; give an FClib HDF5 file")
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise ValueError(f"{path}: not an HDF5 file ({error})") from None
    with file:
        try:
            return _read(file, path)
        except (OSError, RuntimeError, KeyError) as error:  # h5py on a damaged file, past our checks
            raise ValueError(f"{path}: damaged HDF5 file ({error})") from None


def _read(file, path: Path):
    if "fclib_local" in file:
        problem = _local(_child(file, "fclib_local", True))
    elif "fclib_global" in file:
        problem = _global(_child(file, "fclib_global", True))
    else:
        found = sorted(file.keys())
        rolling = " (fclib_global_rolling is not supported)" if "fclib_global_rolling" in found else ""
        raise ValueError(f"{path}: no /fclib_local nor /fclib_global group (found {found}){rolling}; "
                         "is it an FClib file?")
    return (problem, *_answers(file, problem))


def write_matrix(group, matrix: sp.spmatrix) -> None:
    """An FClib matrix group in compressed columns (nz = −1: the form fclib's merit function multiplies, and one
    fclib and Siconos' ``from_fclib_local``/``from_fclib_global`` read)."""
    A = sp.csc_matrix(matrix)
    A.sort_indices()
    one = {"nzmax": A.nnz, "m": A.shape[0], "n": A.shape[1], "nz": -1}
    for name, value in one.items():
        group.create_dataset(name, data=np.array([value], dtype=np.int32))
    group.create_dataset("p", data=A.indptr.astype(np.int32))
    group.create_dataset("i", data=A.indices.astype(np.int32))
    group.create_dataset("x", data=A.data.astype(np.float64))


def _write_solution(group, solution: Solution) -> None:
    for name in ("v", "u", "r", "l"):
        value = getattr(solution, name)
        if value is not None:
            group.create_dataset(name, data=np.asarray(value, dtype=np.float64))


def write(path, problem: LocalProblem | GlobalProblem, solution: Solution | None = None,
          guesses: tuple[Solution, ...] = ()) -> Path:
    """Write ``problem`` (and its solution and guesses) to the FClib file ``path``, whole or not at all (written
    beside it, then moved in)."""
    path = Path(path)
    staging = path.with_name(f".{path.name}.unfinished")
    try:
        _write(staging, problem, solution, guesses)
        os.replace(staging, path)
    finally:
        staging.unlink(missing_ok=True)
    return path


def _write(path, problem, solution, guesses) -> None:
    h5py = _h5py()
    local = isinstance(problem, LocalProblem)
    with h5py.File(path, "w") as file:
        g = file.create_group("fclib_local" if local else "fclib_global")
        g.create_dataset("spacedim", data=np.array([problem.spacedim], dtype=np.int32))
        matrices = {"W": problem.W, "V": problem.V, "R": problem.R} if local else \
            {"M": problem.M, "H": problem.H, "G": problem.G}
        for name, matrix in matrices.items():
            if matrix is not None:
                write_matrix(g.create_group(name), matrix)
        vectors = {"q": problem.q, "mu": problem.mu, "s": problem.s} if local else \
            {"f": problem.f, "w": problem.w, "mu": problem.mu, "b": problem.b}
        group = g.create_group("vectors")
        for name, value in vectors.items():
            if value is not None:
                group.create_dataset(name, data=np.asarray(value, dtype=np.float64))
        if problem.info:
            info = g.create_group("info")
            for name in INFO:
                if name in problem.info:
                    info.create_dataset(name, data=np.bytes_(str(problem.info[name]).encode()))
        if solution is not None:
            _write_solution(file.create_group("solution"), solution)
        if guesses:
            group = file.create_group("guesses")
            group.create_dataset("number_of_guesses", data=np.array([len(guesses)], dtype=np.int32))
            for k, guess in enumerate(guesses, start=1):
                _write_solution(group.create_group(str(k)), guess)
