"""Sparse direct solvers on convexcontact stiffness matrices (issue 5).

Assembles P1/Q1 linear-elasticity stiffness matrices K with scikit-fem (unit square or
cube, Dirichlet bottom eliminated), builds a contact operator B (m rows, each a rotated
nodal frame row on one of the top-most nodes, so every row touches `dim` DOFs) and, for
every (matrix, solver) pair, runs a FRESH subprocess that measures

* ``fact``   factorization time of K (analysis + numeric) [s]
* ``solve1`` one solve with a random right-hand side [s] (and its relative residual)
* ``W``      building the Delassus operator W = B K^-1 B^T by one multi-RHS solve with
             the m dense columns of B^T (or blocks of --chunk columns), plus B X [s]
* ``init``   one-time start-up: factorizing a 4x4 matrix first (thread pools, dispatch) [s]
* ``mem_f``  peak RSS growth during the factorization [MB] (peak counter reset first)
* ``mem_W``  peak RSS growth after the multi-RHS solve (includes the dense n x m RHS and
             solution blocks) [MB]

Solvers named ``*-schur`` instead build W from a partial factorization: the dense Schur
complement S of K onto the contact DOFs C, then W = B_C S^-1 B_C^T; their ``fact``
column is empty and ``W`` is the whole time from the raw matrix.  Solvers named
``*-sprhs`` factorize K (kept for later solves) and build W from the sparse B^T: a sparse
forward solve (CHOLMOD), sparse right-hand sides (MUMPS ICNTL(20)) or PARDISO's partial
solve (iparm[30]=1: sparse RHS on C, only x[C] computed).  Every W is saved and
compared with the first W ever computed for that matrix (``W_err``, max-norm relative
difference; the reference is kept in the cache).

Matrices are cached as .npz under --cache, so a worker only loads K and B.  A solver that
cannot be imported in the worker's interpreter is reported and skipped; --python lets
workers run in another environment (e.g. one with numpy<2 for python-mumps 0.0.2).

Examples::

    python convexcontact/studies/benchmarks/factorizations.py --dim 2 --sizes 1e4,1e5 --out 2d.csv
    python convexcontact/studies/benchmarks/factorizations.py --dim 3 --elem hex --sizes 5e4 --intorder 2
    python convexcontact/studies/benchmarks/factorizations.py --dim 2 --sizes 1e5 --solvers mumps,mumps-schur \\
        --python /tmp/benchvenv_np1/bin/python
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np
import scipy.sparse as sp

# ----------------------------------------------------------------------------- matrices


def build_problem(dim: int, elem: str, target_dofs: float, m: int, intorder: int | None, seed: int = 0):
    """Assemble K (free DOFs) and the contact operator B; return (K, B, info)."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    per_node = dim
    nel = max(2, round((target_dofs / per_node) ** (1.0 / dim)) - 1)
    x = np.linspace(0.0, 1.0, nel + 1)
    mesh, e = {
        "tri": (skfem.MeshTri, skfem.ElementTriP1),
        "tet": (skfem.MeshTet, skfem.ElementTetP1),
        "hex": (skfem.MeshHex, skfem.ElementHex1),
        "quad": (skfem.MeshQuad, skfem.ElementQuad1),
    }[elem]
    mesh = mesh.init_tensor(*([x] * dim))
    basis = skfem.Basis(mesh, skfem.ElementVector(e()), intorder=intorder)
    t0 = time.perf_counter()
    K = skfem.asm(linear_elasticity(*lame_parameters(1.0, 0.3)), basis)
    t_asm = time.perf_counter() - t0

    up = dim - 1  # vertical coordinate
    fixed = basis.get_dofs(lambda p: np.isclose(p[up], 0.0)).all()
    free = basis.complement_dofs(fixed)
    K = K[free][:, free].tocsr()
    K.sort_indices()
    new = -np.ones(basis.N, dtype=np.int64)
    new[free] = np.arange(free.size)

    # contact nodes: the k top-most nodes (top face first), a random orthonormal frame each
    k = -(-m // dim)
    order = np.lexsort((mesh.p[0], -mesh.p[up]))[:k]
    rng = np.random.default_rng(seed)
    rows, cols, vals = [], [], []
    for i, node in enumerate(order):
        q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
        dofs = new[basis.nodal_dofs[:, node]]
        for r in range(dim):
            rows += [dim * i + r] * dim
            cols += list(dofs)
            vals += list(q[r])
    B = sp.csr_matrix((vals, (rows, cols)), shape=(dim * k, K.shape[0]))[:m]
    info = {"elem": elem, "n": K.shape[0], "nnz": K.nnz, "m": B.shape[0], "asm_s": t_asm,
            "qpoints": basis.X.shape[-1]}
    return K, B, info


def cached_problem(cache: str, dim: int, elem: str, size: float, m: int, intorder: int | None):
    os.makedirs(cache, exist_ok=True)
    path = os.path.join(cache, f"{elem}_{size:.3g}_m{m}_io{intorder}.npz".replace("+", ""))
    if not os.path.exists(path):
        K, B, info = build_problem(dim, elem, size, m, intorder)
        np.savez(path, Kdata=K.data, Kind=K.indices, Kptr=K.indptr, Bdata=B.data, Bind=B.indices,
                 Bptr=B.indptr, shape=[K.shape[0], B.shape[0]], info=json.dumps(info))
    with np.load(path) as z:
        return path, json.loads(str(z["info"]))


def load_problem(path: str):
    z = np.load(path)
    n, m = (int(v) for v in z["shape"])
    K = sp.csr_matrix((z["Kdata"], z["Kind"], z["Kptr"]), shape=(n, n))
    B = sp.csr_matrix((z["Bdata"], z["Bind"], z["Bptr"]), shape=(m, n))
    return K, B


# ----------------------------------------------------------------------------- solvers
# Each factory takes the full symmetric CSR matrix K and returns (solve, rhs_order);
# solve(b) accepts a vector or an (n, m) block in memory order rhs_order.


def _loop(solve1):
    def solve(b):
        return solve1(b) if b.ndim == 1 else np.column_stack([solve1(c) for c in b.T])
    return solve


def f_superlu(permc, spd=False):
    def factory(K):
        from scipy.sparse.linalg import splu
        opts = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}} if spd else {}
        return splu(K.tocsc(), permc_spec=permc, **opts).solve, "F"
    return factory


def f_factorized(K):
    from scipy.sparse.linalg import factorized
    s = factorized(K.tocsc())
    return (s if not _has_umfpack() else _loop(s)), "F"


def _has_umfpack():
    try:
        import scikits.umfpack  # noqa: F401
        return True
    except ImportError:
        return False


def f_cholespy(K):
    from cholespy import CholeskySolverD, MatrixType
    K = K.tocsc()
    s = CholeskySolverD(K.shape[0], K.indptr.astype(np.int32), K.indices.astype(np.int32), K.data,
                        MatrixType.CSC)

    def solve(b):
        b = np.ascontiguousarray(b)
        x = np.empty_like(b)
        s.solve(b, x)
        return x
    return solve, "C"


def f_sksparse(K):
    from sksparse.cholmod import cholesky
    return cholesky(K.tocsc()), "F"


def f_pypardiso(mtype):
    def factory(K):
        from pypardiso import PyPardisoSolver
        s = PyPardisoSolver(mtype=mtype)
        A = sp.triu(K, format="csr") if mtype == 2 else K
        s.factorize(A)
        return (lambda b: s.solve(A, b)), "F"
    return factory


def f_mumps(K):
    import mumps
    ctx = mumps.Context()
    ctx.mumps_instance = mumps._mumps.dmumps(False, 1)  # sym=1: SPD (the wrapper only offers 0/2)
    ctx.dtype = "d"
    ctx.set_matrix(K, symmetric=True)
    ctx.factor()
    return ctx.solve, "F"


def f_qdldl(K):
    import qdldl
    s = qdldl.Solver(K.tocsc())
    return _loop(s.solve), "F"


def _delassus_from_schur(S, B, C):
    import scipy.linalg as la
    BC = B[:, C].toarray()
    return BC @ la.cho_solve(la.cho_factor(S), BC.T)


def _pardiso_spd(K, perm, iparm_set):
    """Raw MKL PARDISO (mtype 2, upper triangle, 0-based) through ctypes; return call(phase, b, x, nrhs)."""
    import ctypes

    from pypardiso import PyPardisoSolver
    pardiso = PyPardisoSolver()._mkl_pardiso
    U = sp.triu(K, format="csr")
    U.sort_indices()
    n = K.shape[0]
    iparm = np.zeros(64, np.int32)
    iparm[[0, 1, 9, 34]] = [1, 2, 8, 1]  # user iparm, METIS, pivot 1e-8, 0-based indexing
    for i, v in iparm_set.items():
        iparm[i] = v
    pt, err = np.zeros(64, np.int64), ctypes.c_int32(0)
    ia, ja = U.indptr.astype(np.int32), U.indices.astype(np.int32)
    P, i32, dbl = ctypes.POINTER, ctypes.c_int32, ctypes.c_double

    def call(phase, b, x, nrhs=1):
        keep = (U, ia, ja, perm, iparm, pt)  # noqa: F841 - keep the arrays PARDISO points to alive
        pardiso(pt.ctypes.data_as(P(ctypes.c_int64)), *(ctypes.byref(i32(v)) for v in (1, 1, 2, phase, n)),
                U.data.ctypes.data_as(P(dbl)), ia.ctypes.data_as(P(i32)), ja.ctypes.data_as(P(i32)),
                perm.ctypes.data_as(P(i32)), ctypes.byref(i32(nrhs)), iparm.ctypes.data_as(P(i32)),
                ctypes.byref(i32(0)), b.ctypes.data_as(P(dbl)), x.ctypes.data_as(P(dbl)), ctypes.byref(err))
        if err.value:
            raise RuntimeError(f"PARDISO phase {phase} error {err.value}")
    return call


def s_pardiso(K, B, C):
    """Dense Schur complement of K onto C with MKL PARDISO (iparm[35]=1) through ctypes."""
    perm = np.zeros(K.shape[0], np.int32)
    perm[C] = 1
    call = _pardiso_spd(K, perm, {35: 1})
    S, dummy = np.zeros(C.size * C.size), np.zeros(K.shape[0])
    call(12, dummy, S)
    call(-1, dummy, dummy)
    return _delassus_from_schur(S.reshape(C.size, C.size), B, C)


def s_mumps(K, B, C):
    """Dense Schur complement with MUMPS (ICNTL(19)=1, sym=1), factors discarded."""
    import mumps
    from mumps.mumps import _makemumps_index_array
    idx = _makemumps_index_array(C)
    S = np.zeros((C.size, C.size))
    with mumps.Context() as ctx:
        ctx.mumps_instance = mumps._mumps.dmumps(False, 1)
        ctx.dtype = "d"
        ctx.set_matrix(K, symmetric=True)
        ctx.mumps_instance.icntl[19] = 1
        ctx.mumps_instance.icntl[31] = 1
        ctx.mumps_instance.set_schur(S, idx)
        ctx.analyze()
        ctx.factor(reuse_analysis=True)
    S = np.tril(S) + np.tril(S, -1).T  # with sym=1 only the lower triangle (C order) is valid
    return _delassus_from_schur(S, B, C)


def p_sksparse(K, C):
    """CHOLMOD: W = Y^T Y with Y = L^-1 P B^T from a sparse forward solve only."""
    from sksparse.cholmod import cholesky
    f = cholesky(K.tocsc())

    def w(B):
        Y = f.solve_L(f.apply_P(B.T.tocsc()), use_LDLt_decomposition=False)
        return (Y.T @ Y).toarray()
    return w


def p_mumps(K, C):
    """MUMPS: solve with the sparse B^T (ICNTL(20)=1, sparse right-hand sides)."""
    solve, _ = f_mumps(K)
    return lambda B: B @ solve(B.T.tocsc())


def p_pardiso(K, C):
    """MKL PARDISO partial solve (iparm[30]=1): sparse RHS on C, only x[C] computed."""
    perm = np.zeros(K.shape[0], np.int32)
    perm[C] = 1
    call = _pardiso_spd(K, perm, {30: 1})
    dummy = np.zeros(K.shape[0])
    call(12, dummy, dummy)

    def w(B):
        rhs = np.asfortranarray(B.T.toarray())
        x = np.zeros_like(rhs)
        call(33, rhs, x, B.shape[0])
        return B[:, C] @ x[C]
    return w


SPARSE_RHS = {"sksparse-sprhs": p_sksparse, "mumps-sprhs": p_mumps, "pardiso-sprhs": p_pardiso}

SOLVERS = {
    "superlu-colamd": f_superlu("COLAMD"),
    "superlu-mmd": f_superlu("MMD_AT_PLUS_A"),
    "superlu-spd": f_superlu("MMD_AT_PLUS_A", spd=True),
    "factorized": f_factorized,
    "cholespy": f_cholespy,
    "sksparse": f_sksparse,
    "pardiso": f_pypardiso(11),
    "pardiso-spd": f_pypardiso(2),
    "mumps": f_mumps,
    "qdldl": f_qdldl,
    "pardiso-schur": s_pardiso,
    "mumps-schur": s_mumps,
    **SPARSE_RHS,
}
IMPORTS = {"cholespy": "cholespy", "qdldl": "qdldl"}
IMPORTS.update({k: "pypardiso" for k in SOLVERS if k.startswith("pardiso")})
IMPORTS.update({k: "mumps" for k in SOLVERS if k.startswith("mumps")})
IMPORTS.update({k: "sksparse.cholmod" for k in SOLVERS if k.startswith("sksparse")})


def _status_mb(key):
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith(key)) / 1024.0


def _reset_peak():
    """Reset the peak-RSS counter to the current RSS (Linux >= 4.0); return the baseline [MB]."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return _status_mb("VmRSS:")
    except OSError:  # no /proc: fall back to getrusage's high-water mark
        return _peak_mb()


def _peak_mb():
    try:
        return _status_mb("VmHWM:")
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(name: str, path: str, wout: str) -> dict:
    """Measure one solver on one matrix (run in a fresh process)."""
    K, B = load_problem(path)
    try:
        __import__(IMPORTS.get(name, "scipy.sparse.linalg"))
    except Exception as exc:  # noqa: BLE001 - any import failure means "skip"
        return {"status": f"skipped: {type(exc).__name__}: {exc}"}
    out = {"status": "ok"}
    if not name.endswith("-schur"):  # one-time library start-up (threads, dispatch) on a tiny matrix
        tiny = sp.identity(4, format="csr") * 2.0
        t0 = time.perf_counter()
        SOLVERS[name](*((tiny, np.arange(1)) if name in SPARSE_RHS else (tiny,)))
        out["init"] = time.perf_counter() - t0
    base = _reset_peak()
    C = np.unique(B.indices)
    if name in SPARSE_RHS:
        t0 = time.perf_counter()
        w = SOLVERS[name](K, C)
        out["fact"] = time.perf_counter() - t0
        out["mem_f"] = _peak_mb() - base
        t0 = time.perf_counter()
        W = w(B)
        out["W"] = time.perf_counter() - t0
        out["mem_W"] = _peak_mb() - base
    elif name.endswith("-schur"):
        t0 = time.perf_counter()
        W = SOLVERS[name](K, B, C)
        out["W"] = time.perf_counter() - t0
        out["mem_W"] = _peak_mb() - base
    else:
        t0 = time.perf_counter()
        solve, order = SOLVERS[name](K)
        out["fact"] = time.perf_counter() - t0
        out["mem_f"] = _peak_mb() - base
        f = np.random.default_rng(1).standard_normal(K.shape[0])
        t0 = time.perf_counter()
        x = solve(f)
        out["solve1"] = time.perf_counter() - t0
        out["res"] = float(np.linalg.norm(K @ x - f) / np.linalg.norm(f))
        print(json.dumps(dict(out, status="W not finished")), flush=True)  # kept if W times out
        chunk = int(os.environ.get("FZ_CHUNK", "0"))  # columns per solve (0: all at once)
        BT = B.T.tocsc()
        rhs = None if chunk else np.asarray(BT.toarray(), order=order)  # densified before timing
        t0 = time.perf_counter()
        if chunk:  # each block is densified inside the timing
            W = np.hstack([B @ solve(np.asarray(BT[:, j:j + chunk].toarray(), order=order))
                           for j in range(0, B.shape[0], chunk)])
        else:
            W = B @ solve(rhs)
        out["W"] = time.perf_counter() - t0
        out["mem_W"] = _peak_mb() - base
        if name == "factorized":
            out["status"] = "ok (umfpack)" if _has_umfpack() else "ok (superlu)"
    np.save(wout, W)
    return out


# ----------------------------------------------------------------------------- driver

COLS = ["elem", "n", "nnz", "m", "solver", "init", "fact", "solve1", "W", "mem_f", "mem_W", "res", "W_err", "status"]


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.3g}"
    return "" if v is None else str(v)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dim", type=int, choices=(2, 3), default=2)
    p.add_argument("--elem", choices=("tri", "quad", "tet", "hex"), help="default: tri in 2-D, tet in 3-D")
    p.add_argument("--sizes", default="1e4,1e5", help="comma-separated target DOF counts")
    p.add_argument("--solvers", default=",".join(SOLVERS), help=f"comma-separated, from: {', '.join(SOLVERS)}")
    p.add_argument("--m", type=int, default=300, help="rows of B (contact unknowns)")
    p.add_argument("--intorder", type=int, default=None, help="quadrature order (default: scikit-fem's)")
    p.add_argument("--chunk", type=int, default=0, help="solve the m RHS columns in blocks of this size (0: all)")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per worker")
    p.add_argument("--python", default=sys.executable, help="interpreter for the workers")
    p.add_argument("--cache", default=os.path.join("/tmp", "convexcontact_factorizations"))
    p.add_argument("--out", help="append rows to this CSV file")
    p.add_argument("--worker", nargs=3, metavar=("SOLVER", "NPZ", "WOUT"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(*a.worker)))
        return
    elem = a.elem or ("tri" if a.dim == 2 else "tet")
    solvers = [s for s in a.solvers.split(",") if s]
    unknown = set(solvers) - set(SOLVERS)
    if unknown:
        p.error(f"unknown solvers {sorted(unknown)}")
    rows = []
    print(" | ".join(COLS), flush=True)
    for size in (float(s) for s in a.sizes.split(",")):
        path, info = cached_problem(a.cache, a.dim, elem, size, a.m, a.intorder)
        print(f"# {elem} n={info['n']} nnz={info['nnz']} m={info['m']} assembly {info['asm_s']:.2f} s "
              f"(intorder {a.intorder or 'default'}, {info['qpoints']} quadrature points)", flush=True)
        for name in solvers:
            wout = f"{path[:-4]}_{name}_W.npy"
            row = dict(info, solver=name, chunk=a.chunk or info["m"])
            env = dict(os.environ, FZ_CHUNK=str(a.chunk))
            try:
                r = subprocess.run([a.python, os.path.abspath(__file__), "--worker", name, path, wout],
                                   check=False, capture_output=True, text=True, timeout=a.timeout, env=env)
                lines = r.stdout.strip().splitlines()
                row.update(json.loads(lines[-1]) if r.returncode == 0 and lines else
                           {"status": f"failed (exit {r.returncode}): {r.stderr.strip().splitlines()[-1:]}"})
            except subprocess.TimeoutExpired as exc:
                part = exc.stdout.decode() if isinstance(exc.stdout, bytes) else exc.stdout or ""
                row.update(json.loads(part.strip().splitlines()[-1]) if part.strip() else {})
                row["status"] = f"timeout > {a.timeout:.0f} s" + (" in W" if part.strip() else "")
            if row["status"].startswith("ok"):
                W, ref = np.load(wout), f"{path[:-4]}_Wref.npy"  # reference: first W ever made
                if not os.path.exists(ref):
                    np.save(ref, W)
                Wref = np.load(ref)
                row["W_err"] = float(np.abs(W - Wref).max() / np.abs(Wref).max())
            elif row["status"].startswith("skipped"):
                print(f"# {name}: {row['status']}", flush=True)
            rows.append(row)
            print(" | ".join(_fmt(row.get(c)) for c in COLS), flush=True)
    if a.out:
        new = not os.path.exists(a.out)
        with open(a.out, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=COLS + ["asm_s", "qpoints", "chunk"], extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
