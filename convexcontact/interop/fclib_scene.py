"""A Coulomb scene of ours as an FClib problem, and our certified answer as its ``/solution``.

Our condensed dual (:mod:`convexcontact.formulations.dual`) *is* FClib's local problem. Ours, in
scaled units: r = (λ_N, λ_T) with all m normal multipliers first, then λ_T component-major
(all first tangential components, then, in 3-D, all second ones), B = [C N; −R], c the offsets,

    min ½ rᵀ W r − hᵀ r,  W = B K⁻¹ Bᵀ,  h = B K⁻¹ f + c,   y = h − W r,
    y_N ≤ 0 (weighted gap, admissible), y_T = −(weighted slip),  ‖λ_T,k‖ ≤ s_k = F_k λ_N,k.

FClib: u = W r + q, r ∈ C_μ, û ∈ C*_μ, û ⊥ r, per contact [N, T1(, T2)]. The mapping, with Π the
permutation from our order to FClib's (contact k's unknowns k, m + k(, 2m + k) become 3k, 3k+1, 3k+2):

    r_FClib = Π r,   W_FClib = Π W Πᵀ,   q_FClib = −Π h  (= Π times our program's linear cost),
    u_FClib = −Π y  (u_N = −y_N ≥ 0 the weighted gap, u_T = the weighted slip),   μ = F at the nodes.

No sign changes r: both minimize ½rᵀWr + qᵀr over the same cones for every slip bound, so their
Tresca programs, hence their Picard maps and Coulomb solutions, are the same. The global problem
(M v = H r + f, u = Hᵀ v + w) is the same with v = u (free DOFs): M = K, f = f, H = −(Π B)ᵀ,
w = −Π c; then Hᵀ M⁻¹ H = W_FClib and Hᵀ M⁻¹ f + w = q_FClib.

The law must be FClib's: local Coulomb at the contact nodes (quadrature "nodal", no smoothing, no
ε, no normal compliance). A prescribed obstacle force (and, in 2-D, tangential force) is an equality
a_jᵀ r = P_j of our dual: FClib's mixed local problem Vᵀ r + R λ + s = 0, û = W r + V λ + q + …,
with V = Π a_j, R = 0, s = −P_j and λ = our multipliers = minus the obstacle's advance (and shift),
scaled; the global problem has no place for the obstacle's motion and is refused then. Contacts whose
displacement is all prescribed carry nothing (zero rows of W) and are left out. Values are in our
scaled units; the factors back to the user's are written in the problem's ``info``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..drivers.prepared import Model, field_at_points, prepare
from ..results.result import ContactResult
from ..scene.description import Coulomb, Scene, SceneError, compliance_of
from .fclib import GlobalProblem, LocalProblem, Solution, write


def check_law(law) -> None:
    """Refuse, naming the field and a fix in the scene file's terms, a law that is not FClib's local Coulomb law
    (judged on the scene, before any assembly: ``prepare`` would send the user elsewhere, e.g. to a formulation
    export does not take)."""
    checks = [
        (isinstance(law, Coulomb), "contact.law", "FClib stores Coulomb problems (W, q, μ)", "use law = 'coulomb'"),
        (compliance_of(law) is None, "contact.stiffness",
         "FClib's law is non-penetration, not normal compliance",
         "remove stiffness (and exponent) from [contact] (cc.Coulomb(compliance=None) in Python)"),
        (getattr(law, "quadrature", "nodal") == "nodal", "contact.quadrature",
         "FClib's contacts carry the friction law themselves", "use quadrature = 'nodal'"),
        (getattr(law, "smoothing_radius", 0.0) == 0, "contact.smoothing_radius",
         "the nonlocal law is not FClib's local Coulomb law", "use smoothing_radius = 0"),
        (getattr(law, "regularization", None) is None, "contact.regularization", "FClib's law is exact",
         "remove regularization from [contact]"),
    ]
    for ok, name, why, fix in checks:
        if not ok:
            raise SceneError(name, f"cannot be exported to FClib: {why}", fix)


def check_exportable(model: Model) -> None:
    """Refuse, naming the field, a model whose problem is not FClib's local Coulomb problem."""
    check_law(model.law)
    checks = [
        (model.formulation == "dual", "formulation", "the FClib problem is the condensed dual",
         "prepare the scene with formulation='dual'"),
        (model.friction is None or model.friction.count == model.fem.contact.m, "contact.law",
         "each FClib contact carries friction", "give every contact Coulomb's law (friction = 0 where frictionless)"),
    ]
    for ok, name, why, fix in checks:
        if not ok:
            raise SceneError(name, f"cannot be exported to FClib: {why}", fix)


def ordering(model: Model) -> np.ndarray:
    """Π as an index array: FClib's unknown i is our unknown order[i] (carrying contacts only)."""
    m, d = model.fem.contact.m, model.fem.dim
    carries = per_node(model.program.P.diagonal()[: m * d] > 0, m, d).any(axis=1)
    kept = np.flatnonzero(carries)
    return (kept[:, None] + m * np.arange(d)[None, :]).ravel()


def per_node(values: np.ndarray, m: int, d: int) -> np.ndarray:
    """Our stacked (normal, tangential components) vector as an (m, d) array."""
    return values.reshape(d, m).T


def info(model: Model, kind: str) -> dict:
    scaling = model.fem.scaling
    return {
        "title": f"convexcontact {model.fem.scene.name} ({kind})",
        "description": (f"convexcontact scene {model.fem.scene.name!r}, {model.fem.dim}-D, Coulomb friction at "
                        f"{model.fem.contact.m} contact nodes; the condensed dual of the mixed multiplier method. "
                        f"Scaled units: r [pressure] x {scaling.pressure:.17g}, displacements x "
                        f"{scaling.displacement:.17g}, lengths x {scaling.length:.17g}."),
        "math_info": "W = B K^-1 B^T symmetric positive semi-definite; existence holds, uniqueness for small mu",
    }


def equalities(model: Model) -> int:
    """How many force equalities open our dual program (the obstacle's normal, [tangential] force)."""
    contact = model.fem.contact
    return (contact.obstacle_coupling is not None) + (contact.tangential_coupling is not None)


def local_problem(model: Model) -> tuple[LocalProblem, np.ndarray]:
    """FC(W, q, μ) of ``model`` — with V, R = 0, s for prescribed obstacle forces — and Π (:func:`ordering`)."""
    check_exportable(model)
    order = ordering(model)
    d, program, p = model.fem.dim, model.program, equalities(model)
    mu = field_at_points(model.law.friction, "contact.friction", model.fem, model.friction)
    W = program.P.tocsr()[order][:, order]
    mixed = {}
    if p:  # our rows a_jᵀ r = P_j are FClib's Vᵀ r + R λ + s = 0 with V = [a_j], R = 0, s = −P
        mixed = {"V": sp.csr_matrix(program.A.tocsr()[:p][:, order].T), "R": sp.csr_matrix((p, p)),
                 "s": -program.b[:p]}
    problem = LocalProblem(sp.csr_matrix(W), program.q[order], mu[order[::d]], d, info(model, "local"), **mixed)
    return problem, order


def global_problem(model: Model) -> tuple[GlobalProblem, np.ndarray]:
    """FClib's global problem of ``model`` (M = K, H = −(Π B)ᵀ, f, w = −Π c) and Π."""
    if equalities(model):
        raise SceneError("obstacle.force", "cannot be exported as FClib's global problem: the obstacle's motion is "
                         "an unknown beside the displacements (the local problem holds it as V, R, s)",
                         "export the local problem, or prescribe the obstacle's depth")
    local, order = local_problem(model)
    fem, C, friction = model.fem, model.C, model.friction
    contact = fem.contact
    B = sp.vstack([C @ contact.N, -friction.R]).tocsr()
    c = np.concatenate([C @ (contact.normal_offset - contact.gap), -friction.offset])
    H = -sp.csr_matrix(B[order].T)
    return GlobalProblem(sp.csr_matrix(fem.K), H, fem.f.copy(), -c[order], local.mu, local.spacedim,
                         info(model, "global")), order


def multipliers(model: Model, result: ContactResult) -> np.ndarray:
    """Our r = (λ_N, λ_T component-major), scaled units, from a solved result."""
    pressure = model.fem.scaling.pressure
    friction = np.atleast_2d(np.asarray(result.contact.friction).T)  # (d − 1, m)
    return np.concatenate([result.contact.pressure, friction.ravel()]) / pressure


def solution(model: Model, result: ContactResult, problem, order: np.ndarray) -> Solution:
    """Our certified answer in FClib's terms: r = Π r_ours, u = W r + q (local) or Hᵀ v + w with v = u."""
    r = multipliers(model, result)[order]
    if isinstance(problem, LocalProblem):
        if problem.V is None:
            return Solution(r=r, u=problem.W @ r + problem.q)
        # our dual's equality multipliers are minus the obstacle's advance and shift (formulations/dual.py)
        contact = model.fem.contact
        motion = ([result.obstacle_advance] if contact.obstacle_coupling is not None else []) + \
            ([result.obstacle_shift] if contact.tangential_coupling is not None else [])
        l = -np.array(motion, dtype=float) / model.fem.scaling.displacement
        return Solution(r=r, u=problem.W @ r + problem.V @ l + problem.q, l=l)
    v = result.displacement[model.fem.free] / model.fem.scaling.displacement
    return Solution(r=r, u=problem.H.T @ v + problem.w, v=v)


def export(scene: Scene, path, kind: str = "local", solver: str = "clarabel", **options):
    """Write ``scene`` as an FClib ``kind`` ("local" or "global") problem to ``path``, with our certified
    Coulomb answer as ``/solution`` when the solve succeeds. Returns (problem, solution or None, result)."""
    if kind not in ("local", "global"):
        raise ValueError(f"kind: {kind!r}; use 'local' (W, q, μ) or 'global' (M, H, f, w, μ)")
    check_law(scene.contact.law)
    if scene.history is not None:
        raise SceneError("history", "cannot be exported to FClib: a file holds one static problem",
                         "export one step: remove the [history] table and put that step's values in the scene")
    model = prepare(scene, "dual")
    problem, order = (local_problem if kind == "local" else global_problem)(model)
    result = model.solve(solver, **options)
    answer = solution(model, result, problem, order) if result.solved else None
    write(path, problem, answer)
    return problem, answer, result
