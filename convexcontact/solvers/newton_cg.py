"""Semismooth Newton with conjugate gradients for bound-form programs; P may be an operator.

In bound form (:func:`.cone_polish.bound_form`) without equality rows each constrained variable
x_j has one row r, and v_j = b_r − a_r x_j turns the cones into v_j ≥ 0 (nonnegative rows) and
‖v_k‖ ≤ ρ_k (the rows of a second-order cone after its radius row; in one dimension an interval).
The answer is the zero of the natural map F(v) = v − Π(v − c ∇f(v)). Newton's method on it
(semismooth: Π is piecewise smooth) holds at each step the bounds whose v − c∇f is negative at 0,
puts the balls whose v − c∇f lies outside on their sphere, moving in its tangent plane with the
projection's curvature (‖y‖ − ρ)/(cρ), and solves for the rest by CG (scipy), which needs only
products with P: the Delassus operator of a large contact zone is applied through K's
factorization and never formed. With bounds alone this is the primal-dual active set method
(Hintermüller, Ito, Kunisch 2002). CG stops at a tolerance that follows ‖F‖ (inexact Newton):
the first steps, which find the active set, are cheap.

Convergence (a fixed f, radii that do not move; P symmetric positive semidefinite, f bounded below on the sets;
the start v₀ projected onto the sets).
Let C = diag(c) (c is one number on each ball, so Π is also the projection in the metric C⁻¹), p(v) = Π(v − C∇f(v))
the natural map's point and κ(v) = ∇f(v)ᵀ(p(v) − v), the projected gradient's first-order change of f; the
projection's variational inequality gives κ(v) ≤ −‖p(v) − v‖²_{C⁻¹}. Each step either

(a) takes Newton's point where its natural residual is below ACCEPT × the least so far and f there is at most f(v₀):
    at most log(r₀/tol) / log(1/ACCEPT) such steps before the residual is below tol; or
(b) lowers f by at least σ|κ(v)|: Newton's point, a point towards it or towards Newton's point on the face of the
    sets near their boundary at v (FACE) where one does with σ = ARMIJO, else the least f on the segment [v, p(v)],
    which does with σ = min(½, 1/(2λ)), λ the largest eigenvalue of C^½ P̃ C^½ (the exact line search of a quadratic
    on a feasible segment; no bound of P is needed to take it).

Newton's point is only the trial point of (a) and (b): the argument asks nothing of it, so it may be computed in any
way; a solve from no start with P an operator takes the empty face's first (FIRST_FORCING), which (a) or (b) judges
as any other. Nor does it ask anything of v₀ beyond the sets: where P carries an approximation with coarse functions,
a solve from no start begins at the answer of the program on aggregated sets (COARSE_SETS), feasible by construction.
With fixed radii it is Newton's point on the face the natural map holds at v, then on the face it holds at that point
(the primal-dual active set update: the sets the point leaves held, those whose multipliers point inward released,
an interval moved to the end its multiplier pushes it to), solved for again until the face stays, at most GROW times
(GROW): a step solves at most GROW + 1 Newton systems.

All points lie in {f ≤ f(v₀)}, so between two steps (a) the steps (b) with ‖p(v) − v‖_{C⁻¹} > ε number at most
(f(v₀) − f*) / (σ ε²): the method stops for any tol > 0 after a bounded number of steps, and without a tol the
least natural residual tends to 0 (p(v) = v is the convex program's optimality condition). This is the projected
gradient's argument with Armijo's rule (Bertsekas, Nonlinear Programming, 2nd ed. 1999, §2.3; Calamai & Moré,
Math. Program. 39, 1987, for steps that reach a fraction of the projected gradient's decrease, as Moré & Toraldo's
GPCG, SIAM J. Optim. 1, 1991, takes its Newton-like steps); Newton's steps are its acceleration, and near the answer
(a) takes them where f's changes are round-off. Plain Newton on the natural map has no such property: it cycles on
3-variable SPD box programs (tests/test_global_convergence.py; Ben Gharbia & Gilbert, Math. Program. 134, 2012, for
P-matrices), and did on a tall 3-D Tresca block and the two-body duals applied matrix-free (docs/performance.md).
``info["steps"]`` counts the steps of each kind, ``info["descent"]`` holds (kind, f's change, κ) of each,
``info["grown"]`` the faces grown, ``info["factorizations"]`` those of the preconditioner's H + Gᵀ D⁻¹ G (REUSE).

An operator P may carry ``approximation`` with sparse ``G``, ``H`` (SPD) and ``factorize`` such that
P ≈ G H⁻¹ Gᵀ (a Delassus operator of a thin slab of the body and coarse functions beyond it): each Newton
system of a program with balls is then preconditioned by the exact inverse of the same system with P's
approximation (Woodbury: one numeric sparse factorization per Newton step), of a program with bounds alone by
the restriction of the approximation's inverse (one per session; see :class:`_Preconditioner`).
"""

from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee, shortest_path

from .. import blas
from ..arrays import group_ranks
from ..conic import ConicProgram, ConicSolution, dense_values, nonnegative, soc
from .cone_polish import BoundForm, bound_form, tangent_bases, unit_rows

TOL = 1e-12
"""Largest natural residual ‖F‖∞ relative to the answer's scale: Signorini and Tresca certificates
of the whole-face scenes then reached ≤ 1e-12."""
FORCING = 0.1
"""CG stops at FORCING · min(1, ‖F‖/‖F₀‖) · ‖F‖ (as a gradient): loose while the active set moves."""
SHIFT = 1e-3
"""δ of the preconditioner relative to each row's scale (:func:`_shifts`; P's mean eigenvalue without an estimate):
relative to the mean, 1e-1 left 49 CG iterations on a 2-D Tresca dual, 1e-2 34, 1e-3 and below 31, as the exact
(δ = 0) slab operator."""
ACCEPT = 0.5
"""Newton's point is taken outright where its natural residual is below ACCEPT × the least so far (and f there is at
most its value at the start: see "Convergence")."""
ARC = 6
"""Points Π(v + α(Newton's point − v)), α = ½, ¼, …, tried where the least f on the segment to Π(Newton's point)
gains too little: a point of the arc holds its bounds exactly, one inside the segment does not (two-body Tresca dual
applied matrix-free, 1.4·10⁴ DOFs: 68 Newton steps and 740 products so, 326 and 4016 without the arc; the arc
before the segment: 36 and 410, but the 2-D whole face of 1001 nodes then 16 steps and 70 products against 8 and 39).
One order whether P is a matrix or an operator. A dense W took Π(Newton's point) first, then the arc (before its
Newton points on grown faces, GROW: the segment alone left the two-body Tresca dual at 1434 unknowns wandering at
1e-2–1e-4 for 100 steps); with the grown faces the segment first is as sure and shorter: that dual 17 Newton steps /
91 Newton systems → 8 / 33, Signorini 12 → 5; the 2-D block at 2·10⁴ DOFs, Tresca, 8 → 4, the 3-D tall block 10 → 7,
the clamped strip 20 : 1 at 10⁵ 9 → 8; the 2-D punch at 10⁵ Signorini 4 → 5 and the pair at 2·10⁴ Tresca 6 → 7
(docs/performance.md, "The dense dual's cost on the pair and whole faces")."""
ARMIJO = 1e-4
"""Fraction of the projected gradient's first-order decrease of f (κ in "Convergence") a point towards Newton's must
reach. Measured against the first-order decrease of its own direction instead (before), the point of the segment was
taken however little it gained, and newton-cg failed after 100 steps on the tall 3-D block (289 bottom nodes, Tresca,
matrix-free: certificate 0.4) where it now takes 10, and on the two-body Tresca dual applied matrix-free (1.4·10⁴
DOFs) where it now takes 68."""
STALL = 0.9
"""A step to the segment's or the projected gradient's point that leaves the natural residual above STALL × its value
is followed by a projected-gradient one (f only falls further)."""
CG_LIMIT = 5000
"""CG iterations per Newton step before it gives up (the step then still uses its last iterate)."""
DIRECT_LIMIT = 10_000
"""Unknowns of a Newton system solved by a dense Cholesky (LU where radii move) where P is a matrix: a dense W's
systems took hundreds of unpreconditioned Krylov iterations per step (a mortar pair on graded meshes; the 3-D punch at
2.8·10⁵ DOFs, ~5000 unknowns: 180–400 a step, 52 s against 8 s by Cholesky), and an inexact direction stalled the
Coulomb Newton. 10,000 is ``auto``'s largest dense W; a Cholesky there is ~3·10¹¹ flops."""
FIRST_FORCING = 1e-6
"""A solve from no start with P an operator takes as its first Newton point that of the empty face (every set free:
P̃'s unconstrained minimizer, the face then grown by the sets it leaves, GROW), CG stopping at FIRST_FORCING (not
FORCING) × ‖F‖. The natural map's face at a point with an error in W's long waves (a thin body's bending) follows
that error: c is the short waves' step length and cW's largest eigenvalues are ~10³ on the clamped strip 400 : 1,
whose Tresca answer is all in contact and sticking (the empty face's point) while its path held 300–2,500 nodes open
and 1,000–2,000 slipping, a different count each step (Newton steps / products, 5·10⁴ DOFs: 16–26 / 300–572 with
d_j's round-off → 3 / 30; 10⁵ 12–14 → 2 / 20). Solved to FORCING (0.1 × ‖F‖, and ‖F‖ there is relative to
‖c q‖ = 10³ ‖v‖) the empty face's point carried the same long-wave error and the path was as long (17 steps at
5·10⁴), and FIRST_FORCING on every step 21 (docs/performance.md, "The clamped strip's Newton path"). The point is a
trial that the step rules judge ("Convergence"): where the answer's face is not empty it costs one step's systems
(the pairs of the bench's family at 2·10⁴ DOFs, 2-D and 3-D: 6 → 7 steps). Not where P is a matrix: its systems are
solved directly, and the pair's dense Tresca dual at 3·10⁴ DOFs grew 23 faces against 12 so; its dense Signorini dual
at 10⁵ DOFs 11 against 2 (CPU 0.15 → 0.26 s), though the clamped strip 100 : 1's at 2·10⁴ then took 2 Newton steps
against 9. The empty face's grown faces stop at GROWN_FORCING alone, not at the step's target: that target is
relative to ‖c q‖, 10³ ‖v‖ on the clamped strip 400 : 1, where it stopped them after 0–1 CG iterations and the grown
point missed the opening zone's last node (5·10⁵ DOFs, Signorini: 3 Newton steps / 54 products → 2 / 42;
docs/performance.md, "Signorini on the clamped strip: the opening zone in one step")."""
GROW = 10
"""Times Newton's face may change per step where radii are fixed: to the face the natural map holds at its point
(:func:`_released`), the point solved for again, until the face stays. Before, the face only grew: the sets the point
leaves were held too, until it left none (a feasible point; :func:`_grown`, as where radii move). Without either,
Tresca's slip zone was found a few nodes a step: Newton's point on too small a face overshoots the intervals of the
nodes about to slip, its projection raises f, and the least f on the segment to it stops short of their bounds, where
the next step's face is decided. Matrix-free (Newton steps / products with P, before → now): tall 2-D block 1 : 4 at
2·10⁴ DOFs 75 / 720 → 5 / 118 (23 faces grown), at 10⁵ failed after 100 → 5 / 97; the two-body pair at 3·10⁴ DOFs
30 / 412 → 4 / 150, at 10⁵ 47 / 1147 → 7 / 444; the dense W of the tall block 95 → 4 (docs/performance.md). Bounds
alone (Signorini) too: an opening zone grows as a front, a few nodes a Newton point (the clamped strip 400 : 1,
matrix-free, from the empty face: 5 / 6 / 6 Newton steps at 10⁵ / 2·10⁵ / 5·10⁵ DOFs, 7 at 10⁶, each a step with its
residual and segment), and a grown face is one CG solve of 1–2 iterations (the bounds' preconditioner is one
factorization per session): 2 / 2 / 2 steps, 56 / 81 / 76 → 37 / 40 / 42 products. Dense W (the 2-D family at 2·10⁴
DOFs, Newton steps): the pair 10 → 2, the punch 4 → 1, clamped strips 20 / 100 : 1 5 / 24 → 3 / 9, at 10⁵ the pair 5 →
3, no more CPU. Before the empty face first, grown faces on that strip's swinging path cost more than they saved (385
products against 54).

Grown faces never released a set: on the 2-D pair, whose answer has nearly every node slipping, an interval held at
the wrong end stayed there for the step, its natural residual exactly 2s (the ∞-norm's floor while any node flips),
so ACCEPT refused Newton's point for 3–5 steps (a plateau) and the segment and projected-gradient steps moved
thousands of intervals off their ends (docs/performance.md, "The pair at 1.4·10⁶ DOFs"). The face at Newton's point
releases and flips them; ∇f there comes from CG's own products (:func:`_step`), so a face costs no more products than
a grown one, and where Newton's point is feasible that ∇f serves the step's test too. A set released once in a step
is not released again in it: CG's loose multipliers (GROWN_FORCING) released and held the same few nodes near the
stick–slip ends in turn until GROW. Tresca on the pair, `auto` (matrix-free beyond 10⁵ DOFs), Newton steps / products
before → the update without that rule → now: 2·10⁴ DOFs forced matrix-free 7 / 99 → 3 / 73 → 5 / 97; 10⁵ forced
matrix-free 8 / 148 → 6 / 141 → 5 / 109; 10⁵ dense 8 / 49 → 3 / 60 → 3 / 58 (one n² product a face: ∇f); 2.8·10⁵
9 / 193 → 7 / 180 → 5 / 152; 6·10⁵ 11 / 284 → 4 / 146 → 4 / 145 (docs/performance.md, "Tresca's plateau on the
pair"). The convergence argument does not change: Newton's point is a trial."""
GROW_MOVING = 3
"""Times the face may grow where radii move on balls of more variables (discs; intervals take the natural map's faces,
RELEASE_MOVING), and only after Newton's point was refused (its natural residual not below the step's): a node that
leaves its interval at Newton's point made its projection raise the residual, and each step went half way to that same
point (clamped strip 400 : 1, 4·10⁴ DOFs: 7 Newton steps, the residual halved 5 times, an answer the certificate
refused, 7.6e-6). Grown at every step, as with fixed radii, the faces cost more than the steps they saved where P is a
matrix (each is an LU of its own: strip 20 : 1 free, 2·10⁴ DOFs, 5 → 13 systems) and on the clamped plate (3-D, 2·10⁴
DOFs: 33 → 75 products, 5 steps both). Refused points only (steps / products / faces grown, 2·10⁴ DOFs unless said;
docs/performance.md, "The clamped strip 400 : 1's Coulomb row"): GROW_MOVING = 1: tall block stalled after 16 steps,
strip 400 : 1 at 5·10⁴ 6 / 208 / 5; 2: tall 12 / 134 / 22; 3: block 13 → 9 / 38 / 12, tall (stalled after 18 before) 2 /
13 / 4, clamped plate 5 / 51 / 3, strip 400 : 1 at 5·10⁴ 3 / 67 / 2; 10 (GROW): block 6 / 23 / 7, tall 1 / 10 / 4,
clamped plate 5 / 75 / 10."""
RELEASE_MOVING = True
"""Where radii move and the balls are intervals (2-D), Newton's point is on the face the natural map holds at it, as
with fixed radii (GROW, :func:`_released`: sets whose multiplier points inward released, an interval moved to the end
its multiplier pushes it to), at every step, not only grown by the sets it leaves (:func:`_grown`) once refused.
Those faces at refused points only (GROW_MOVING = 3 of them, before) left the pair on a plateau, the residual 1.5–4×
lower a step for 4–5 steps: the third face still moved 1–4 intervals, and its point gained little; at every Newton
point, up to GROW, the faces stay after 3–9 and the point is the answer's but for GMRES's tolerance. Newton's Coulomb
solve, steps / products, before → faces at refused points up to GROW → at every point (docs/performance.md, "Newton's
Coulomb plateau on the pair"): the pair `auto` at 3.5·10⁵ DOFs 7 / 176 → 3 / 90 → 2 / 33, at 1.4·10⁶ 6 / 73 → 2 / 56
(at every point); forced matrix-free at 2·10⁴ 6 / 118 → 4 / 58 → 3 / 69, 1.6·10⁵ 5 / 51 → 5 / 51 → 2 / 37, but 10⁵
3 / 25 → 3 / 25 → 2 / 36 (its first Newton point was 13× lower already, then taken as it was); the clamped strip
400 : 1 at 10⁵ forced matrix-free 3 / 29 → 2 / 25; W a matrix, dense LUs (steps + faces): the pair at 10⁵ 6 + 9 →
1 + 5, the block 6 + 9 → 2 + 9, the tall block at 2·10⁴ 2 + 6 → 1 + 4. Discs unchanged.

Before that, the refused Newton point's faces were only grown by the sets it leaves (:func:`_grown`): a grown face held
a node at the wrong end of its interval, Newton's point was refused again, and the steps crawled on a plateau (2-D pair
at 3.2·10⁵ DOFs: a refused step cost 25–37 products against 9–14 for a taken one). Newton's Coulomb solve, steps /
products, grown → released (docs/performance.md, "Coulomb's starts on the pair from the coarse answer"): the 2-D
block at 10⁵ DOFs (W a matrix) 11 / 65 → 6 / 36, the tall block 9 / 96 → 3 / 33, the pair 7 / 34 → 6 / 37; the pair
forced matrix-free at 2·10⁴ 7 / 156 → 6 / 136, 5·10⁴ 7 / 109 → 5 / 63, 10⁵ 3 / 30 both, `auto` at 3.2·10⁵ 4 / 59 →
3 / 49, but at 1.4·10⁶ 6 / 66 → 6 / 81 (the same plateau, each face a gradient more); the strips unchanged (no face
grown). Not on discs (3-D): the tall block at 3·10⁴ DOFs 12 / 63 → 12 / 97, and a
disc program that stalls without the fixed-point step (tests/test_coulomb_newton.py) no longer stalled."""
FACE = True
"""After a step that took no Newton point (a segment, arc, face or gradient step), the face step first: Newton's point
on the face that holds every set within ε (the natural residual) of its boundary, the least f on the segment towards
it as far as the free sets allow (the working set of a primal active-set method: f falls monotonically, and the set
that stops the segment joins the face of the next such step; sets leave it through Newton's points on the natural
map's faces, the segment and the gradient steps). Where W is ill-conditioned the natural map's faces cycle and the
projected gradient crawls: the fuzz long profile's stiff slave cylinder on a 1000 × softer master (Tresca, 150
unknowns, W's eigenvalues 1.8e-7 … 29) had Newton's point leave the intervals of 15 nodes by up to 7.9 × their bound
and refused on 99 of 100 steps, the projected gradient gaining ~0.6 % a step: max_iter on the dense and the
matrix-free dual. Measured (docs/performance.md, "The crawl on a stiff slave over a soft master"): Bertsekas'
ε-binding face (the sets whose gradient points out) with a projected search left free sets a few 1e-8 inside their
bounds that its Newton point pushed far out, and stalled or took 33–44 steps; the working set with the segment cut
where a free set's boundary is met solves every such pair found."""
GRADIENT_LENGTHS = 0.5 ** np.arange(8)
"""Where radii move and Newton's points were refused, the fractions of the projected gradient's step tried (the first
whose natural residual is below the step's is taken). The step lengths c (0.1 / P̃_jj) are those of a segment on which
f is least, but where radii move there is no f, and along that step the natural residual rises as ~α c‖P̃‖ where
W is far from diagonal: on the 2-D block at 10⁶ DOFs (dense W, 1416 unknowns) from the frictionless start (natural
residual 2.2e-2, every node slipping) it was 0.66, 0.33, …, 4.2e-2 at 1, ½, …, 1/16, below 2.2e-2 only from ~1/32, so
Newton stalled after 0 steps (the Picard map answered, Clarabel on 10 Tresca programs). To 1/128: 6 short gradient
steps, then Newton's: solved after 16 steps (docs/performance.md, "The pair's dense Newton systems on the
Coulomb problem, and the block at 10⁶ DOFs's stall")."""
GROWN_FORCING = 0.1
"""CG on a grown face stops at GROWN_FORCING × its first residual (or the step's own target, if larger): the point
is a trial, and the face it finds is what counts. Solved to the step's target as the first face is, the grown faces
took most of the products of a clamped strip (Tresca, matrix-free, products before → after: 100 : 1 at 2·10⁴ DOFs
310 → 148, 400 : 1 268 → 207, 20 : 1 at 5·10⁴ 373 → 217; docs/performance.md, "Thin bodies")."""
EPS = np.finfo(float).eps
"""A ball's radius at most EPS × ‖y‖ is a point to the Newton step (see :func:`_step`)."""
LOAD_SCALE = np.sqrt(EPS)
"""The natural residual is relative to the answer's scale, max ‖v‖∞ and ‖c q‖∞ (the scale of the first gradient step,
for answers that are 0); ‖c q‖ is also the rounding floor of ∇f = P x + q formed as a sum. Where P x + q has its own
formula (:func:`_affine`) there is no such floor, and the method stops only where the residual is below tol relative
to ‖v‖∞ too (‖c q‖∞ counting only LOAD_SCALE): on a strip 400 : 1 clamped at its ends ‖c q‖ is 10³ ‖v‖ (the load
bends the beam its contact holds up), and a natural residual of 3e-16 relative to it left gaps and slips of 2e-10
(certificate, 2·10³ DOFs). The steps' own tests keep the fixed scale: measured against ‖v‖, which moves, the clamped
strip's Signorini dual failed after 100 steps."""
SUM_FLOOR = 1e5
"""Where P has its own formula of P x + q (:func:`_affine`) and is an operator, that formula serves from the start (one
solve with K, as a product is); where P is a matrix a product is far cheaper than the solve (2-D punch at 10⁵ DOFs,
Tresca: 27 solves took the dense newton-cg from 0.12 to 0.94 s), so the sum serves until the natural residual is within
SUM_FLOOR × ε ‖c q‖∞ of 0 or passes the stopping test, P's own formula after (the sum's rounding held the clamped
strip 400 : 1 at ~5·10³ ε ‖c q‖ for 100 steps; from there P's own formula refines it as iterative refinement does)."""
REUSE = 4.0
"""Where a Newton system's preconditioner (:class:`_Preconditioner`, with balls) keeps its factors instead of a
numeric refactorization of H + Gᵀ D⁻¹ G, where that is K-sized: a body that is its own approximation, H = K on its
DOFs (a plate 20 : 20 : 1: 9 refactorizations, 35 of the 53 s of its Tresca solve at 7.9·10⁴ DOFs; one costs 15–30
solves with its factors, as many products with W). Not on a slab with coarse functions: its factorization costs a
few products (2-D strip at 10⁵ DOFs: 0.053 s against 0.016 s for a solve with K), and keeping the factors there cost
more products than it saved (the 2-D family at 2·10⁴ DOFs, Tresca: 7–45 % more; the pair 99 → 150). Two cases, each
with a bound:

- the same face as the system factored (free variables, spheres, tangent bases) and D within a spread of REUSE
  (max over min of d/d_kept): the kept system's exact inverse then has its eigenvalues against this one's within
  [min d/d_kept, max d/d_kept] (the two differ by a diagonal), so CG's condition number is at most REUSE;
- a grown face (:func:`_grown`; none released, GROW) of a step whose first system was factored: its variables held
  more only remove terms (a bound's 1/δ) or shrink them (a ball's two δ⁻¹ e eᵀ to one b bᵀ/(bᵀδb + curvature), smaller
  by Cauchy–Schwarz), so the factors of H + G₀ᵀ D₀⁻¹ G₀ with this face's G and D are the exact inverse of D + G H′⁻¹ Gᵀ
  with H′ ⪰ H (Woodbury): SPD, its eigenvalues against the system's ≥ 1, those above 1 at most the rank of the terms
  removed. After the empty face (FIRST_FORCING) the same holds with sets released too: its factored terms are every
  variable's 1/δ, which bound any face's. The free plate 20 : 20 : 1 at 2.6·10⁵ DOFs, Tresca: its first step's seventh
  face released a set and was refactorized, 4.9 s for 1 CG iteration; kept, 12 iterations, 2.8 s (factorizations
  3 → 2, products 88 → 99, the same 5 Newton steps). A loss where a refactorization costs nothing: the coarse program
  (COARSE_SETS, H = I as small as P) from no start, taken only where its approximation's solve fails
  (:func:`_approximated`): the 2-D pair at 2·10⁴ DOFs 53 → 67 coarse products."""
KEPT_FORCING = 0.01
"""CG on a grown face preconditioned by the factors of the face it grew from (REUSE) stops at KEPT_FORCING × its first
residual, not GROWN_FORCING: the exact inverse went well past GROWN_FORCING in its one or two iterations, and at
GROWN_FORCING the first step's point on the free strips 100 / 400 : 1 (10⁴ DOFs) was 10 times farther from the answer
and they took 3 Newton steps instead of 2 (0.01: 2 steps, 32–33 products; 0.001: 2, 35–37; the step's own target:
2, 41–44; the plate 20 : 20 : 1 at 2·10⁴ DOFs 5 steps and 59 / 65 / 92 products; the exact inverse 25 on the strips,
43 on the plate, with 6 and 9 factorizations against 2). The step's later grown faces stop there too, at KEPT_FORCING ×
the first kept face's residual, not their own (``grown_point``'s ``level``): each face is a few columns off the last,
whose point it starts from, so its own first residual is already that much smaller, and KEPT_FORCING of it asked 100
times more of each face in turn. The free plate 20 : 20 : 1, Tresca, from the empty face: at 2.6·10⁵ DOFs its
grown faces took 6 / 11 / 9 / 9 / 15 / 12 CG iterations, now 6 / 7 / 4 / 3 / 0 (products 99 → 57, the same 5 Newton
steps and 2 factorizations); at 7.9·10⁴ 57 → 44; the free strip 400 : 1 at 10⁴ DOFs 2 Newton steps / 27 products →
3 / 23 (docs/performance.md, "The free plate's second Newton step")."""
ROTATION = 0.3
"""Largest change of a tangent basis's entries (~ its angle) for which a Newton system is the same face as the one
factored (REUSE)."""
FIXED_STEPS = 3
"""Where radii move and no step lowers the natural residual (a stall), at most FIXED_STEPS times the step to the answer
of the program whose radii are fixed at v's (the fixed-point map x ↦ that answer: Picard's, from v) is taken, whether
or not it lowers the residual: finitely many such steps, so the monotone rule holds from the last of them on, and
Newton's point stays a trial. The 3-D tall block at 3.2·10⁵ DOFs (matrix-free) stalled after 3 steps at 2.1e-3, the
residual's ∞-norm refusing every point, and the Picard map ran (9 Tresca solves, 479 products with W, certificate
9.7e-10); the Tresca answer under v's radii raised it to 8.2e-3 (so a monotone test refused it too), and from there 4
Newton steps reached 3e-16: 212 products, certificate 9e-15 (docs/performance.md, "The 3-D tall block's Coulomb
stall")."""
FIXED_FORCING = 1e-3
"""The fixed-point step's solve stops at FIXED_FORCING × the natural residual it starts from (or tol)."""
GMRES_RESTART = 50
"""Krylov vectors GMRES keeps where radii move (the Newton system is then not symmetric)."""
GMRES_LIFT = True
"""Where radii move, ∇f at Newton's point is ∇f at the step's start + P̃ Z ξ from GMRES's own products, ξ their inputs'
combination (:func:`_combined`), as CG's updates give it where radii are fixed: ∇f there cost the step's test a
product where the point is feasible, and a refused point's face another (``grown_point``). The solve where radii move,
products: the 2-D pair at 2·10⁴ DOFs forced matrix-free 132 → 119, at 1.4·10⁶ DOFs 78 → 74, the same 6 Newton steps
and GMRES iterations (docs/performance.md, "The pair's products that are not CG iterations")."""
GMRES_CYCLES = 10
"""Restarts of GMRES per Newton system: a direction for the step rules, which judge it, not a solve to the end. Two P2
spheres with Coulomb (12,168 DOFs, matrix-free): near the axis node's answer GMRES(50) stagnated at 1e-7–1e-9 of the
right-hand side against a target of 3e-11, 4,100–4,400 iterations a system (CG_LIMIT); capped, the same 20 Newton
steps and answer in 33 s instead of 255 s."""
UPDATE_RANK = 64
"""Largest number of rank-one terms g gᵀ/d (a free variable or tangent coordinate joining or leaving the face, or its
d changing) by which a Newton system's H + Gᵀ D⁻¹ G may differ from the one factored and still be solved with those
factors by Woodbury (:class:`_Updated`) instead of a numeric refactorization. The preconditioner stays exact (up to
rounding), so the Newton path does not change, unlike a kept, inexact one (REUSE; ``keptrule`` in
docs/performance.md: 6 → 8 Newton steps on the pair at 1.4·10⁶ DOFs). The pair at 2.8·10⁵ DOFs, Tresca: consecutive
faces differ by 1–20 terms on 23 of its 44 refactorized systems (docs/performance.md, "The preconditioner updated by
low rank"). Each CG iteration then also multiplies by Z (rank × H's size)."""
COARSE_SETS = 64
"""A solve from no start with P an operator that carries an approximation (fixed radii) first solves the program
restricted to COARSE_SETS aggregates of neighbouring bounds and as many of balls (:func:`_coarse_start`), and starts
from that answer. From no start the first step's faces find the opening and slip zones a front at a time, the part of
the zone left after each face a fixed fraction of the last (the 2-D pair at 3.2·10⁵ DOFs, Signorini: 0, 8, 16, 201,
561, …, 1124, 1135 of 1153 bounds held in 10 faces), each face a product, a gradient and mostly a refactorization; the
coarse program finds the zones to within an aggregate in a few faces on 64 unknowns, and the fine one's faces then
move the fronts within it (docs/performance.md, "The first step on aggregated rows")."""
LIFT = 1e-12
"""∇f at the coarse answer x = shift + Q̃ x_c (COARSE_SETS) is q + P Q̃ x_c from the coarse solve's own products, P Q̃
kept before Q̃ᵀ restricts it (:class:`_Coarse`), where x_c is their inputs' combination to LIFT × ‖x_c‖∞ (least
squares: that solve's points are such combinations, as its gradients are of the products, but where a projection
moved one): a fresh ∇f there cost the fine program a product. Against a fresh ∇f by W's own formula at the 2-D pair's
coarse answers (2·10⁴–2.8·10⁵ DOFs; Signorini, Tresca, Coulomb's stick start): 2e-16–4e-15 of its largest entry
(tests/test_products.py)."""
COARSE_TOL = 1e-5
"""The coarse program's tolerance (COARSE_SETS): its answer is a start, constant on each aggregate. The coarse program
starts from its approximation's answer (:func:`_approximated`), near its own, so a tighter tolerance costs it few
products, and the fine path needs it: the pair at 1.4·10⁶ DOFs, Tresca, from there to 1e-3 took 6 coarse products, then
4 Newton steps and 105 products with 12 refactorizations and 17 updates; to 1e-5, 8 coarse products, then 3 steps and
78 products with 13 and 9, as from no start to 1e-3 after 35 coarse products (docs/performance.md, "The coarse program
from its approximation's answer"). From no start, 1e-2 on the pair at 10⁵ DOFs forced matrix-free, Tresca: 82 → 108
products."""
COARSE_BOUNDS_TOL = 1e-3
"""COARSE_TOL where the sets are bounds alone (Signorini): there the fine path needs the coarse answer only to 1e-3.
The pair (Newton steps, the fine program's products, the coarse program's), 1e-5 → 1e-3: at 1.4·10⁶ DOFs 2, 26, 12 →
2, 26, 11; at 3.5·10⁵ forced matrix-free 3, 28, 10 → 3, 28, 6 (the coarse program's second Newton step, 4 products,
took its residual from ~1e-3 to ~4e-8). Looser, 1e-2, it stopped at 1.3e-3 after one step at 1.4·10⁶ and the fine
first step grew two faces more: 8 coarse products, 30 fine (docs/performance.md, "The pair's Signorini products")."""
LINE = 8
"""The coarse start (COARSE_SETS) only where the sets' rows form a line: the breadth-first levels of their graph from
the reverse Cuthill–McKee order's start number at least 1 / LINE of the rows (the 2-D pair at 2·10⁴ / 5·10⁴ DOFs: 44
of 148, 98 of 345 bounds; the 3-D pair of spheres at 10⁵: 16 of 511). On a 3-D face the opening and slip zones are a
few nodes across and the fine faces from no start are few: there the coarse program's own 26–49 products outweighed
what it saved (forced matrix-free at 10⁵–3·10⁵ DOFs: Tresca 72–75 → 95, Coulomb 68 → 82 products; compact patches in
place of RCM's bands were no better; docs/performance.md, "The coarse start on the 3-D rows at 3·10⁵ DOFs")."""
UPDATE_SOLVES = 12
"""Largest number of the update's terms not met since the factorization (each a solve with the factors, ≈ 7 ms on the
pair at 2.8·10⁵ DOFs, against ≈ 0.1 s for a refactorization): a term of the last update keeps its solve."""


def check_settings(names) -> None:
    """The solver has no native settings: refuse any."""
    if names:
        raise ValueError(f"{min(names)}: newton-cg has no such setting; it takes tol, max_iter, verbose, "
                         "progress")


@dataclass
class _Bounds:
    """The change of variables x = shift + scale ⊙ v and where the sets of v are."""

    scale: np.ndarray
    shift: np.ndarray
    bounds: np.ndarray  # variables with v ≥ 0
    balls: np.ndarray  # (k, p) variables of each ball
    radius: np.ndarray  # (k,)
    coupling: sp.csr_matrix | None = None  # radii that move: ρ = coupling v + radius (in v), see coupled()

    def radii(self, v: np.ndarray) -> np.ndarray:
        """The balls' radii at v."""
        return self.radius if self.coupling is None else np.maximum(self.coupling @ v + self.radius, 0.0)


def _bounds(program: ConicProgram, form: BoundForm, coupling: sp.spmatrix | None = None) -> _Bounds:
    scale, shift = np.ones(program.n_variables), np.zeros(program.n_variables)
    rows = np.concatenate([form.bound_rows, form.ball_rows.ravel()])
    columns = np.concatenate([form.bound_vars, form.ball_vars.ravel()])
    coef = np.concatenate([form.bound_coef, form.ball_coef.ravel()])
    scale[columns], shift[columns] = -1.0 / coef, program.b[rows] / coef
    if coupling is None:
        return _Bounds(scale, shift, form.bound_vars, form.ball_vars, program.b[form.ball_radius_rows])
    coupling = sp.csr_matrix(coupling)  # ρ = coupling x = coupling (shift + scale ⊙ v)
    return _Bounds(scale, shift, form.bound_vars, form.ball_vars, coupling @ shift,
                   sp.csr_matrix(coupling @ sp.diags(scale)))


def bound_form_of(program: ConicProgram) -> BoundForm:
    """The program's bound form, or a ValueError saying what this solver takes."""
    form = bound_form(program)
    if form is None or form.equality.size:
        raise ValueError("newton-cg takes programs in bound form: each nonnegative or second-order cone row holds "
                         "one variable of its own, and no equality rows (a force-controlled obstacle adds one); "
                         "use clarabel on this program")
    if (program.b[form.ball_radius_rows] < 0).any():
        raise ValueError("newton-cg: a second-order cone of negative radius (the program is infeasible)")
    return form


class Session:
    """Newton-CG set up for ``program``: :meth:`update` changes q and b, and the next solve starts from
    the last answer (or from :meth:`seed`)."""

    def __init__(self, program: ConicProgram, tol: float | None = None, max_iter: int = 100, verbose: bool = False,
                 polishing: bool = True, progress=None, **native):
        check_settings(native)  # polishing: the answer is an active-set answer already
        self.program, self._form = program, bound_form_of(program)
        self._tol, self._max_iter, self._verbose, self._progress = tol or TOL, max_iter, verbose, progress
        self._start: np.ndarray | None = None
        self._cache: dict = {}  # the preconditioner and the step lengths, made at the first solve

    def update(self, q: np.ndarray | None = None, b: np.ndarray | None = None):
        self.program = self.program.updated(q, b)
        if (self.program.b[self._form.ball_radius_rows] < 0).any():
            raise ValueError("newton-cg: a second-order cone of negative radius (the program is infeasible)")

    def seed(self, guess: ConicSolution):
        if self._start is None:
            self._start = guess.x

    @property
    def started(self) -> bool:
        """Whether the next solve has a start: a seed, or the last answer (a sweep's or a load history's)."""
        return self._start is not None

    def trial(self, b: np.ndarray, max_iter: int) -> ConicSolution:
        """At most ``max_iter`` Newton steps from no start on this session's program with the bounds ``b`` (a start for
        another solve: the stick start of :func:`~convexcontact.drivers.picard.newton_session`), the coarse program's
        answer one of them where it begins the solve (COARSE_SETS), with this session's preconditioner; the session's
        program and start are left as they were."""
        return newton_cg(self.program.updated(b=b), self._form, None, self._tol, max_iter, self._verbose, None,
                         self._cache, coarse_step=True)

    def coupled(self, coupling: sp.spmatrix, max_iter: int = 30) -> ConicSolution:
        """:func:`coupled` from the last answer, with this session's preconditioner; the session's program then
        holds the radii reached, and the next solve starts from its answer. The session's max_iter bounds it too."""
        solution = coupled(self.program, coupling, self._start, self._tol, min(max_iter, self._max_iter), self._verbose,
                           self._cache)
        if solution.solved:
            self.update(b=self.program.b.copy())
            self.program.b[self._form.ball_radius_rows] = solution.info["radii"]
            self._start = solution.x
        return solution

    def solve(self, tol: float | None = None, fresh: bool = False) -> ConicSolution:
        """From the last answer (or the seed) to this session's tolerance, or to a looser ``tol`` (a start's);
        ``fresh``: from no start instead (the coarse program's answer, where one begins the solve: COARSE_SETS)."""
        solution = newton_cg(self.program, self._form, None if fresh else self._start, max(self._tol, tol or 0.0),
                             self._max_iter, self._verbose, self._progress, self._cache)
        if solution.solved:
            self._start = solution.x
        return solution


def coupled(program: ConicProgram, coupling: sp.spmatrix, start: np.ndarray, tol: float | None = None,
            max_iter: int = 30, verbose: bool = False, cache: dict | None = None) -> ConicSolution:
    """Newton's method from ``start`` on the program whose ball radii move with x: ‖v_k‖ ≤ (coupling x)_k, a
    quasi-variational inequality (no f is minimized: the Newton system is not symmetric, GMRES solves it, and a step is
    taken where it lowers the natural residual: Newton's point, else the point on the face grown by the sets it leaves
    (GROW_MOVING; on intervals Newton's point is on the natural map's faces, RELEASE_MOVING), else a point towards
    Newton's or the projected gradient's, else the fixed-point map's step, FIXED_STEPS). ``coupling`` (balls ×
    variables) may not involve the balls' own variables. The answer is that of the program whose radius rows hold the
    radii it reached (also ``info["radii"]``); "failed" (solver status "stalled") where no step lowers the residual:
    without a convexity argument Newton's method is local, so start near the answer (a fixed point of x ↦ the program's
    answer with radii coupling x)."""
    form = bound_form_of(program)
    coupling = sp.csr_matrix(coupling)
    if coupling.shape != (form.ball_vars.shape[0], program.n_variables):
        raise ValueError(f"newton-cg: coupling has shape {coupling.shape}, expected one row per ball and one column "
                         f"per variable, {(form.ball_vars.shape[0], program.n_variables)}")
    if np.isin(coupling.indices, form.ball_vars).any():
        raise ValueError("newton-cg: a radius may not depend on the balls' own variables")
    return newton_cg(program, form, start, tol or TOL, max_iter, verbose, None, cache, coupling)


def solve(program: ConicProgram, **options) -> ConicSolution:
    """Solve a bound-form ``program`` (P a matrix or a scipy LinearOperator); options as :class:`Session`."""
    return Session(program, **options).solve()


def newton_cg(program: ConicProgram, form: BoundForm, start, tol: float, max_iter: int, verbose=False,
              progress=None, cache: dict | None = None, coupling: sp.spmatrix | None = None,
              coarse_step: bool = False) -> ConicSolution:
    """Newton's method on the natural map from ``start`` (x; None: the projected gradient step from 0);
    ``cache`` keeps the preconditioner and the step lengths (c: one product, see :func:`_step_lengths`) for the next
    solve of a session (the pair's Coulomb problem at 1.4·10⁶ DOFs: three solves, 2 products fewer); ``coupling``:
    see :func:`coupled`; ``coarse_step``: the coarse program's answer, where one begins the solve (COARSE_SETS),
    counts as one of ``max_iter``'s Newton steps (a trial's, :meth:`Session.trial`)."""
    began = time.perf_counter()
    P = _operator(program.P)
    sets = _bounds(program, form, coupling)
    matrix = None if isinstance(program.P, spla.LinearOperator) else functools.cache(  # P̃, made at a dense step
        lambda: _scaled(program.P, sets.scale))
    products = [0]
    fresh = [None]  # the last ∇f gradient() computed, where it is the stopping test's fresh one (see that test)
    evaluated = [0, None]  # P's own formula's evaluations: how many, and the last ∇f it gave (see _fresh_enough)
    as_sum, own = _affine(program)
    exact = own is not None and matrix is None  # see SUM_FLOOR

    def affine(x):
        if not exact:
            return as_sum(x)
        value = own(x)
        evaluated[:] = evaluated[0] + 1, sets.scale * value
        return value

    def gradient(v):
        """∇f in v: scale ⊙ (P x + q); q itself at x = 0, without a product: a solve from no start began with one
        there, its coarse program's too (the pair at 1.4·10⁶ DOFs, Signorini: 65 → 63 products)."""
        x = sets.shift + sets.scale * v
        if not x.any():
            return sets.scale * program.q
        products[0] += 1
        g = sets.scale * affine(x)
        fresh[0] = g if exact == (own is not None) else None  # by the formula the stopping test takes
        return g

    @functools.cache
    def curvature():
        """P̃'s mean eigenvalue by one random product, taken only where it serves: the step lengths of variables whose
        diagonal is not known (:func:`_step_lengths`), the preconditioner's δ without the approximation's estimate
        (:func:`_shifts`). Where P is a matrix with a positive diagonal, or the contact dual's operator whose
        approximation estimates it, it served neither: one product (a K solve) of each call, its coarse program's
        too (the pair at 1.4·10⁶ DOFs, Signorini: 67 → 65 products; docs/performance.md, "The pair's products that
        are not CG iterations")."""
        probe = np.random.default_rng(0).standard_normal(program.n_variables) * sets.scale
        products[0] += 1
        return probe @ P.matvec(probe) / (probe @ probe)

    def fallback():  # 0.1: 219 products on a 2-D Tresca dual, 1: 263, 10: 2076
        return 0.1 / curvature() if curvature() > 0 else 1.0

    cache = {} if cache is None else cache
    if "lengths" not in cache:  # a session's P and scale do not change (its update takes q and b)
        cache["lengths"] = _step_lengths(program.P, sets, fallback, products)
    c = cache["lengths"]
    v = np.zeros(program.n_variables) if start is None else (start - sets.shift) / sets.scale
    if start is not None and sets.coupling is None:  # the last answer may be outside this program's sets (a Picard
        v = _project(v, sets)  # step's smaller radii), and the convergence argument needs v₀ in them
    g = gradient(v)
    coarse = None
    if start is None:  # the projected gradient's point, or the coarse answer (COARSE_SETS: before the preconditioner's
        v = _project(v - c * g, sets)  # factors, whose peak is the fine program's), whose first face is then its own
        if sets.coupling is None and matrix is None:  # (FORCING, not the empty face's FIRST_FORCING)
            coarse = _coarse_start(program, sets, v, max_iter, verbose)
        lifted = None
        if coarse is not None:
            point, _, lifted = coarse
            point = (point - sets.shift) / sets.scale
            v = _project(point, sets)
            products[0] += coarse[1]["products"]
            max_iter -= coarse_step
            lifted = lifted if np.array_equal(v, point) else None  # ∇f at the coarse answer, not at its projection
        g = gradient(v) if lifted is None else lifted
    if "precondition" not in cache:
        approximation = getattr(program.P, "approximation", None)
        cache["precondition"] = approximation and _Preconditioner(approximation, sets.scale, sets.balls,
                                                                  SHIFT * _shifts(approximation, sets, curvature))
    factorized = getattr(cache["precondition"], "factorizations", 0)  # before this solve (info["factorizations"])
    updated = getattr(cache["precondition"], "updates", 0)
    def natural(v, g):
        """:func:`_natural` with this solve's step lengths."""
        return _natural(v, g, c, sets, program.q)

    def move(v, g, w, known=None):
        """∇f at w, f(w) − f(v) (exact: f is quadratic) and P̃(w − v): one product. Where P x + q has its own
        formula (:func:`_affine`) ∇f at w is that, not g + P̃(w − v): the sum's errors, ε‖P̃‖‖w − v‖ a step, added
        up over the large first steps and stood for the gradient at the end (strip 400 : 1 clamped, Tresca: a natural
        residual of 6e-13 reported where ∇f gave 4e-10)."""
        d = w - v
        if known is not None:  # ∇f at w, already computed
            return known, g @ d + 0.5 * (d @ (known - g)), known - g
        if exact:
            g_end = gradient(w)
            return g_end, g @ d + 0.5 * (d @ (g_end - g)), g_end - g
        products[0] += 1
        Pd = sets.scale * P.matvec(sets.scale * d)
        return g + Pd, g @ d + 0.5 * (d @ Pd), Pd

    def least_on_segment(v, g, w, Pd):
        """The least f on [v, w] (feasible: both ends are), ∇f there and f's change: exact, P̃(w − v) = ``Pd``."""
        d = w - v
        slope, curve = g @ d, d @ Pd
        alpha = min(1.0, max(0.0, -slope / curve)) if curve > 0 else float(slope < 0)
        return v + alpha * d, g + alpha * Pd, alpha * slope + 0.5 * alpha**2 * curve

    def descend(v, g, towards, residual, cauchy, risen, known, epsilon, target):
        """The step from v to Newton's point ``towards`` or towards it (see "Convergence" in the module's docstring):
        Π(``towards``) where its natural residual is below ``residual`` and f there is at most f(v₀) (f − f(v₀) =
        ``risen`` at v); else the first point that lowers f by ARMIJO × |``cauchy``|, the projected gradient's
        first-order decrease, of: after a step that was no Newton point, the face step (:func:`face_step`, ``epsilon``,
        ``target``; FACE); the least f on the segment to Π(``towards``), the projection arc towards it (ARC); else
        the least f on the projected gradient's segment. The point, ∇f there, f's change and which point it is.
        One order whether P is a matrix or an operator (see ARC)."""
        end = _project(towards, sets)  # the points themselves are returned: v + (w − v) would leave bounds by round-off
        g_end, change, Pd = move(v, g, end, known if np.array_equal(end, towards) else None)
        if risen + change <= 0 and natural(end, g_end)[0] < residual:
            return end, g_end, change, "residual"
        face = face_step(v, g, cauchy, epsilon, target) if FACE and descent and descent[-1][0] != "residual" else None
        if face is not None:
            return (*face, "face")
        on_segment = least_on_segment(v, g, end, Pd)
        if on_segment[2] <= ARMIJO * cauchy:
            return (*on_segment, "segment")
        for alpha in 0.5 ** np.arange(1, ARC):
            w = _project(v + alpha * (towards - v), sets)
            gw, change, _ = move(v, g, w)
            if change <= ARMIJO * cauchy:
                return w, gw, change, "arc"
        return (*gradient_step(v, g), "gradient")

    def face_step(v, g, cauchy, epsilon, target):
        """The least f on the segment from v towards Newton's point on the face that holds every set within
        ``epsilon`` of its boundary where it is (:func:`_working`; CG to ``target``), as far as the other sets allow
        (:func:`_feasible_length`; a held ball's tangent move projected back onto its sphere), ∇f there and f's
        change, where that lowers f by ARMIJO × |``cauchy``|; else None (FACE)."""
        nonlocal cg_total
        held = _working(v, sets, epsilon)
        newton, iterations, known = _step(P, affine, sets, v, held, c, target, products, cache["precondition"], matrix,
                                          gradient_at=(v, g) if loose else None)
        cg_total += iterations
        alpha = _feasible_length(v, newton - v, sets, held)
        end = _project(v + alpha * (newton - v), sets)
        _, _, Pd = move(v, g, end, known if np.array_equal(end, newton) else None)
        w, gw, change = least_on_segment(v, g, end, Pd)
        return (w, gw, change) if change <= ARMIJO * cauchy else None

    def gradient_step(v, g):
        """The least f on the segment from v to the natural map's point Π(v − c∇f), ∇f there and f's change."""
        p = _project(v - c * g, sets)
        return least_on_segment(v, g, p, move(v, g, p)[2])

    def newton_point(v, g, y, target, empty=False):
        """Newton's point from v (∇f there g) on the face y holds, the CG iterations it took and ∇f there where known;
        with fixed radii, or moving radii on intervals (RELEASE_MOVING), on the face the natural map holds at that point
        (:func:`grown_point`), whose solves stop at GROWN_FORCING alone where y is the ``empty`` face
        (FIRST_FORCING)."""
        face = {}  # the dense Cholesky factor of this step's first system, for its grown faces (_direct)
        newton, iterations, known = _step(P, affine, sets, v, y, c, target, products, cache["precondition"], matrix,
                                          face=face, gradient_at=(v, g) if loose else None)
        if natural_faces:
            newton, more, known = grown_point(v, y, newton, 0.0 if empty else target, face, known=known, empty=empty)
            iterations += more
        return newton, iterations, known

    def grown_point(v, y, newton, target, face=None, limit=None, known=None, empty=False):
        """Newton's point on the face y holds, updated to the face the natural map holds at that point (fixed radii, or
        moving radii on intervals, RELEASE_MOVING: :func:`_released`, ∇f there ``known`` or one product) or, where
        radii move on balls of more variables, grown by the sets the point leaves (:func:`_grown`), each solve started
        from the last point, projected, until the face stays (at most ``limit`` times, GROW by default; see GROW); the
        point, the CG iterations it took and ∇f there where known; ``empty``: y is the empty face."""
        iterations, at, released, moved = 0, v, np.zeros(v.size, bool), False
        level = [0.0]  # where the step's first kept solve stopped: the later ones' target too (KEPT_FORCING)
        for _ in range(GROW if limit is None else limit):
            if natural_faces:
                known = gradient(newton) if known is None else known
                y, more = _released(y, newton, known, c, sets, released, sets.radii(at), sets.radii(newton))
                moved = moved or more
            else:
                y = _grown(y, newton, sets, sets.radii(at))
            if y is None:
                break
            at = _project(newton, sets)
            # not the step's kept factors where radii move: REUSE's bound is for CG's symmetric systems, and GMRES
            # on the clamped plate's Coulomb problem (2·10⁴ DOFs) took over 4 min CPU with them, 13 s without; nor
            # once a set was released, but after the empty face, whose factors bound every face's (see REUSE)
            newton, more, known = _step(P, affine, sets, at, y, c, max(target, level[0]), products,
                                        cache["precondition"], matrix, GROWN_FORCING, face,
                                        grown=sets.coupling is None and (empty or not moved), level=level,
                                        gradient_at=(newton, known) if loose and known is not None else None)
            iterations += more
            faces[0] += 1
        return newton, iterations, known if y is None else None

    def backtrack(v, g, towards, residual, lengths=(1.0, 0.5, 0.25, 0.125, 0.0625), known=None):
        """Without an f (moving balls), the first of ``lengths`` (1, ½, …, 1/16) of the way to ``towards``
        (projected; ∇f there ``known``, where it is) whose natural residual is below ``residual``; ``v`` itself where
        none is."""
        for alpha in lengths:
            w = _project(towards if alpha == 1.0 else v + alpha * (towards - v), sets)
            gw = known if alpha == 1.0 and known is not None and np.array_equal(w, towards) else gradient(w)
            if natural(w, gw)[0] < residual:
                return w, gw, True
        return v, g, False

    def answer(v, size):
        """The scale the stopping test holds the residual to: see LOAD_SCALE."""
        return max(np.abs(v).max(initial=0.0), LOAD_SCALE * size) if exact else size

    def drift_at(g) -> float:
        """``drift`` where ∇f is g and no updates are counted: 0 where P's own formula gave g, else ∞."""
        return 0.0 if g is fresh[0] else np.inf

    residual = first = None
    drift = drift_at(g)  # c ⊙ what updates added to ∇f since P's own formula gave it, ∞-norm
    best, history = np.inf, []
    risen, kinds, descent = 0.0, dict.fromkeys(("residual", "segment", "arc", "gradient", "face"), 0), []
    steps = cg_total = 0
    faces = [0]  # the faces grown (see GROW)
    fixed_steps = 0  # the fixed-point map's steps taken where radii move (see FIXED_STEPS)
    status, word = "failed", "max_iter"
    floor = SUM_FLOOR * EPS * (c * np.abs(sets.scale * program.q)).max(initial=0.0)
    natural_faces = sets.coupling is None or (RELEASE_MOVING and sets.balls.shape[1] == 1)  # at every Newton point
    for steps in range(max_iter + 1):
        residual, y, size = natural(v, g)
        if residual * size <= max(tol * answer(v, size), 0.0 if exact or own is None else floor):
            exact = own is not None  # the sum's rounding is near: P's own formula from here on, where it has one
            if (exact or tol < LOAD_SCALE) and g is not fresh[0] and not _fresh_enough(drift,
                                                                                     0.1 * tol * answer(v, size)):
                # ∇f was updated along the segments: check with a fresh one; not a sum again against a tolerance above
                # √ε (the coarse program's, COARSE_TOL), beyond the rounding of the updates, ε‖P̃‖‖w − v‖ each: a
                # product of each coarse solve (the pair at 1.4·10⁶ DOFs, Signorini: 63 → 62 products); nor where ∇f
                # is fresh already (a segment's end by P's own formula, ``move``: the 3-D rows' Tresca steps, whose
                # Newton points leave their spheres, flat block at 3·10⁴ DOFs 44 → 43) or the last step's updates
                # of one (drift, _fresh_enough)
                g = gradient(v)
                residual, y, size = natural(v, g)
        first = first or residual
        history.append(residual)
        if verbose:
            print(f"newton-cg {steps:3d}  natural residual {residual:.2e}  products {products[0]}")
        if progress is not None:
            progress(steps, residual)
        if not np.isfinite(residual):
            word = "diverged"
            break
        if residual * size <= tol * answer(v, size):
            status, word = "solved", "converged"
            break
        if steps == max_iter:
            break
        empty = steps == 0 and start is None and coarse is None and sets.coupling is None and matrix is None
        target = (FIRST_FORCING if empty else FORCING) * min(1.0, residual / first) * residual * size / np.max(c)
        target = max(target, 0.1 * tol * answer(v, size) / np.max(c))
        # ∇f's sums may serve (_start_gradient): above the sum's rounding, or the updates' (_fresh_enough)
        loose = not exact or target * np.max(c) >= floor or _fresh_enough(drift, target * np.max(c))
        count = evaluated[0]
        newton, iterations, known = newton_point(v, g, np.zeros_like(y) if empty else y, target, empty)
        cg_total += iterations
        best = min(best, residual)
        if sets.coupling is not None:
            v, g, moved = backtrack(v, g, newton, residual, (1.0,), known)
            if not moved and not natural_faces:  # Newton's point refused: first on the face grown by the sets it
                # leaves (GROW_MOVING)
                grown, more, at_grown = grown_point(v, y, newton, target, limit=min(GROW, GROW_MOVING), known=known)
                cg_total += more
                if grown is not newton:
                    v, g, moved = backtrack(v, g, grown, residual, known=at_grown)
            if not moved:
                v, g, moved = backtrack(v, g, newton, residual, (0.5, 0.25, 0.125, 0.0625))
            if not moved:  # a projected-gradient segment, as for a fixed f: Newton stalled on a punch with F = 2
                v, g, moved = backtrack(v, g, _project(v - c * g, sets), residual, GRADIENT_LENGTHS)
            if not moved and fixed_steps < FIXED_STEPS:  # the fixed-point map's step (see FIXED_STEPS)
                fixed_steps += 1
                b = program.b.copy()
                b[form.ball_radius_rows] = sets.radii(v)
                fixed = newton_cg(program.updated(b=b), form, sets.shift + sets.scale * v, max(tol, FIXED_FORCING *
                                  residual), max_iter, verbose, None, cache)
                products[0] += fixed.info["products"]
                cg_total += fixed.info["cg_iterations"]
                if fixed.solved:
                    v = (fixed.x - sets.shift) / sets.scale
                    g, moved = gradient(v), True
            if not moved:
                word = "stalled"
                break
            drift = drift_at(g)
            continue
        # Newton's point, projected, where it halves the least natural residual so far (so those steps cannot cycle;
        # near the answer f's changes are round-off, and the segment alone stalled a 3-D Tresca dual at 2e-10), else a
        # point that lowers f at least as a fraction of the projected gradient's step does (see "Convergence")
        cauchy = g @ (_project(y, sets) - v)
        before = g
        v, g, change, kind = descend(v, g, newton, ACCEPT * best, cauchy, risen, known, residual * size, target)
        # drift: CG's updates of ∇f since the step's last fresh one, or since its start
        if kind == "residual" and g is known and exact and g is not fresh[0]:
            restarted = evaluated[0] > count
            drift = (0.0 if restarted else drift) + np.abs(c * (g - (evaluated[1] if restarted else before))).max()
        else:
            drift = drift_at(g)
        if kind in ("segment", "gradient") and natural(v, g)[0] > STALL * residual:
            v, g, more = gradient_step(v, g)
            change += more
        risen += change
        kinds[kind] += 1
        descent.append((kind, change, cauchy))
    x = sets.shift + sets.scale * v
    info = {"products": products[0], "cg_iterations": cg_total, "natural_residual": residual, "residuals": history,
            "steps": kinds, "descent": descent, "grown": faces[0], "fixed_steps": fixed_steps,
            "factorizations": getattr(cache["precondition"], "factorizations", 0) - factorized,
            "updates": getattr(cache["precondition"], "updates", 0) - updated,
            "coarse": None if coarse is None else coarse[1]}
    if sets.coupling is not None:  # the program of the radii reached: x is its answer
        b = program.b.copy()
        b[form.ball_radius_rows] = info["radii"] = sets.radii(v)
        program = program.updated(b=b)
    z = np.zeros(program.n_constraints)
    z[form.bound_rows] = np.maximum(g[form.bound_vars], 0.0)  # P x + q + Aᵀz = 0 with a = −1 / scale, z ≥ 0
    z[form.ball_rows] = g[form.ball_vars]
    z[form.ball_radius_rows] = np.linalg.norm(g[form.ball_vars], axis=1)
    if status != "solved" and residual is not None and residual <= 1e3 * tol:
        status = "inaccurate"
    return ConicSolution(x=x, z=z, s=program.b - program.A @ x, status=status, solver_status=word, iterations=steps,
                         solve_time=time.perf_counter() - began, solver="newton-cg", info=info)


def _coarse_start(program: ConicProgram, sets: _Bounds, v: np.ndarray, max_iter: int,
                  verbose: bool) -> tuple[np.ndarray, dict, np.ndarray | None] | None:
    """x of the answer of ``program`` restricted to x = shift + scale ⊙ Q v_c, solved to COARSE_TOL (COARSE_SETS),
    that solve's products (K solves, as this program's), Newton steps, faces grown, refactorizations and updates, and
    ∇f at x (in v) from that solve's own products where they give it (LIFT; else None): Q
    copies each coarse set to the sets of its aggregate (:func:`_aggregates`, bounds and balls apart), so a feasible
    v_c is a feasible x (a coarse ball's radius is its aggregate's least), and P_c = Q̃ᵀ P Q̃ (Q̃ = diag(scale) Q)
    carries P's approximation with G's rows summed alike (Q̃ᵀ G). None where P has no approximation or one without
    coarse functions beyond a slab (H may be K itself: the coarse approximation would cost a factorization of K, see
    REUSE; a 3-D clamped plate's Tresca dual at 2·10³ DOFs was then certified at 3e-10 against 1e-10), where some
    variable is in no set, where the sets are too few for the coarse program to be much smaller, where the
    projected gradient's point ``v`` holds at 0 no more bounds than an aggregate has (no zone to find at its scale), or
    where the sets' rows do not form a line (LINE)."""
    approximation = getattr(program.P, "approximation", None)
    groups = [members for members in (sets.bounds[:, None], sets.balls) if members.size]
    counted = sum(members.size for members in groups)
    if (approximation is None or approximation.slab in (None, approximation.H.shape[0])
            or counted < program.n_variables or sum(map(len, groups)) < 4 * COARSE_SETS
            or (v[sets.bounds] == 0).sum() * COARSE_SETS <= sets.bounds.size):
        return None
    G = sp.csr_matrix(approximation.G)
    rows, columns, cones, offset = [], [], [], 0
    bounds, radius = 0, np.zeros(0)  # the coarse bounds' count, the coarse balls' radii
    for members in groups:  # bounds (one variable each), then balls (p each)
        aggregate = _aggregates(G[members[:, 0]], COARSE_SETS)
        if aggregate is None:  # not a line (LINE)
            return None
        count, p = aggregate.max() + 1, members.shape[1]
        rows.append(members.ravel())
        columns.append((offset + aggregate[:, None] * p + np.arange(p)).ravel())
        if members is sets.balls:
            radius = np.full(count, np.inf)
            np.minimum.at(radius, aggregate, sets.radius)
            cones += [soc(1 + p)] * count
        else:
            bounds = count
            cones.append(nonnegative(count))
        offset += count * p
    Q = sp.csr_matrix((sets.scale[np.concatenate(rows)], (np.concatenate(rows), np.concatenate(columns))),
                      shape=(program.n_variables, offset))  # Q̃ = diag(scale) Q
    P = _Coarse(program.P, Q, _coarse_approximation(approximation, sp.csr_matrix(Q.T @ G)))
    q = program.q if not sets.shift.any() else program.q + program.P.matvec(sets.shift)
    p = sets.balls.shape[1]
    A = [-sp.eye(bounds, offset)] + [sp.vstack([sp.csr_matrix((1, offset)), -sp.eye(p, offset, bounds + k * p)])
                                     for k in range(radius.size)]  # each ball: its radius row, −I on its variables
    b = np.concatenate([np.zeros(bounds)] + [np.concatenate([[r], np.zeros(p)]) for r in radius])
    coarse = ConicProgram(P, Q.T @ q, sp.vstack(A).tocsc(), b, tuple(cones))
    bounds_only = not sets.balls.size
    lengths = {}  # the approximated program's step lengths (see _approximated)
    start = _approximated(coarse, max_iter, verbose, lengths)
    solution = newton_cg(coarse, bound_form_of(coarse), start, COARSE_BOUNDS_TOL if bounds_only else COARSE_TOL,
                         max_iter, verbose, cache=lengths if bounds_only else None)
    info = {key: solution.info[key] for key in ("products", "grown", "factorizations", "updates")}
    info.update(products=info["products"] + int(sets.shift.any()), steps=solution.iterations)
    lifted = P.lifted(solution.x)
    return sets.shift + Q @ solution.x, info, None if lifted is None else sets.scale * (q + lifted)


def _approximated(program: ConicProgram, max_iter: int, verbose: bool, lengths: dict) -> np.ndarray | None:
    """x of the answer of the coarse ``program`` (:func:`_coarse_start`) with P its approximation G Gᵀ, dense: no
    product with P, where it is solved (else None), the coarse solve's start. From no start the coarse program found its
    faces as the fine one did, each a product with W at least (a K solve): the pair at 1.4·10⁶ DOFs, Signorini 21 → 12
    coarse products, Tresca 35 → 8 (COARSE_TOL 1e-5), the fine program's Newton steps, products, refactorizations and
    updates the same; Coulomb's stick start at 2·10⁴ DOFs forced matrix-free 46 → 6.

    ``lengths`` gets that solve's step lengths, 0.1 / (G Gᵀ)_jj (a newton-cg ``cache``): the coarse program's where
    its sets are bounds alone, in place of Hutchinson's estimate (:func:`_step_lengths`, a product with W). A bound's
    step length only decides whether a variable within c∇f of 0 is held, and the ratio Hutchinson's product measures
    was ~0.75 there: the pair at 1.4·10⁶ DOFs, Signorini, 11 → 10 coarse products, the same fine path; 3.5·10⁵ forced
    matrix-free 6 → 5. Not with balls: the stick–slip test ‖v − c∇f‖ ≤ ρ takes c at every sticking node, and the
    pair's Tresca coarse program at 2·10⁴ DOFs forced matrix-free took 2 Newton steps and 23 products against 1 and 20
    (the fine program's ratio in place of the coarse one's: 25)."""
    G = program.P.approximation.G
    approximated = replace(program, P=sp.csc_matrix((G @ G.T).toarray()))
    solution = newton_cg(approximated, bound_form_of(approximated), None, COARSE_TOL, max_iter, verbose, cache=lengths)
    lengths.pop("precondition", None)
    return solution.x if solution.solved else None


def _coarse_approximation(approximation, G: sp.csr_matrix):
    """The coarse program's approximation A = G H⁻¹ Gᵀ (G: P's approximation's rows summed) as a dense matrix, in the
    approximation's form with H = I and G = V Λ^½ (A = V Λ Vᵀ: A may be singular, where summed rows are dependent or
    empty, as a 3-D clamped plate's friction rows on its symmetry planes): A from the approximation's ``reduced`` (one
    sparse factorization with G's few rows as its Schur block, or H's and a solve with them). With G's summed rows in a
    factorization of H + Gᵀ D⁻¹ G, each aggregate filled a block as wide as its DOFs: the pair at 1.4·10⁶ DOFs,
    Signorini, its peak memory 1.72 → 2.44 × the linear solve's."""
    values, vectors = np.linalg.eigh(approximation.reduced(G))
    root = sp.csr_matrix(vectors * np.sqrt(np.maximum(values, 0.0)))
    return replace(approximation, G=root, H=sp.eye(G.shape[0], format="csr"), slab=None)


def _aggregates(rows: sp.csr_matrix, count: int) -> np.ndarray | None:
    """Each row's aggregate: ``count`` runs of rows, consecutive in a reverse Cuthill–McKee order of the graph of
    rows sharing a column (on a 2-D contact face, the nodes along it); None where that graph is no line (LINE)."""
    pattern = sp.csr_matrix((np.ones(rows.nnz), rows.indices, rows.indptr), shape=rows.shape)
    graph = sp.csr_matrix(pattern @ pattern.T)
    order = reverse_cuthill_mckee(graph, symmetric_mode=True)
    distance = shortest_path(graph, unweighted=True, indices=order[-1])  # levels from RCM's start
    if (distance[np.isfinite(distance)].max() + 1) * LINE < rows.shape[0]:
        return None
    aggregate = np.empty(rows.shape[0], dtype=int)
    aggregate[order] = np.arange(rows.shape[0]) * count // rows.shape[0]
    return aggregate


class _Coarse(spla.LinearOperator):
    """x_c ↦ Q̃ᵀ P Q̃ x_c (see :func:`_coarse_start`); ``approximation`` that of P with G's rows summed by Q̃."""

    def __init__(self, P, Q: sp.csr_matrix, approximation):
        super().__init__(float, (Q.shape[1], Q.shape[1]))
        self._P, self._Q, self._Qt = P, Q, sp.csr_matrix(Q.T)
        self.approximation = approximation
        self._kept = []  # each product's x_c and P Q̃ x_c, before Q̃ᵀ restricts it (see lifted)

    def _matvec(self, x):
        x = np.asarray(x, dtype=float).ravel()
        full = self._P.matvec(self._Q @ x)
        self._kept.append((x.copy(), full))
        return self._Qt @ full

    def lifted(self, x: np.ndarray) -> np.ndarray | None:
        """P Q̃ x from the products taken, where x is their x_c's combination (:func:`_combined`); else None."""
        return _combined(self._kept, x)

    _rmatvec = _matvec


def _combined(taken: list, x: np.ndarray) -> np.ndarray | None:
    """A linear map's value at x from its values at the points ``taken`` ((point, value) pairs): Σ wᵢ valueᵢ for
    the weights with Σ wᵢ pointᵢ = x to LIFT × ‖x‖∞ (least squares); None where x is no such combination."""
    if not taken:
        return None
    X = np.stack([point for point, _ in taken], axis=1)
    weights = np.linalg.lstsq(X, x, rcond=None)[0]
    if np.abs(X @ weights - x).max(initial=0.0) > LIFT * np.abs(x).max(initial=0.0):
        return None
    return np.stack([value for _, value in taken], axis=1) @ weights


class _Preconditioner:
    """For each Newton system D + Rᵀ P̃ R (R: the step's free variables and tangent coordinates; D: the curvature
    there, + δ) from P ≈ G H⁻¹ Gᵀ (in v: G̃ = diag(scale) G). With balls (friction), the exact inverse of
    D + Rᵀ P̃_approx R by Woodbury, D⁻¹(ξ − Gᵣ (H + Gᵣᵀ D⁻¹ Gᵣ)⁻¹ Gᵣᵀ D⁻¹ ξ) with Gᵣ = Rᵀ G̃: factorized at the first
    system on a pattern that holds every later one, then a numeric refactorization where the factors kept cannot
    serve (REUSE). With bounds alone, the restriction to R of (P̃_approx + δI)⁻¹, the same formula with every
    variable free: one factorization per session.
    Measured on whole faces (contact solve, the other choice in brackets): 3-D Tresca 10.4 s (restriction first,
    exact after a step of more than 8 Krylov iterations: 12.8 s; the restriction alone left 24–36 iterations a
    step), 2-D Tresca 7.0 s (8.0 s); Signorini 3.6 s (3.9 s) in 2-D and 3.6 s (4.5 s) in 3-D, whose held variables
    are only the open nodes.
    With bounds alone, where a system's CG takes more iterations than a refactorization of H + Gᵀ D⁻¹ G costs
    products with W (PARDISO's flops against a solve's with K's factors, :func:`_cost`), the session's later systems
    get their faces' exact inverse instead, as with balls (:meth:`spent`). Measured on Signorini (docs/performance.md,
    "Signorini's faces exact where the restriction costs more"): the 2-D pair at 1.4·10⁶ DOFs (a refactorization
    7.7 products) restricted 6 Newton steps / 277 products, switched after its first system 3 / 96 with 13
    refactorizations; the 2-D family switches at 10⁵ (0.4–3.2 products) with the same or fewer products; the 3-D rows
    (10–140 products) do not switch: exact throughout, the 3-D pair at 3·10⁵ took 2 / 43 against 4 / 60 but 9
    refactorizations of ~4 s (contact solve 20 → 57 s)."""

    def __init__(self, approximation, scale: np.ndarray, balls: np.ndarray, shift):
        self.G, self.H = sp.csr_matrix(sp.diags(scale) @ approximation.G), approximation.H
        self.shift = np.broadcast_to(np.asarray(shift, dtype=float), scale.shape)  # δ, one or per variable
        self.exact = balls.size > 0
        self.factorizations = 0  # of H + Gᵀ D⁻¹ G, the first included
        self.updates = 0  # systems solved with the factors updated by low rank (UPDATE_RANK)
        self._solved: dict = {}  # a term's key (_terms) -> M⁻¹uᵀ with the factors of now (see _updated)
        self._factored = None  # (R, G, d) of the system the factors are of (see system)
        self._grows = False  # whether the factors are of this Newton step's first face (see system)
        self.kept = False  # whether the last system's are those of the face it grew from (see KEPT_FORCING)
        self._factorize = approximation.factorize
        self._holds = False  # whether the factors hold H as their refactorizations' base (see system)
        self._keeps = approximation.slab in (None, self.H.shape[0])  # H is K on DOFs, no coarse functions: see REUSE
        if not self.exact:
            self.factors = self._factorize(self.H, self.G.T @ sp.diags(1.0 / self.shift) @ self.G)
            self._cost = _cost(self.factors, approximation.fill)  # see spent
            return
        # every R D⁻¹ Rᵀ is on E: the pattern they all fit, factorized at the first system with its values (one
        # numeric factorization fewer than ordering it here with D = δ: the first system then refactorized at once)
        n, p = scale.size, balls.shape[1]
        pairs = (np.repeat(balls, p, axis=1).ravel(), np.tile(balls, (1, p)).ravel())
        E = sp.eye(n) + sp.csr_matrix((np.ones(pairs[0].size), pairs), shape=(n, n))
        self._pattern = sp.csr_matrix(abs(self.G).T @ E @ abs(self.G))  # on G's columns only: small beside H
        self._pattern.data[:] = 0.0  # its entries held as zeros, a term of the first factorization: every later face's
        self.factors = None

    def system(self, R: sp.csr_matrix, curvature: np.ndarray, grown: bool = False):
        """ξ ↦ the preconditioner of D + Rᵀ P̃ R, D = δ + ``curvature``; ``grown``: R's face is a grown face of the
        step's last system (:func:`_grown`). Refactorizes only where the factors kept cannot serve (REUSE)."""
        if not self.exact:
            return lambda xi: R.T @ _woodbury(self.factors, self.G, self.shift, R @ xi)
        d = R.multiply(R).T @ self.shift + curvature  # a tangent coordinate's δ: its ball's, weighted by its basis
        G = sp.csr_matrix(R.T @ self.G)
        self.kept = grown and self._grows and self._keeps
        if self.kept:  # H + Gᵀ D⁻¹ G of the face it grew from bounds this one's: see REUSE
            return lambda xi: _woodbury(self.factors, G, d, xi)
        kept = self._factored
        reusable = not grown and kept is not None and self._keeps  # H = K: the factors kept may serve (REUSE)
        signs = _face_signs(R, kept[0]) if reusable else None
        if signs is not None and _ratio_spread(d, kept[2]) <= REUSE:
            self._grows = False
            return lambda xi: signs * _woodbury(self.factors, kept[1], kept[2], signs * xi)
        terms = None if self._factored is None else _terms(R, d)  # the first system: after its factorization
        updated = self._updated(R, d, terms)
        if updated is not None:
            self._grows, self.updates = False, self.updates + 1  # the factors are not of this step's first face
            return lambda xi: _woodbury(updated, G, d, xi)
        near = self._near(R, d) if reusable else None
        if near is not None:
            self._grows, self.updates = False, self.updates + 1
            return near
        contact = G.T @ sp.diags(1.0 / d) @ G
        if self.factors is None:
            self.factors = self._factorize(self.H, contact, self._pattern)
            self._pattern = None
        else:
            if not self._holds:  # H placed once, the base of every later refactorization
                self.factors.hold(self.H)
                self._holds = True
            self.factors.refactorize(contact)  # added in place: no K-sized sum
        self.factorizations += 1
        self._factored, self._grows, self._solved = (R, G, d), True, {}
        self._terms = _terms(R, d) if terms is None else terms
        return lambda xi: _woodbury(self.factors, G, d, xi)

    def spent(self, iterations: int) -> None:
        """CG's ``iterations`` on the last system: with bounds alone, past a refactorization's cost in products, the
        session's later systems get their faces' exact inverse, starting from the factors it has: those of the face
        with every variable free."""
        if not self.exact and self._cost is not None and iterations > self._cost:
            n = self.shift.size
            self.exact, self._grows, self._solved = True, False, {}
            self._factored, self._terms = (sp.eye(n, format="csr"), self.G, self.shift), _terms(sp.eye(n), self.shift)

    def _updated(self, R: sp.csr_matrix, d: np.ndarray, terms: dict | None):
        """The factors of H + Gᵀ D⁻¹ G for face R and D (``terms``: :func:`_terms`), from those factored, where the two
        differ by at most UPDATE_RANK terms g gᵀ/d, at most UPDATE_SOLVES of them not met since the factorization;
        else None (and where nothing is factored yet)."""
        if terms is None:
            return None
        kept = self._terms
        added, removed = list(terms.keys() - kept.keys()), list(kept.keys() - terms.keys())
        new = [i for i, key in enumerate(added + removed) if key not in self._solved]
        if len(added) + len(removed) > UPDATE_RANK or len(new) > UPDATE_SOLVES:
            return None
        if not added and not removed:
            return self.factors
        R_kept, _, d_kept = self._factored
        joining, leaving = [terms[key] for key in added], [kept[key] for key in removed]
        U = sp.csr_matrix(sp.hstack([sp.csc_matrix(R)[:, joining], sp.csc_matrix(R_kept)[:, leaving]]).T @ self.G)
        if new:  # M⁻¹uᵀ of the terms not yet met, in one solve with multiple right-hand sides
            self._solved.update(zip([(added + removed)[i] for i in new], self.factors.solve(U[new].T.toarray()).T))
        self._solved = {key: self._solved[key] for key in added + removed}  # at most UPDATE_RANK held
        Z = np.stack(list(self._solved.values()), axis=1)
        return _Updated(self.factors, U, Z, np.concatenate([1.0 / d[joining], -1.0 / d_kept[leaving]]))

    def _near(self, R: sp.csr_matrix, d: np.ndarray):
        """ξ ↦ the inverse of the system factored, on R's face: where R holds the factored face's columns but for at
        most UPDATE_RANK, the kept ones turned by at most ROTATION and their d within a spread of REUSE of the factored
        (REUSE's first case on them), the others joining or leaving as a low-rank update (:meth:`_updated`); else None.
        The free plate 20 : 20 : 1 at 2.6·10⁵ DOFs, Tresca: its fifth face held 8 columns the factored one did not and
        4 fewer, d within 1.63 on the 40,731 both hold; refactorized, 5.4 s, ~43 solves with its factors."""
        R, R_kept, d_kept = sp.csc_matrix(R), sp.csc_matrix(self._factored[0]), self._factored[2]
        here, there = _matched(R, R_kept)
        others = np.setdiff1d(np.arange(R.shape[1]), here)
        if R.shape[1] + R_kept.shape[1] - 2 * here.size > UPDATE_RANK:
            return None
        signs = _face_signs(sp.csr_matrix(R[:, here]), sp.csr_matrix(R_kept[:, there]))
        if signs is None or _ratio_spread(d[here], d_kept[there]) > REUSE:
            return None
        order = np.argsort(np.concatenate([here, others]))  # R's columns' order, the kept ones' in their place
        R_near = sp.csr_matrix(sp.hstack([R_kept[:, there], R[:, others]], format="csc")[:, order])
        d_near = np.concatenate([d_kept[there], d[others]])[order]
        signs = np.concatenate([signs, np.ones(others.size)])[order]
        updated = self._updated(R_near, d_near, _terms(R_near, d_near))
        if updated is None:
            return None
        G = sp.csr_matrix(R_near.T @ self.G)
        return lambda xi: signs * _woodbury(updated, G, d_near, signs * xi)


def _matched(R: sp.csc_matrix, other: sp.csc_matrix) -> tuple[np.ndarray, np.ndarray]:
    """The columns of R and of ``other`` (two faces) that are one variable's or one sphere's tangent coordinate in both:
    those with the same first and last row, paired in their order among such columns."""
    keys = [_rows(face) for face in (R, other)]
    ranks = [group_ranks(key) for key in keys]
    count = 1 + max(rank.max(initial=0) for rank in ranks)
    return np.intersect1d(*(key * count + rank for key, rank in zip(keys, ranks)), assume_unique=True,
                          return_indices=True)[1:]


def _rows(R: sp.csc_matrix) -> np.ndarray:
    """Each column's first row × rows + its last."""
    R.sort_indices()
    return R.indices[R.indptr[:-1]].astype(np.int64) * R.shape[0] + R.indices[R.indptr[1:] - 1]


def _cost(factors, fill: int | None) -> float | None:
    """A numeric refactorization of ``factors`` in products with W: its flops against a solve's with K's factors,
    ``fill`` nonzeros (4 flops each: forward and back); None where either is not known (SuperLU)."""
    flops = getattr(factors, "flops", None)
    return None if fill is None or not flops else flops / (4 * fill)


class _Updated:
    """Solves with M + Uᵀ diag(w) U from M's ``factors`` and Z = M⁻¹Uᵀ (Woodbury): M⁻¹b − Z C⁻¹ U M⁻¹b with
    C = diag(1/w) + U Z, small and dense. w < 0 (terms leaving the face) make C indefinite, not singular:
    M + Uᵀ diag(w) U is a face's SPD matrix."""

    def __init__(self, factors, U: sp.csr_matrix, Z: np.ndarray, weights: np.ndarray):
        self._factors, self._U, self._Z = factors, U, Z
        self._C = scipy.linalg.lu_factor(np.diag(1.0 / weights) + U @ Z)

    def solve(self, b: np.ndarray) -> np.ndarray:
        y = self._factors.solve(b)
        return y - self._Z @ scipy.linalg.lu_solve(self._C, self._U @ y)


def _terms(R: sp.csr_matrix, d: np.ndarray) -> dict:
    """R's columns with their d, each as a key (its rows', entries' and d's bytes, one bytes object: its length
    fixes the column's count of entries) to its index: the rank-one terms g gᵀ/d of the face's Gᵀ D⁻¹ G, compared
    between faces by key (:meth:`_Preconditioner._updated`). The keys of the columns with one count of entries are
    the rows of one byte array: the pair's Coulomb at 1.4·10⁶ DOFs spent 0.6 s of its contact solve on them column by
    column (~2,500 columns a face, three ``tobytes`` each)."""
    R = sp.csc_matrix(R)
    R.sort_indices()
    counts = np.diff(R.indptr)
    keys = np.empty(R.shape[1], dtype=object)
    for count in np.unique(counts):
        columns = np.flatnonzero(counts == count)
        at = R.indptr[columns, None] + np.arange(count)
        record = np.hstack([R.indices[at].view(np.uint8), R.data[at].view(np.uint8), d[columns, None].view(np.uint8)])
        keys[columns] = record.view(f"V{record.shape[1]}").ravel().tolist()
    return dict(zip(keys.tolist(), range(R.shape[1])))


def _face_signs(R: sp.csr_matrix, other: sp.csr_matrix) -> np.ndarray | None:
    """Signs s of R's columns such that R diag(s) is ``other``'s face: the same free variables and spheres, each
    tangent basis turned by at most ROTATION (a basis may come out of :func:`tangent_bases` reversed); None where
    there are none."""
    if not (R.shape == other.shape and R.nnz == other.nnz and np.array_equal(R.indptr, other.indptr)
            and np.array_equal(R.indices, other.indices)):
        return None
    signs = np.where(np.asarray(R.multiply(other).sum(axis=0)).ravel() < 0, -1.0, 1.0)
    return signs if np.abs(R.data * signs[R.indices] - other.data).max(initial=0.0) <= ROTATION else None


def _ratio_spread(d: np.ndarray, kept: np.ndarray) -> float:
    """max(d / kept) / min(d / kept): the condition number of the kept system's inverse times this one's, where the
    two differ only in D (see REUSE)."""
    ratio = d / kept
    return float(ratio.max(initial=1.0) / max(ratio.min(initial=1.0), 1e-300))


def _shifts(approximation, sets: _Bounds, curvature) -> np.ndarray:
    """δ/SHIFT of the preconditioner per variable: the approximation's estimate of P̃_jj with the body clamped near
    its row (``approximation.diagonal``), the short waves' scale; else P's mean eigenvalue (``curvature()``). On a
    strip clamped at its ends W's long waves (beam bending) make the mean eigenvalue 10⁴ times the short waves', a δ
    beyond those leaves the short waves unpreconditioned: Signorini, aspect 400, 2.4·10⁴ DOFs with the whole strip
    as the approximation took 1346 CG iterations with δ = 10⁻³ × the mean eigenvalue, 29 with 10⁻⁷ ×."""
    estimate = getattr(approximation, "diagonal", None)
    if estimate is None:
        return np.full(sets.scale.size, max(curvature(), 1e-300))
    return np.maximum(sets.scale**2 * estimate, 1e-300)


def _woodbury(factors, G: sp.csr_matrix, d, xi: np.ndarray) -> np.ndarray:
    """(D + G H⁻¹ Gᵀ)⁻¹ ξ = D⁻¹(ξ − G (H + Gᵀ D⁻¹ G)⁻¹ Gᵀ D⁻¹ ξ), ``factors`` those of H + Gᵀ D⁻¹ G, D = diag(d)."""
    return (xi - G @ factors.solve(G.T @ (xi / d))) / d


def _scaled(P, scale: np.ndarray):
    """P̃ = diag(scale) P diag(scale) for the dense Newton steps: an array where P is mostly nonzero (a dense W held
    as a sparse matrix: its reduced Hessians were sparse products, 3-D punch at 2.8·10⁵ DOFs), sparse otherwise.
    A dense W (:func:`~convexcontact.conic.dense_matrix`) is read as its values' array, without a copy where the scale
    is 1 (the contact dual's)."""
    if sp.issparse(P) and P.nnz < 0.25 * P.shape[0] ** 2:
        return sp.diags(scale) @ sp.csr_matrix(P) @ sp.diags(scale)
    dense = dense_values(P)
    if dense is not None:
        return dense if (scale == 1).all() else scale[:, None] * dense * scale
    return scale[:, None] * (P.toarray() if sp.issparse(P) else np.asarray(P, dtype=float)) * scale


def _step_lengths(P, sets: _Bounds, c, products: list | None = None):
    """c per variable, 0.1 / P̃_jj (one per ball: its least), where P is a matrix and its diagonal known; for an
    operator whose approximation estimates its diagonal up to a slowly varying factor (``approximation.diagonal``,
    d), 0.1 / (r d̃_j), r the mean of P̃_jj / d̃_j by one random product (Hutchinson's estimate of the trace of
    D̃^-½ P̃ D̃^-½); else, and where that diagonal is 0, the scalar ``c()`` (called only there: a product where P is an
    operator, see ``curvature`` in :func:`newton_cg`). One c for all misjudges the active set where rows differ in
    scale: the dense W of a mortar pair on graded meshes took 29 Newton steps on Signorini with one c, 5 with these, and
    Tresca failed after 100 where it now converges (86: the slip zone still moves a node a step); the same pair's
    Tresca dual applied matrix-free: see ``approximation.diagonal``'s measurements in docs/performance.md."""
    if isinstance(P, spla.LinearOperator):
        estimate = getattr(getattr(P, "approximation", None), "diagonal", None)
        if estimate is None:
            return c()
        diagonal = sets.scale**2 * estimate
        probe = np.random.default_rng(1).standard_normal(diagonal.size) / np.sqrt(np.maximum(diagonal, 1e-300))
        if products is not None:
            products[0] += 1
        ratio = (sets.scale * probe) @ P.matvec(sets.scale * probe) / (probe @ (diagonal * probe))
        diagonal = diagonal * ratio
    else:
        diagonal = sets.scale**2 * np.asarray(P.diagonal()).ravel()
    lengths = np.where(diagonal > 0, 0.1 / np.maximum(diagonal, 1e-300), c() if (diagonal <= 0).any() else 0.0)
    if sets.balls.size:
        lengths[sets.balls] = lengths[sets.balls].min(axis=1, keepdims=True)
    return lengths


def _grown(y: np.ndarray, newton: np.ndarray, sets: _Bounds, radius: np.ndarray) -> np.ndarray | None:
    """y (v − c∇f, whose outside sets :func:`_step` holds under the radii ``radius``, those at v) with the sets it
    leaves free and Newton's point leaves added, at Newton's point (so held on that side, a ball on its sphere
    through it; where radii move, a ball Newton's point leaves under the radii it reaches); None where there are
    none."""
    bounds = sets.bounds[(y[sets.bounds] >= 0) & (newton[sets.bounds] < 0)]
    balls = sets.balls[(np.linalg.norm(y[sets.balls], axis=1) <= radius)
                       & (np.linalg.norm(newton[sets.balls], axis=1) > sets.radii(newton))]
    if not (bounds.size or balls.size):
        return None
    grown = y.copy()
    grown[bounds], grown[balls] = newton[bounds], newton[balls]
    return grown


def _working(v: np.ndarray, sets: _Bounds, epsilon: float) -> np.ndarray:
    """y for :func:`_step` that holds every set within ``epsilon`` of its boundary where v is (a bound at 0, a ball on
    its sphere in v's direction, put just outside it: no tangent curvature) and leaves every other set free (y = v)."""
    y = v.copy()
    y[sets.bounds[v[sets.bounds] <= epsilon]] = -1.0
    radius, ball = sets.radii(v), v[sets.balls]
    norm = np.linalg.norm(ball, axis=1)
    near = (norm >= radius - epsilon) & (norm > 0)
    y[sets.balls[near]] = ball[near] * ((1 + 1e-8) * radius[near] / norm[near])[:, None]
    return y


def _feasible_length(v: np.ndarray, d: np.ndarray, sets: _Bounds, held: np.ndarray) -> float:
    """The largest α ≤ 1 with v + αd in every set that ``held`` (:func:`_working`) leaves free."""
    bounds = sets.bounds[(held[sets.bounds] >= 0) & (d[sets.bounds] < 0)]
    alpha = min(1.0, (v[bounds] / -d[bounds]).min(initial=np.inf))
    radius = sets.radii(v)
    free = np.linalg.norm(held[sets.balls], axis=1) <= radius
    x, e, radius = v[sets.balls[free]], d[sets.balls[free]], radius[free]
    a, b = np.einsum("ij,ij->i", e, e), np.einsum("ij,ij->i", x, e)
    slack = np.maximum(radius**2 - np.einsum("ij,ij->i", x, x), 0.0)  # ‖x + αe‖ = ρ: aα² + 2bα − slack = 0
    moving = a > 0
    a, b, slack = a[moving], b[moving], slack[moving]
    root = np.sqrt(b**2 + a * slack)  # its positive root, without cancellation whatever b's sign
    return min(alpha, np.where(b > 0, slack / np.maximum(b + root, 1e-300), (root - b) / a).min(initial=np.inf))


def _released(y: np.ndarray, newton: np.ndarray, g: np.ndarray, c, sets: _Bounds, released: np.ndarray,
              then: np.ndarray, now: np.ndarray):
    """The face the natural map holds at ``newton``, Newton's point on the face y holds (``g`` = ∇f there; the balls'
    radii ``then`` where y's face was held, ``now`` at Newton's point: the same where radii are fixed): the primal-dual
    active set update (GROW), y' = newton − c g on the sets y holds (c g: their multipliers), newton on the others
    (whose multipliers the Newton system set to 0). It holds the sets the point leaves (as :func:`_grown`), releases
    those whose multiplier points inward, and moves an interval (a ball of one variable) to the end its multiplier
    pushes it to; a set ``released`` before in this step (a mask over the variables, updated here) stays as y holds
    it, and a ball of more variables held in both keeps y's point (its tangent basis: REUSE). (y', whether a set was
    released), or (None, False) where the face is y's."""
    held = np.zeros(y.size, bool)
    held[sets.bounds[y[sets.bounds] < 0]] = True
    on = np.linalg.norm(y[sets.balls], axis=1) > then
    held[sets.balls[on].ravel()] = True
    face = np.where(held, newton - c * g, newton)
    again = np.zeros(y.size, bool)
    again[sets.bounds] = face[sets.bounds] >= 0
    again[sets.balls[np.linalg.norm(face[sets.balls], axis=1) <= now].ravel()] = True
    again &= held & released
    face[again] = y[again]
    bounds_then, bounds_now = y[sets.bounds] < 0, face[sets.bounds] < 0
    on_now = np.linalg.norm(face[sets.balls], axis=1) > now
    kept = sets.balls[on & on_now]
    if sets.balls.shape[1] > 1:
        face[kept] = y[kept]
    bounds_off, balls_off = sets.bounds[bounds_then & ~bounds_now], sets.balls[on & ~on_now]
    released[bounds_off] = released[balls_off.ravel()] = True
    changed = (bounds_off.size or balls_off.size or (bounds_now & ~bounds_then).any() or (on_now & ~on).any()
               or (np.sign(face[kept]) != np.sign(y[kept])).any())
    return (face, bool(bounds_off.size or balls_off.size)) if changed else (None, False)


def _affine(program: ConicProgram):
    """x ↦ P x + q as a sum, and the program's own formula of it (``program.gradient``) or None (the contact dual's
    computes it from the displacement its multipliers leave, K⁻¹(f − Bᵀx), as the answer's fields are recovered:
    P x and q cancel where the loads bend a body its contact holds up, and the sum's rounding ε‖q‖ passed the gaps
    the certificate checks; formulations/dual.py)."""
    P = _operator(program.P)
    return (lambda x: P.matvec(x) + program.q), program.gradient


def _operator(P) -> spla.LinearOperator:
    """x ↦ P x: numpy's product where P is a dense W (:func:`~convexcontact.conic.dense_matrix`; scipy's took 2.6 times
    as long on a W of 3,900², one thread), else P's own."""
    dense = dense_values(P)
    return spla.aslinearoperator(P if dense is None else dense)


def _natural(v, g, c, sets: _Bounds, q):
    """The natural residual ‖v − Π(v − c∇f)‖∞ relative to the answer's scale, v − c∇f and that scale
    (Π onto the sets at v, where radii move)."""
    y = v - c * g
    size = max(np.abs(v).max(initial=0.0), (c * np.abs(sets.scale * q)).max(initial=0.0), 1e-300)
    return np.abs(v - _project(y, sets, sets.radii(v))).max(initial=0.0) / size, y, size


def _project(y: np.ndarray, sets: _Bounds, radius: np.ndarray | None = None) -> np.ndarray:
    """Π onto v_bounds ≥ 0 and ‖v_ball‖ ≤ ρ (other variables are free); ρ = ``radius``, or where radii move
    the radii at y's projected bounds (then the point is in its own sets)."""
    v = y.copy()
    v[sets.bounds] = np.maximum(y[sets.bounds], 0.0)
    radius = sets.radii(v) if radius is None else radius
    ball = y[sets.balls]
    norm = np.linalg.norm(ball, axis=1)
    outside = norm > radius
    if outside.any():
        v[sets.balls[outside]] = radius[outside, None] * unit_rows(ball[outside])
    return v


def _fresh_enough(drift: float, limit: float) -> bool:
    """Whether a ∇f that is updates of one by P's own formula (``drift``: c ⊙ what they added, ∞-norm; ∞ where it is no
    such sum) serves as a fresh one to ``limit``: their rounding is at most SUM_FLOOR × ε of what they added (as the
    sum's, SUM_FLOOR). At the stopping test (limit: a tenth of the tolerance) a fresh ∇f then checks nothing the
    updates' rounding could hide; at a Newton step's start (limit: its target) it starts from them (``loose`` in
    :func:`newton_cg`, :func:`_start_gradient`). Measured (docs/performance.md, "The pair's Signorini products"): on
    the pair at 1.4·10⁶ DOFs, Signorini, the last step moved c∇f by 3e-7 of the answer's scale and the natural residual
    by the updates was 1.8e-15 where a fresh ∇f gave 1.6e-15 (tol 1e-12), and its second step began one CG update
    away from a fresh ∇f: 26 → 24 fine products; one or two less, the same Newton steps and certificates, on the 2-D
    pair at 2·10⁴ DOFs forced matrix-free (Signorini 46 → 45, Tresca 40 → 38), on the strips and the 3-D free plate
    at 3·10⁴–10⁵ DOFs, the clamped strip 20 : 1 at 10⁵ 15 → 14. Where the first step's updates from far away stand
    for ∇f (that strip's: c∇f moved by ~‖c q‖ = 10³ ‖v‖) the bound is above any target near the answer, and the next
    step starts from a fresh ∇f (tests/test_products.py)."""
    return SUM_FLOOR * EPS * drift <= limit


def _start_gradient(point, known, affine, sets: _Bounds, products) -> np.ndarray:
    """∇f at a Newton step's start ``point`` (v with the face's held sets at their bounds): that of ``known`` = (a
    point, ∇f there) without a product where the two points are the same (v already on the face: the step after one
    that took Newton's point on a face that stayed, a grown face that only released sets), else one product. Where P
    has its own formula of ∇f (:func:`_affine`), a sum of CG's updates serves for it only while the step's target is
    above the sum's rounding, SUM_FLOOR × ε ‖c q‖∞ (``loose`` in :func:`newton_cg`): the updates' rounding,
    ε‖P̃‖‖w − v‖ each, held the second step of the clamped strip 20 : 1 (10⁵ DOFs, Tresca) at 2e-13 where a fresh ∇f
    took it from 4e-10 to 3e-17 (3 Newton steps and 18 products against 2 and 15). The pair at 1.4·10⁶ DOFs, Signorini:
    62 → 59 products, the same 3 Newton steps and 30 CG iterations (docs/performance.md, "The pair's products that are
    not CG iterations")."""
    if known is not None and np.array_equal(point, known[0]):
        return known[1].copy()  # CG's updates follow it in place (_step)
    products[0] += 1
    return sets.scale * affine(sets.shift + sets.scale * point)


def _step(P, affine, sets: _Bounds, v, y, c, target, products, precondition, matrix=None, relative=0.0, face=None,
          grown=False, gradient_at=None, level=None):
    """The Newton step from v (y = v − c∇f; ``affine``: x ↦ P x + q, see :func:`_affine`): the new v, the CG
    (GMRES, where radii move) iterations it took and ∇f at the new v where CG's products give it (else None), CG
    stopping at ``target`` or ``relative`` × its first residual (GROWN_FORCING); where P is a matrix (``matrix()`` = P̃)
    and the system has at most DIRECT_LIMIT unknowns, a dense Cholesky (LU where that fails or radii move) instead, or
    the factor kept in ``face`` (:func:`_direct`). ``grown``: the face is a grown one of the step's (:func:`_grown`),
    whose preconditioner may be the step's factors (REUSE, KEPT_FORCING). ``gradient_at``: (a point, ∇f there), ∇f at
    the step's start where that is the point (:func:`_start_gradient`). ``level``: [0] is set, where it is 0, to the
    residual CG stops at on a kept system (KEPT_FORCING)."""
    n = v.size
    held = np.zeros(n, bool)
    new = np.zeros(n)
    held[sets.bounds[y[sets.bounds] < 0]] = True  # held at 0
    radius = sets.radii(v)
    ball = y[sets.balls]
    norm = np.linalg.norm(ball, axis=1)
    # a ball whose radius is below the rounding of its point's norm is held at Π(y) (its centre where ρ = 0): its
    # tangent curvature (‖y‖ − ρ)/(cρ) would pass 1/(c·eps), and overflowed at a slip bound of 5e-324 (fuzz suite)
    point = np.flatnonzero(radius <= EPS * norm)
    sphere = np.flatnonzero((norm > radius) & (radius > EPS * norm))
    held[sets.balls[point].ravel()] = True
    held[sets.balls[sphere].ravel()] = True
    if point.size:
        new[sets.balls[point]] = radius[point, None] * unit_rows(ball[point])
    free = np.flatnonzero(~held)
    rho = radius[sphere]
    p = sets.balls.shape[1]
    bases = np.zeros((0, p, max(p - 1, 0)))
    if sphere.size:
        new[sets.balls[sphere]] = rho[:, None] * unit_rows(ball[sphere])
        bases = tangent_bases(ball[sphere])
    k, _, t = bases.shape
    c_sphere = c[sets.balls[sphere, 0]] if np.ndim(c) and sets.balls.shape[1] else np.max(c)
    curvature = np.repeat((norm[sphere] - rho) / (c_sphere * rho), t)
    # v = new + Z ξ: ξ holds the free variables, then t tangent coordinates per sphere (see _expansion)
    sphere_vars = sets.balls[sphere]
    moving = None if sets.coupling is None else sets.coupling[sphere]
    if moving is not None:  # the sphere's radius at the new point: ρ(new + Z ξ), linear in the free variables
        directions = unit_rows(ball[sphere])
        new[sphere_vars] = (moving @ new + sets.radius[sphere])[:, None] * directions

    Z = _expansion(n, free, sphere_vars, bases, None if moving is None else (directions, moving))
    R = Z if moving is None else _expansion(n, free, sphere_vars, bases)  # rows kept: Rᵀ, not Zᵀ, where radii move

    last = [None, None, np.zeros(free.size + k * t)]  # CG's last direction, P̃ Z times it, its last iterate

    # GMRES's products: each ξ and P̃ Z ξ (GMRES_LIFT), at most a restart's: beyond, their memory (two vectors each)
    # and the least squares (n k² flops) outgrow the one product they save
    taken = [] if moving is not None and GMRES_LIFT else None

    def hessian(xi):  # Rᵀ P̃ Z ξ + curvature on the tangent coordinates
        nonlocal taken
        products[0] += 1
        last[0], last[1] = xi.copy(), sets.scale * P.matvec(sets.scale * (Z @ xi))  # CG scales xi in place after
        if taken is not None:
            taken = taken + [(last[0], last[1])] if len(taken) < GMRES_RESTART else None
        return R.T @ last[1] + np.concatenate([np.zeros(free.size), curvature * xi[free.size:]])

    size = free.size + k * t
    # the system for the step from ξ at v, whose right-hand side is the residual there: one product with P where
    # the right-hand side and the Krylov method's first residual took two
    start = R.T @ (v - new)
    gradient = _start_gradient(new + Z @ start, gradient_at, affine, sets, products)
    rhs = -(R.T @ gradient)
    rhs[free.size:] -= curvature * start[free.size:]
    count, at_point = [0], None if size else gradient  # ∇f at the point, where known without a product
    direct = size and matrix is not None and size <= DIRECT_LIMIT
    if direct:
        system = functools.partial(_system, matrix, Z, R, free.size, curvature)
        with blas.limited(DENSE_THREADS):
            xi = _direct(system, free, rhs, moving is None, face if k * t == 0 else None)
        direct = xi is not None
        if direct:
            new = new + Z @ (start + xi)
    if size and not direct:
        H = spla.LinearOperator((size, size), matvec=hessian, dtype=float)
        M = None if precondition is None else spla.LinearOperator(
            (size, size), matvec=precondition.system(R, np.concatenate([np.zeros(free.size), curvature]),
                                                     grown=grown), dtype=float)
        callback = lambda *_: count.__setitem__(0, count[0] + 1)
        if moving is None:
            def follow(x):  # ∇f follows CG's iterate: P̃ Z (x − its last) = α P̃ Z p, CG's own product (GROW); scipy's
                # CG multiplies each direction p once, then steps x by α p and calls back (tests/test_pair_plateau.py)
                callback()
                p, Pp, before = last
                gradient[:] += ((x - before) @ p / (p @ p)) * Pp
                last[2] = x.copy()

            if getattr(precondition, "kept", False):
                relative = min(relative, KEPT_FORCING)
                if level is not None and not level[0]:
                    level[0] = relative * np.linalg.norm(rhs)
            xi, _ = spla.cg(H, rhs, rtol=relative, atol=target, maxiter=CG_LIMIT, M=M, callback=follow)
            at_point = gradient
            if precondition is not None:
                precondition.spent(count[0])
        else:
            xi, _ = spla.gmres(H, rhs, rtol=0.0, atol=target, restart=GMRES_RESTART,
                               maxiter=GMRES_CYCLES, M=M, callback=callback, callback_type="pr_norm")
            moved = None if taken is None else _combined(taken, xi)  # P̃ Z ξ (GMRES_LIFT)
            at_point = None if moved is None else gradient + moved
        new = new + Z @ (start + xi)
    return new, count[0], at_point


DENSE_THREADS = 1
"""BLAS threads for a dense Newton system (:func:`_direct`: its gather and its factorization, a few hundred to
DIRECT_LIMIT unknowns): too small for a second thread to pay its start. The 2-D pair at 10⁵ DOFs, quiet, the Newton
solve on OpenBLAS's default 2 threads against 1 (the whole process): Tresca 0.69–0.74 s against 0.21–0.28 s, Coulomb
0.75–0.83 s against 0.48–0.49 s; loaded, one 530 × 530 LU 0.11 s against 5 ms. The rest (S's Cholesky, W) keeps
every thread (docs/performance.md, "The dense Newton systems on one BLAS thread")."""


def _direct(system, free, rhs, symmetric: bool, face: dict | None):
    """ξ of the dense Newton system ``system()`` ξ = ``rhs``, or None where it is singular: Cholesky where it is
    ``symmetric`` and positive definite, else LU. ``face`` (None where the system has tangent coordinates) keeps the
    Cholesky factor of a Newton step's first system; a later face of the step that only holds more variables
    (bounds and intervals, none released: GROW) has a principal submatrix of that one as its system, solved from the
    kept factor (:func:`_on_face`) while that costs less than a factorization of its own."""
    if symmetric and face and _cheaper_on_face(face["free"], free):
        xi = _on_face(face["factor"], np.isin(face["free"], free), rhs)
        if xi is not None:
            return xi
    with warnings.catch_warnings():  # a beam's bending: rcond 1e-16 on a clamped 20 : 1 strip's face.
        # The point is a trial that the residual and decrease rules accept or not, the answer is
        # certified from the displacement, and a warning per step says nothing the certificate does not
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        if symmetric:
            try:  # H.T: H's own memory in Fortran order (H is symmetric), factored in place
                factor = scipy.linalg.cho_factor(system().T, overwrite_a=True, check_finite=False)
                if face is not None:
                    face.update(free=free, factor=factor)
                return scipy.linalg.cho_solve(factor, rhs, check_finite=False)
            except np.linalg.LinAlgError:  # rounding left H indefinite: LU next
                pass
        try:
            return scipy.linalg.solve(system(), rhs, assume_a="gen", overwrite_a=True, check_finite=False)
        except np.linalg.LinAlgError:  # H = 0: Krylov instead
            return None


def _system(matrix, Z, R, free: int, curvature) -> np.ndarray:
    """The dense Newton system Rᵀ P̃ Z + curvature (on the tangent coordinates, after the ``free`` variables),
    with a relative 1e-14 on its diagonal: W is singular where a multiplier's DOFs are all held (a 3-D punch's
    symmetry planes); such a variable then stays where it is."""
    H = _reduced(matrix(), Z, R)
    H[free:, free:] += np.diag(curvature)
    H[np.diag_indices(H.shape[0])] += 1e-14 * max(H.max(initial=0.0), -H.min(initial=0.0))  # no |H| copy
    return H


def _reduced(tilde, Z: sp.csr_matrix, R: sp.csr_matrix) -> np.ndarray:
    """Rᵀ P̃ Z as a dense array, from the block of P̃ on the rows Z touches (one gather; where Z only picks variables,
    that block itself). Through sparse products with all of P̃ (scipy copied it in and out of Fortran order) this took
    1.0 s of the 1.8 s of newton-cg on the pair's dense Tresca dual (1434 unknowns, 91 systems)."""
    rows = np.flatnonzero(np.diff(Z.indptr))
    block = tilde[np.ix_(rows, rows)] if isinstance(tilde, np.ndarray) else tilde[rows][:, rows].toarray()
    if R is Z and Z.nnz == Z.shape[1] == rows.size and (Z.data == 1).all() and (Z.indices == np.arange(rows.size)).all():
        return block  # Z picks the variables ``rows``, in order
    Z, R = Z[rows], R[rows]
    left = Z.T @ block
    del block  # each m² temporary freed once used: two at a time, not three (Coulomb's dense Newton systems)
    left = np.ascontiguousarray(left.T)
    return np.ascontiguousarray(R.T @ left)


REFACTOR = 1 / 3
"""A grown face is solved from its step's first factor (:func:`_on_face`, ~n² k flops for k variables held more on n)
while n² k < REFACTOR × n'³ (n' = n − k), the flops of a Cholesky of its own."""


def _cheaper_on_face(factored: np.ndarray, free: np.ndarray) -> bool:
    """Whether the system on the variables ``free`` is a principal submatrix of the one factored on ``factored``
    (both sorted) that its factor solves in fewer flops than a factorization (REFACTOR)."""
    held = factored.size - free.size
    return held >= 0 and np.isin(free, factored).all() and factored.size**2 * held < REFACTOR * free.size**3


def _on_face(factor, keep: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
    """x solving H[keep, keep] x = ``rhs`` from the Cholesky ``factor`` of H (scipy's cho_factor, upper: H = UᵀU):
    H x̃ = b̃ + E μ with x̃_E = 0 on the variables E held more, μ from the k × k system (XᵀX) μ = −Xᵀ z, X = U⁻ᵀE,
    z = U⁻ᵀ b̃ (a Schur complement of H⁻¹ on E). By hand: scipy has Cholesky updates for neither deleted rows nor
    columns (only QR's ``qr_delete``), and a rank-k downdate would change the factor this keeps for the next grown
    face. None where XᵀX is numerically singular (a fresh factorization then)."""
    U, lower = factor
    held = np.flatnonzero(~keep)
    b = np.zeros(keep.size)
    b[keep] = rhs
    z = scipy.linalg.solve_triangular(U, b, trans="T", lower=lower, check_finite=False)
    if not held.size:
        return scipy.linalg.solve_triangular(U, z, lower=lower, check_finite=False)
    E = np.zeros((keep.size, held.size))
    E[held, np.arange(held.size)] = 1.0
    X = scipy.linalg.solve_triangular(U, E, trans="T", lower=lower, check_finite=False)
    try:
        mu = -scipy.linalg.cho_solve(scipy.linalg.cho_factor(X.T @ X, check_finite=False), X.T @ z, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    return scipy.linalg.solve_triangular(U, z + X @ mu, lower=lower, check_finite=False)[keep]


def _expansion(n: int, free, sphere_vars, bases, coupling=None) -> sp.csr_matrix:
    """Z (n × unknowns) of v = new + Z ξ: the free variables, t tangent coordinates per sphere, and where radii
    move (``coupling`` = (directions, rows of the coupling)) each sphere's radial motion with the free variables."""
    k, p, t = bases.shape
    rows = [free, np.repeat(sphere_vars.ravel(), t)]
    columns = [np.arange(free.size), np.broadcast_to(free.size + np.arange(k * t).reshape(k, 1, t), (k, p, t)).ravel()]
    values = [np.ones(free.size), bases.ravel()]
    if coupling is not None:
        directions, moving = coupling
        radial = sp.coo_matrix(sp.csr_matrix(moving)[:, free])
        for j in range(p):
            rows.append(sphere_vars[radial.row, j])
            columns.append(radial.col)
            values.append(directions[radial.row, j] * radial.data)
    return sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(columns))),
                         shape=(n, free.size + k * t))
