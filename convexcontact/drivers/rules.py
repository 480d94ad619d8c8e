"""``auto``'s rules: which formulation a scene gets (:func:`choose_formulation`) and when newton-cg answers a
dense dual before Clarabel (:func:`dense_newton`). Each threshold carries the measurements that set it
(docs/performance.md); changing a rule touches this module only."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .. import solvers
from ..conic import ConicProgram
from ..fem.assembly import FEModel
from ..fem.factorization import saddle_applies
from ..scene.description import Coulomb, compliance_of, has_friction

INCOMPRESSIBLE = 1e5
"""λ/μ (ν ≈ 0.499995) from which "auto" keeps the primal: beyond what was measured. Below it the dual is certified
and faster (docs/performance.md, "Near-incompressible bodies"; dual / primal, certificate and time). Cattaneo–Mindlin
(Q2, 25,115 DOFs, Coulomb F = 0.6, tol 1e-7): ν = 0.499 (λ/μ = 499) 2e-8 in 4.2 s / 3e-8 in 25 s; 0.4999 1e-8 in
6.1 s / —; 0.49999 1e-7 in 13 s / no answer in 15 min (auto's primal map failed before). The stability study's Hertz
rows (Signorini, nx = 32): P2 ν = 0.49 9e-13 in 2.9 s / 8e-13 in 1.2 s; P2 0.499 7e-12 0.7 s / 5e-12 1.4 s; P2 0.4999
6e-11 0.6 s / 6e-11 1.5 s; Q2 0.4999 6e-11 0.7 s / 4e-11 2.6 s; Q2 0.49999 4e-10 0.9 s / inaccurate (6e-8) 2.2 s.
The dual's Tresca steps at 0.499–0.49999 (W's condition 1e9–1e11) needed the polish to judge signs on the KKT
solve's rounding (solvers/polish.py); before, its certificate was 3e-3 and 1e-5 and the rule stood at 1000."""

DENSE_LIMIT = 10000
"""Most contact unknowns (rows of B) a dense W takes at all: memory grows as m² (800 MB at the limit).
Measured at 6348 rows (3-D Tresca punch, 2.8·10⁵ DOFs, few of them in contact): contact 3.9× one
linear solve, peak memory 2.3×. Beyond it, the matrix-free dual (or the primal where that has no bound
form)."""

TOUCHING = 1e-9
"""A gap (scaled: of the displacement scale) this small counts as closed for :data:`CLOSED_LIMIT`: two
bodies' meshes that touch have gaps of ±1e-11 from their geometry, not 0."""

CLOSED_LIMIT = 2000
"""Most contact unknowns at nodes closed at the start (gap ≤ 0) for a dense W: the dense solvers' work
grows with the unknowns in contact, the matrix-free dual's hardly. Measured on whole faces (every node
closed; ratios to one linear solve, dense / matrix-free; docs/performance.md): 2-D 10⁵ DOFs, Signorini
1000 unknowns 3.3 / 3.3, 2000: 24 / 2.1; Tresca 1000: 4.7 / 5.7, 2000: 10.4 / 4.2, 4000: 169 / 3.7;
3-D 3·10⁴ DOFs, Signorini 625: 3.4 / 1.6–2.5, 1089: 12.1 / 2.7; Tresca 867: 2.8 / failed, 1875: 11.9 / 9.2,
3267: 51 / 7.3. On the punch (few nodes closed) the dense W stays ahead: 2-D Tresca 634 unknowns
1.9 / 4.0, 1098: 2.2 / 7.0. Measured again with newton-cg on the dense W (end to end, dense / matrix-free, Tresca and
Coulomb; docs/performance.md, "The rule for closed nodes measured again"): 2-D strips 20 : 1 at 10⁵ DOFs (2,002
unknowns) 2.89 / 2.16 and 6.16 / 2.67 free, 4.57 / 1.68 and 6.98 / 1.76 clamped; at 3·10⁵ (3,482) 4.55 / 2.18 and
12.1 / 2.23; 400 : 1 at 10⁴ (3,202) 42 / 2.6 and 247 / 2.7, the dense memory 2.5–43× the linear solve's. Only the 3-D
tall block at 3·10⁵ DOFs (2,700) is the other way, 1.48 / 1.60 and 1.82 / 2.71, both under their targets."""

DENSE_DOFS_3D = 50_000
"""Most free DOFs of a 3-D body for a dense W: there its condensation (PARDISO's Schur complement onto the contact
DOFs) costs 1.6–1.8× a factorization and forming W |C|³ more, while the matrix-free dual costs one factorization and
its products. Measured on the 3-D punch (ratios to one linear solve, dense / matrix-free; Signorini, Tresca,
Coulomb): 9.0·10³ DOFs 1.64 / 2.25, 2.47 / 4.51, 2.30 / 4.17; 3.0·10⁴ DOFs 1.53 / 2.22, 2.80 / 3.17, 2.59 / 3.48;
8.5·10⁴ DOFs 1.86 / 1.59, 2.83 / 2.27, 2.63 / 2.70; 2.8·10⁵ DOFs 1.71 / 1.27, 2.47 / 1.48, 2.51 / 1.52 (peak memory 1.1–1.4×
the linear solve's against 1.5–1.9×).
Not on a pair whose W comes from K's factors with B's rows appended (``factorization.saddle_applies``; a pair: the
rows touch more DOFs than the contact nodes carry, the other body's): there is no Schur complement onto the columns,
that factorization forms W itself at ~1.6× K's flops, and the pair's matrix-free dual is the family's costliest (with
friction a K-sized slab refactorized at nearly every Newton system, ~250 products with W). The 3-D pair of spheres
(contact ratio / end to end, loaded, matrix-free → the saddle): 1.0·10⁵ DOFs, Signorini 2.53 / 2.12 → 1.59 / 1.41,
Tresca 14.2 → 1.69 / 1.50 (201 products, 18 factorizations → 6 dense Newton steps); 3·10⁵ DOFs (end to end, loaded,
one run each): Tresca 6.02 → 1.81, Coulomb 5.72 → 1.24, Signorini 1.53 / 1.58 → 1.90 / 1.42 (two pairs of runs:
a wash, its matrix-free dual factorizes one slab per session; memory 1.26 → 1.10×); docs/performance.md, "The 3-D
pair of spheres through the saddle's W". One body keeps the rule: the tall block's Signorini at 3.2·10⁵ DOFs (900
rows on 2700 DOFs) is 1.25 end to end matrix-free (2 Newton steps, 16 products), below the saddle's ~1.6×.
Only where the contact DOFs are over MATRIX_FREE_COLUMNS too: a body whose contact zone is small beside its DOFs keeps
its dense W, whose condensation is then a fraction of the matrix-free dual's products and factorizations (quiet, end
to end, matrix-free → dense; Coulomb / Tresca / Signorini; docs/performance.md, "The free plate's Tresca at 3·10⁵
DOFs under its target; the tall block's Coulomb row at 10⁵ over its own, and `auto`'s 3-D rule"): the tall block
1 : 1 : 4 at 10⁵ DOFs (1,323 contact DOFs) 5.16 → 1.42, 1.68 → 1.49, 1.23 → 1.17; at 3·10⁵ (2,700) 2.71 → 1.82,
1.60 → 1.48, 1.17 → 1.09 (friction there stays matrix-free: its 2,700 unknowns are closed, CLOSED_LIMIT); the punch at
10⁵ (3,072) 2.64 → 1.95, 2.92 → 2.12, 1.88 → 1.38. Beyond: the punch at 3·10⁵ (6,348) Coulomb 1.87 against 2.11
dense, the flat block 4 : 4 : 1 at 10⁵ (8,427) 2.04 against 19.9."""

COLUMN_LIMIT = 15000
"""Most columns K is condensed onto for a dense W (the contact DOFs; a pair's slave and master DOFs): the
Schur complement is dense, 8·c² bytes (1.8 GB at the limit) before PARDISO's own copies. The two-body
bench at 1.4·10⁶ DOFs has 9816 unknowns, under DENSE_LIMIT, but 34,762 columns: its condensation passed
18 GB and was stopped. Beyond it, the matrix-free dual (or the primal where that has no bound form)."""

MATRIX_FREE_COLUMNS = 4000
"""Most columns for a dense W where the matrix-free dual applies (newton-cg's bound form): forming W takes a solve
per column and its Newton steps dense factorizations of the unknowns in contact, the matrix-free dual one
factorization of K and its products. Measured on the 2-D pair (`bench --scenario two-body`, quiet; contact ratio and
peak memory, dense / matrix-free; Signorini, Tresca, Coulomb): 1.0·10⁵ DOFs, 2,566 columns: 4.21 / 4.87, 9.12 / 11.4,
6.33 / 15.1 (memory 2.6–3.1× / 1.7–1.8×); 2.8·10⁵ DOFs, 7,084 columns: 9.49 / 7.53, 27.5 / 14.6, 18.5 / 14.5 (memory
5.0–6.3× / 1.8–1.9×); 6.0·10⁵ DOFs, 14,916 columns, Tresca: 83.6 (memory 12×) / 24.2 (1.9×). The 2-D punch at 10⁶
DOFs condenses onto 2,002 columns and keeps its dense W. Where W comes from K's factors with B's rows appended
(factorization.saddle_applies) its cost grows with the rows m, not the columns: there the limit is on m. The pair
at 2.8·10⁵ DOFs (7,084 columns), quiet, dense / matrix-free (contact ratio, end to end, memory): Signorini, 2,269
rows, 2.01, 1.37, 1.57× / 9.7, 4.77, 1.83× (dense since); Tresca, 4,538 rows, 4.08, 2.32, 2.54× / 16.7, 7.9, 1.69×
(matrix-free: the dense memory over 2×); at 6·10⁵ Tresca, 10,880 rows, dense memory 4.3× (docs/performance.md, "W
from K's factors with B's rows appended")."""

MATRIX_FREE = "dual-matrix-free"
"""The dual with W as an operator (one solve with K's factors per product) and newton-cg."""


def choose_formulation(fem: FEModel, law, unknowns: int) -> tuple[str, str]:
    """The formulation "auto" runs, and why (before knowing whether K is singular)."""
    if compliance_of(law) is not None:
        return "primal", "normal compliance is posed in the primal only"
    if getattr(law, "non_penetration", None) == "gauss":
        return "primal", ("Gauss-point non-penetration: more multipliers than contact nodes leave the condensed W "
                          "singular, the primal is not")
    lam, mu = fem.lame
    if np.max(lam / mu) >= INCOMPRESSIBLE:
        return "primal", (f"near-incompressible (λ/μ up to {np.max(lam / mu):.0f}): the condensed program loses "
                          "accuracy with the conditioning of W, the primal does not")
    columns = contact_columns(fem).size
    if columns == 0:
        return "primal", "no contact node has a free DOF: nothing to condense onto"
    reuse = " and is reused by every Picard step" if isinstance(law, Coulomb) else ""
    closed = round(unknowns * np.count_nonzero(fem.contact.gap <= TOUCHING) / fem.contact.m)
    saddle = saddle_applies(columns, unknowns)  # W from K's factors with its rows: no dense S onto the columns
    pair = columns > fem.dim * fem.contact.m  # the rows touch DOFs beyond their nodes': a pair's other body
    # what a dense W's cost grows with (MATRIX_FREE_COLUMNS): its rows by the saddle, else the columns condensed onto
    size, what = (unknowns, f"{unknowns} contact unknowns") if saddle else (columns, f"the {columns} DOFs to condense onto")
    too_large = (f"{unknowns} contact unknowns exceed {DENSE_LIMIT}" if unknowns > DENSE_LIMIT else
                 f"{closed} contact unknowns at closed nodes exceed {CLOSED_LIMIT}" if closed > CLOSED_LIMIT else
                 f"the {columns} DOFs to condense onto exceed {COLUMN_LIMIT}" if columns > COLUMN_LIMIT and not saddle
                 else f"{what} exceed {MATRIX_FREE_COLUMNS}" if size > MATRIX_FREE_COLUMNS and matrix_free_applies(fem, law)
                 else
                 f"a 3-D body of {fem.n_free} DOFs (over {DENSE_DOFS_3D}) costs more to condense onto its {columns} "
                 f"contact DOFs (over {MATRIX_FREE_COLUMNS}) than to factorize"
                 if fem.dim == 3 and fem.n_free > DENSE_DOFS_3D and columns > MATRIX_FREE_COLUMNS
                 and not (saddle and pair) else None)
    if too_large and matrix_free_applies(fem, law):
        return MATRIX_FREE, (f"{too_large}: W = B K⁻¹ Bᵀ is applied through one factorization of K{reuse}, never "
                             "formed (a dense W would cost more), and newton-cg solves the dual")
    if too_large and (unknowns > DENSE_LIMIT or (columns > COLUMN_LIMIT and not saddle)):
        return "primal", (f"{too_large}: the dense condensed program would cost more than the sparse one (a "
                          "force-controlled obstacle or a regularized friction has no matrix-free dual)")
    # Not for 3-D friction with a bound form: the primal's second-order cones are not in the polish's bound form and
    # Clarabel leaves their law at 1e-8–3e-7, where newton-cg's dense dual certifies it to round-off, in less time on
    # the sizes this rule reaches (docs/performance.md, "The family in 3-D and with Coulomb"; 2-D intervals are polished)
    unpolished = fem.dim == 3 and has_friction(law) and matrix_free_applies(fem, law)
    if 4 * columns > fem.n_free and not unpolished:
        return "primal", f"the contact nodes carry {columns} of the {fem.n_free} DOFs: too many to gain by condensing"
    return "dual", (f"{unknowns} contact unknowns beside {fem.n_free} DOFs: K is condensed onto Γ_C once "
                    f"(Delassus operator W){reuse}, then the program is small and dense")


DENSE_NEWTON = "auto: newton-cg on the dense dual (Clarabel where it fails)"
"""Why newton-cg answered a dense dual that ``auto`` was left (docs/performance.md, "newton-cg on a dense W"): its
Newton steps are dense Cholesky solves of the reduced W, 2–10× faster than Clarabel with the polish (3-D punch,
2.8·10⁵ DOFs, Tresca: 8.1 s against 38.6 s); it converges (a bounded number of steps), but the bound may exceed its
step limit (a two-body Tresca dual at 10⁵ DOFs stopped after 100 Newton steps, 1.4 s, before the globalization; Clarabel
answered in 2.4 s)."""


DENSE_NEWTON_STEPS = 50
"""Newton steps newton-cg gets on a dense dual before Clarabel answers: those it solved took up to 42 (two-body
Tresca, 5·10⁴ DOFs), one it failed wandered at residuals 1e-2 to 1e-4 for 100 (the same at 10⁵ DOFs)."""


def dense_newton(formulation: str, program: ConicProgram, law):
    """A newton-cg session on a model's dense dual (its ``formulation``, ``program`` and contact ``law``), or None
    where ``auto`` keeps Clarabel: programs not in newton-cg's bound form (a force-controlled obstacle's equality)
    and contact at Gauss points (more touching points than nodes: W singular on their multipliers)."""
    if formulation != "dual" or solvers.matrix_free(program) or "gauss" in (
            getattr(law, "non_penetration", None), getattr(law, "quadrature", None)):
        return None
    try:
        return solvers.session(program, "newton-cg", max_iter=DENSE_NEWTON_STEPS)
    except ValueError:
        return None


def matrix_free_applies(fem: FEModel, law) -> bool:
    """Whether the matrix-free dual is in bound form (newton-cg's programs): no equality (force control) and
    exact friction."""
    return matrix_free_obstruction(fem.scene.contact.obstacle, law) is None


def matrix_free_obstruction(obstacle, law) -> str | None:
    """What keeps the dual of a scene out of newton-cg's bound form (None: nothing)."""
    if compliance_of(law) is not None:
        return "normal compliance is posed in the primal only"
    if obstacle.force_controlled:
        return "a force-controlled obstacle (obstacle.force) adds an equality row"
    if obstacle.tangential_force is not None:
        return "a tangential obstacle force (obstacle.tangential_force) adds an equality row"
    if getattr(law, "regularization", None) is not None:
        return "the ε-regularized friction (contact.regularization) has no bound form"
    return None


def contact_columns(fem: FEModel) -> np.ndarray:
    """Free DOFs the contact rows touch (the contact nodes; a pair's master nodes too): the columns of
    N, T and R, where K is condensed to. Their stored entries, zeros included, cover every free DOF of a node."""
    return np.unique(sp.vstack([fem.contact.N, fem.contact.T]).tocsr().indices)
