"""FClib's HDF5 format (Siconos' frictional-contact problem library), read and written with h5py.

The layout is the one of ``src/fclib.h`` of FrictionalContactLibrary/fclib:

- ``/fclib_local/{spacedim, W, [V, R], vectors/{q, mu, [s]}, info}``: find u = W r + q and r with
  C*_μ ∋ û ⊥ r ∈ C_μ, û = u + [μ‖u_T‖, 0, 0] per contact (De Saxcé's form of Coulomb's law);
- ``/fclib_global/{spacedim, M, H, [G], vectors/{f, w, mu, [b]}, info}``: M v = H r + G λ + f,
  Gᵀ v + b = 0, u = Hᵀ v + w, and the same law on (u, r);
- a matrix is a group ``nzmax, m, n, nz, p, i, x`` (nz ≥ 0: triplet with p the rows and i the
  columns; −1: compressed columns; −2: compressed rows), integers as int32 arrays of one entry;
- each contact's unknowns are ordered [N, T1(, T2)]; ``spacedim`` is 2 or 3;
- ``/solution/{v, u, r, [l]}`` and ``/guesses/{number_of_guesses, 1/…, 2/…}``.

Everything here is data: no mechanics, no solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

INFO = ("title", "description", "math_info")


def _h5py():
    try:
        import h5py
    except ImportError:
        raise ImportError("FClib files need h5py: pip install 'convexcontact[fclib]' (or pip install h5py)") from None
    return h5py


@dataclass
class LocalProblem:
    """FClib's local (Delassus) problem FC(W, q, μ); ``V``, ``R``, ``s`` are its optional equalities."""

    W: sp.csr_matrix
    q: np.ndarray
    mu: np.ndarray
    spacedim: int
    info: dict = field(default_factory=dict)
    V: sp.csr_matrix | None = None
    R: sp.csr_matrix | None = None
    s: np.ndarray | None = None

    def __post_init__(self):
        check_contacts(self.W.shape[0], self.spacedim, self.mu, "fclib_local/W")
        if self.W.shape != (self.q.size, self.q.size):
            raise ValueError(f"fclib_local: W is {self.W.shape} but q has {self.q.size} entries")
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

    def __post_init__(self):
        check_contacts(self.H.shape[1], self.spacedim, self.mu, "fclib_global/H")
        if self.M.shape != (self.f.size, self.f.size) or self.H.shape[0] != self.f.size or self.w.size != self.H.shape[1]:
            raise ValueError(f"fclib_global: M {self.M.shape}, H {self.H.shape}, f ({self.f.size}) and w "
                             f"({self.w.size}) do not fit together")


@dataclass
class Solution:
    """A solution or a guess: contact forces r, local velocities u, [global velocities v, multipliers l]."""

    r: np.ndarray
    u: np.ndarray
    v: np.ndarray | None = None
    l: np.ndarray | None = None  # multipliers of FClib's equalities (its name)


def check_contacts(size: int, spacedim: int, mu: np.ndarray, where: str) -> None:
    if spacedim not in (2, 3):
        raise ValueError(f"{where.split('/')[0]}/spacedim: must be 2 or 3, got {spacedim}")
    if size % spacedim or mu.size != size // spacedim:
        raise ValueError(f"{where}: {size} contact unknowns are not {mu.size} contacts (mu) of {spacedim}")
    if not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise ValueError(f"{where.split('/')[0]}/vectors/mu: friction coefficients must be finite and ≥ 0")


def read_matrix(group) -> sp.csr_matrix:
    """A sparse matrix from an FClib matrix group (triplet, CSC or CSR)."""
    scalar = {name: int(np.asarray(group[name][()]).ravel()[0]) for name in ("m", "n", "nz")}
    m, n, nz = scalar["m"], scalar["n"], scalar["nz"]
    p, i, x = (np.asarray(group[name][()]).ravel() for name in ("p", "i", "x"))
    if nz >= 0:
        return sp.csr_matrix((x[:nz], (p[:nz], i[:nz])), shape=(m, n))
    if nz == -1:
        return sp.csc_matrix((x[: p[-1]], i[: p[-1]], p), shape=(m, n)).tocsr()
    if nz == -2:
        return sp.csr_matrix((x[: p[-1]], i[: p[-1]], p), shape=(m, n))
    raise ValueError(f"{group.name}/nz: {nz} is no FClib storage (≥ 0 triplet, −1 CSC, −2 CSR)")


def write_matrix(group, matrix: sp.spmatrix) -> None:
    """An FClib matrix group in compressed columns (nz = −1: the form fclib's merit function multiplies)."""
    A = sp.csc_matrix(matrix)
    A.sort_indices()
    one = {"nzmax": A.nnz, "m": A.shape[0], "n": A.shape[1], "nz": -1}
    for name, value in one.items():
        group.create_dataset(name, data=np.array([value], dtype=np.int32))
    group.create_dataset("p", data=A.indptr.astype(np.int32))
    group.create_dataset("i", data=A.indices.astype(np.int32))
    group.create_dataset("x", data=A.data.astype(np.float64))


def _vector(group, name):
    return np.asarray(group[name][()], dtype=float).ravel() if name in group else None


def _info(group) -> dict:
    if "info" not in group:
        return {}
    found = {name: group["info"][name][()] for name in INFO if name in group["info"]}
    return {k: v.decode(errors="replace") if isinstance(v, bytes) else str(v) for k, v in found.items()}


def _spacedim(group) -> int:
    return int(np.asarray(group["spacedim"][()]).ravel()[0])


def _solution(group) -> Solution:
    return Solution(**{name: _vector(group, name) for name in ("r", "u", "v", "l")})


def read(path) -> tuple[LocalProblem | GlobalProblem, Solution | None, list[Solution]]:
    """The problem stored in ``path``, its ``/solution`` (None when absent) and its ``/guesses``."""
    h5py = _h5py()
    with h5py.File(path, "r") as file:
        if "fclib_local" in file:
            g = file["fclib_local"]
            vectors = g["vectors"]
            extra = {k: read_matrix(g[k]) for k in ("V", "R") if k in g}
            problem = LocalProblem(read_matrix(g["W"]), _vector(vectors, "q"), _vector(vectors, "mu"), _spacedim(g),
                                   _info(g), s=_vector(vectors, "s"), **extra)
        elif "fclib_global" in file:
            g = file["fclib_global"]
            vectors = g["vectors"]
            problem = GlobalProblem(read_matrix(g["M"]), read_matrix(g["H"]), _vector(vectors, "f"),
                                    _vector(vectors, "w"), _vector(vectors, "mu"), _spacedim(g), _info(g),
                                    read_matrix(g["G"]) if "G" in g else None, _vector(vectors, "b"))
        else:
            found = sorted(file.keys())
            raise ValueError(f"{path}: no /fclib_local nor /fclib_global group (found {found}); is it an FClib file?")
        solution = _solution(file["solution"]) if "solution" in file else None
        guesses = []
        if "guesses" in file:
            count = int(np.asarray(file["guesses/number_of_guesses"][()]).ravel()[0])
            guesses = [_solution(file[f"guesses/{k}"]) for k in range(1, count + 1)]
    return problem, solution, guesses


def _write_solution(group, solution: Solution) -> None:
    for name in ("v", "u", "r", "l"):
        value = getattr(solution, name)
        if value is not None:
            group.create_dataset(name, data=np.asarray(value, dtype=np.float64))


def write(path, problem: LocalProblem | GlobalProblem, solution: Solution | None = None,
          guesses: tuple[Solution, ...] = ()) -> Path:
    """Write ``problem`` (and its solution and guesses) to a new FClib file ``path``."""
    h5py = _h5py()
    path = Path(path)
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
    return path
