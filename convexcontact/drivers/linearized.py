"""The answer of a certified result at its active set: its fields in scaled units, the operators of its law, and
the derivative system of :mod:`.active_set` built there (docs/sensitivity.md).

The statuses are read off the certificate's quantities, each over its scale; a force-controlled obstacle's
advance and shift are appended to u as unknowns without stiffness; from 2·10⁴ DOFs the system is condensed onto the
DOFs the contact rows touch (K's Schur complement there, as the dual's W)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp

from ..fem.assembly import FEModel
from ..fem.factorization import Condensation, condense
from ..fem.friction import FrictionPoints, friction_points
from ..fem.mortar import PairTrace
from ..formulations import contact_weights
from ..results.result import ContactResult, held
from ..scene.bodies import Pairs
from ..scene.description import (
    Coulomb,
    Material,
    NormalCompliance,
    Scene,
    SceneError,
    Signorini,
    Tresca,
    compliance_of,
    has_friction,
    of_type,
)
from .active_set import (
    Linearization,
    Rates,
    friction_status,
    linearize,
    normal_status,
)
from .picard import pressure_map
from .prepared import CERTIFIED, field_at_points, frictional_rows
from .rules import contact_columns

STRICT = 1e-8
"""A contact row or friction point is strictly on one side of its law where the quantity of that side (gap,
pressure; slip, room below the bound) exceeds this fraction of its scale, or 100 × the certificate's worst
residual if larger; where neither does, it is degenerate and the derivative one-sided there."""


@dataclass
class Point:
    """The answer in scaled units with the operators of its law, and its active set (:class:`Linearization`)."""

    result: ContactResult
    C: sp.spmatrix
    friction: FrictionPoints | None
    u: np.ndarray  # free DOFs, then the force-controlled obstacle's motions
    pressure: np.ndarray
    unit_bound: sp.csr_matrix | None  # Coulomb: ds/dF (F constant) as a map of λ_N
    linear: Linearization
    margin: float
    obstacle: int = 0  # the force-controlled obstacle's unknowns after u (advance, then shift): 0, 1 or 2
    condensation: Condensation | None = None  # K condensed onto the contact DOFs: the system is over those

    @property
    def fem(self) -> FEModel:
        return self.result.fem


def check_result(result, in_history: bool = False) -> ContactResult:
    """The result if its answer can be differentiated here, else an error naming what to change (``in_history``:
    a step of a history, differentiated with the steps before it)."""
    of_type(result, ContactResult, "result", "give the ContactResult of cc.solve(scene)")
    if not result.solved or result.status != "solved":
        raise ValueError(f"result: status {result.status!r}{', ' + result.message if result.message else ''}: only a "
                         "solved and certified answer has a derivative — solve it again more tightly (tol) or with "
                         "another solver")
    if not result.certificate.passes(CERTIFIED):
        raise ValueError(f"result: certificate {result.certificate.worst:.1e} > {CERTIFIED:g}: not an answer of the "
                         "discrete problem, so not one to differentiate — solve more tightly")
    scene, law = result.scene, result.scene.contact.law
    if scene.history is not None and not in_history:
        raise SceneError("result", "a step of a load history: its derivative depends on the earlier steps",
                         "give the whole HistoryResult to cc.sensitivity")
    if isinstance(scene.contact, Pairs):
        raise SceneError("result", "several contacts in one scene: not implemented",
                         "differentiate one pair of bodies, or a body on one rigid obstacle")
    if not isinstance(law, (Signorini, NormalCompliance, Tresca, Coulomb)):
        raise SceneError("contact.law", f"{type(law).__name__}: sensitivities are implemented for Signorini, normal "
                         "compliance, Tresca and Coulomb", "use one of these laws")
    if law.non_penetration == "gauss" or getattr(law, "quadrature", "nodal") == "gauss":
        raise SceneError("contact.non_penetration", "contact or friction at Gauss points: their multipliers need not "
                         "be unique, so neither are their derivatives", "use non_penetration and quadrature 'nodal'")
    if has_viscosity(scene):
        raise SceneError("materials", "a viscous material: not implemented", "differentiate an elastic body")
    return result


def has_viscosity(scene: Scene) -> bool:
    materials = [scene.materials] if isinstance(scene.materials, Material) else list(scene.materials.values())
    return any(m.viscosity for m in materials)


def point_of(result: ContactResult) -> Point:
    """The answer of ``result`` in scaled units, its law's operators and its active set."""
    fem, law = result.fem, result.scene.contact.law
    scaling, contact = fem.scaling, fem.contact
    C = contact_weights(contact, law.non_penetration)
    friction = None
    if has_friction(law):
        if frictional_rows(law, contact) is not None:
            raise SceneError("contact.friction", "friction laws per contact pair: not implemented", "use one law")
        friction = friction_points(contact, fem.mesh, fem.basis, law.quadrature, law.non_penetration)
    K, A, R, obstacle = with_obstacle(result, C, friction)
    u = np.concatenate([result.displacement[fem.free] / scaling.displacement, obstacle])
    pressure = result.contact.pressure / scaling.pressure
    u_ref, p_ref = max(np.abs(u).max(initial=0.0), 1.0), max(np.abs(pressure).max(initial=0.0), 1.0)
    tol = max(STRICT, 100 * result.certificate.worst)
    gap = (weighted_gap(contact, C) - A @ u) / contact.row_weights(C) / u_ref
    normal = normal_status(gap, pressure / p_ref, held(A), tol)
    unit, arguments = None, {}
    if compliance_of(law) is not None:
        normal, arguments["flexibility"] = compliant(normal, gap * u_ref, contact.row_weights(C),
                                                     result_compliance(fem, law))
    strict = [np.where(normal == "closed", pressure / p_ref, np.where(normal == "open", gap, np.inf))]
    if friction is not None:
        unit, state, room = friction_state(result, friction, R @ u + friction.offset, normal, (u_ref, p_ref), tol)
        arguments.update(state, R=R)
        strict.append(room)
    condensation, kept = condensed(fem, obstacle.size, result.condensation)
    if condensation is not None:  # the derivative system on the contact DOFs, K replaced by its Schur complement
        K = sp.block_diag([sp.csr_matrix(condensation.S), sp.csr_matrix((obstacle.size,) * 2)], format="csr")
        A = A[:, kept]
        if friction is not None:
            arguments["R"] = arguments["R"][:, kept]
    linear = linearize(K, A, normal, **arguments)
    margin = float(np.concatenate(strict).min(initial=np.inf))
    return Point(result, C, friction, u, pressure, unit, linear, margin, obstacle.size, condensation)


CONDENSED = 3000
"""Most contact DOFs onto which the derivative system is condensed (a dense Schur complement of K, as the dual's
W): beyond, the sparse system over every DOF is factorized instead (SuperLU)..."""


CONDENSED_DOFS = 20000
"""... and the fewest free DOFs: below, SuperLU on the whole system was faster (10⁴ DOFs, 101 contact nodes:
0.18 s against 0.56 s for PARDISO's Schur complement; 4·10⁴ DOFs, 201 nodes: 1.10 s against 0.78 s)."""


def condensed(fem: FEModel, extra: int, solved: Condensation | None = None) -> tuple[Condensation | None,
                                                                                    np.ndarray | None]:
    """K condensed onto the DOFs the contact rows touch, and the columns of the augmented unknowns (u, obstacle)
    kept: those DOFs, then the obstacle's; (None, None) where condensing gains nothing. ``solved``: the condensation
    the solve built (the dual's), taken as it is whatever the size: no factorization of K at all; else one sparse
    factorization (PARDISO's Schur complement where it loads)."""
    columns = contact_columns(fem)
    if solved is not None and np.array_equal(solved.C, columns):
        condensation = solved
    elif fem.n_free < CONDENSED_DOFS or not 0 < columns.size <= min(CONDENSED, fem.n_free // 2):
        return None, None
    else:
        condensation = condense(fem.K, columns, dim=fem.dim)
    return condensation, np.concatenate([columns, fem.n_free + np.arange(extra)])


def reduced(point: Point, rates: list[Rates]) -> list[Rates]:
    """The rates of the condensed system: each force condensed onto the contact DOFs (f_C − K_CI K_II⁻¹ f_I), all
    in one pass through the factors."""
    if point.condensation is None or not rates:
        return rates
    n = point.fem.n_free
    loads = point.condensation.load(np.column_stack([rate.force[:n] for rate in rates])).reshape(-1, len(rates))
    return [Rates(np.concatenate([load, rate.force[n:]]), rate.gap, rate.offset, rate.bound)
            for load, rate in zip(loads.T, rates)]


def expanded(point: Point, x: np.ndarray, force: np.ndarray) -> np.ndarray:
    """The solution over every DOF from the condensed one: du_I = K_II⁻¹(f_I − K_IC du_C) for the force rate
    ``force`` it was solved for."""
    if point.condensation is None:
        return x
    n, kept = point.fem.n_free, point.condensation.C.size
    return np.concatenate([point.condensation.lift(x[:kept], force[:n]), x[kept:]])


def friction_state(result: ContactResult, friction: FrictionPoints, weighted: np.ndarray, normal: np.ndarray,
                   refs: tuple[float, float], tol: float):
    """The friction points' part of :func:`linearize`'s arguments from the answer's weighted slip and traction,
    the map ds/dμ of a Coulomb law (None for Tresca), and how strictly each point holds its side."""
    fem, law = result.fem, result.scene.contact.law
    scaling, (u_ref, p_ref) = fem.scaling, refs
    traction = friction.components(np.asarray(result.contact.friction).reshape(fem.contact.m, -1).T.ravel()
                                   / scaling.pressure)
    coupling, unit, fixed = None, None, np.ones(friction.count, bool)
    if isinstance(law, Tresca):
        bound = field_at_points(law.slip_bound, "contact.slip_bound", fem, friction) / scaling.pressure
    else:  # s = μ λ_N at the answer: the Coulomb law itself
        unit = pressure_map(SimpleNamespace(law=replace(law, friction=1.0), fem=fem, friction=friction))[2]
        coupling = pressure_map(SimpleNamespace(law=law, fem=fem, friction=friction))[2]
        bound = coupling @ np.maximum(result.contact.pressure / scaling.pressure, 0.0)
        moving = np.isin(normal, ("closed", "grazing")).astype(float)
        fixed = (abs(coupling) @ moving) == 0  # no closed or grazing node under the point: its bound stays 0
    weighted = friction.components(weighted)
    slip = weighted / friction.weights[:, None] / u_ref
    epsilon = None if law.regularization is None else law.regularization / scaling.displacement
    status = friction_status(slip, traction / p_ref, bound / p_ref, held(friction.R, friction.dim), fixed, tol,
                             smooth=epsilon is not None)
    room = (bound - np.linalg.norm(traction, axis=1)) / p_ref
    strict = np.where(status == "slip", np.linalg.norm(slip, axis=1), np.where(status == "stick", room, np.inf))
    arguments = {"R": None, "friction": status, "slip": weighted, "traction": traction, "bound": bound,
                 "coupling": coupling, "epsilon": None if epsilon is None else epsilon * friction.weights}
    return unit, arguments, strict


def result_compliance(fem: FEModel, law) -> tuple[float, float]:
    """(c_N, p) of the law's normal compliance in scaled units, as the model scales them."""
    compliance = compliance_of(law)
    return compliance.stiffness * fem.scaling.displacement**compliance.exponent / fem.scaling.pressure, \
        compliance.exponent


def compliant(normal: np.ndarray, gap: np.ndarray, weights: np.ndarray, compliance: tuple[float, float]):
    """Normal compliance λ = c e^p, e = −gap the excess: the rows' statuses (a grazing row of p > 1 has a zero
    derivative: open) and their flexibility φ = w/(c p e^(p−1)) (:func:`linearize`)."""
    stiffness, exponent = compliance
    excess = np.maximum(-gap, 0.0)
    if exponent > 1:
        normal = np.where(normal == "grazing", "open", normal)
    rate = stiffness * exponent * excess ** (exponent - 1)
    flexibility = np.divide(weights, rate, out=np.zeros_like(weights), where=rate > 0)
    return normal, flexibility


def with_obstacle(result: ContactResult, C: sp.spmatrix, friction: FrictionPoints | None):
    """K, A = C N and R with the force-controlled obstacle's unknowns appended as columns (its advance δ_N closes
    the gaps by C c δ_N, its shift δ_T moves the slip by −coupling δ_T; no stiffness: their equations are the
    force balances), and their values in the answer (scaled). As in :mod:`~convexcontact.formulations.primal`."""
    fem = result.fem
    contact, scaling = fem.contact, fem.scaling
    rows = friction.R.shape[0] if friction is not None else 0
    normal, tangential, values = [], [], []
    if contact.obstacle_coupling is not None:
        normal.append(C @ contact.obstacle_coupling)
        tangential.append(np.zeros(rows))
        values.append(result.obstacle_advance / scaling.displacement)
    if contact.tangential_coupling is not None:
        normal.append(np.zeros(C.shape[0]))
        tangential.append(-friction.coupling)
        values.append(result.obstacle_shift / scaling.displacement)

    def widened(matrix, columns):
        return sp.csr_matrix(sp.hstack([matrix, sp.csr_matrix(np.column_stack(columns))])) if columns else \
            sp.csr_matrix(matrix)

    K = sp.block_diag([fem.K, sp.csr_matrix((len(values), len(values)))], format="csr") if values else fem.K
    return (K, widened(C @ contact.N, normal), None if friction is None else widened(friction.R, tangential),
            np.array(values, dtype=float))


def weighted_gap(contact, C) -> np.ndarray:
    """h = C(g − o_N): the right-hand side of the normal rows A u ≤ h."""
    return contact.weighted_gap(C) - C @ contact.normal_offset


def resultant_maps(point: Point) -> tuple[np.ndarray, np.ndarray | None]:
    """The contact force on the body (d-vector, scaled) as linear maps of λ_N and of λ_T: the nodal forces of
    :func:`~convexcontact.results.result.contact_nodes`, summed."""
    contact = point.fem.contact
    if isinstance(contact, PairTrace):  # the slave's nodal forces, from N and T over both bodies' DOFs
        return pair_resultant_maps(contact, point.C, point.friction)
    normal = -np.asarray(sp.csr_matrix(point.C).T @ contact.normals).T  # −Σ_i (Cᵀλ_N)_i n_i
    if point.friction is None:
        return normal, None
    along = np.hstack([t.T for t in contact.frame])  # d × m(d − 1), component-major like T
    return normal, np.asarray((sp.csr_matrix(contact.T) @ point.friction.R.T).T @ along.T).T


def pair_resultant_maps(contact: PairTrace, C: sp.spmatrix, friction: FrictionPoints | None):
    """:func:`resultant_maps` of a pair of bodies: the forces of :meth:`PairTrace.forces` on the slave's DOFs,
    summed per component (−N_fullᵀCᵀλ_N + T_fullᵀ(w·λ_T), as :func:`~convexcontact.results.certificate.pair_multipliers`
    weighs them)."""
    summing = sp.csr_matrix((np.ones(contact.dofs.size), (np.tile(np.arange(contact.dim), contact.m),
                                                          contact.dofs.ravel())),
                            shape=(contact.dim, contact.N_full.shape[1]))
    normal = -(summing @ contact.N_full.T @ sp.csr_matrix(C).T).toarray()
    if friction is None:
        return normal, None
    weights = np.tile(friction.weights, friction.dim)
    return normal, (summing @ contact.T_full.T).toarray() * weights


def mean_frame(fem: FEModel) -> tuple[np.ndarray, np.ndarray]:
    """The unit mean normal and mean tangent of Γ_C along which the result's normal and tangential forces act."""
    contact = fem.contact
    normal, tangent = contact.weights @ contact.normals, contact.weights @ contact.tangents
    return normal / np.linalg.norm(normal), tangent / np.linalg.norm(tangent)


def obstacle_names(contact) -> list[str]:
    """The force-controlled obstacle's unknowns, in the order of :func:`with_obstacle`."""
    return [name for name, coupling in (("obstacle_advance", contact.obstacle_coupling),
                                        ("obstacle_shift", contact.tangential_coupling)) if coupling is not None]
