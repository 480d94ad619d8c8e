"""The result of a contact solve, in the user's units."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..fem import flux, flux3d
from ..fem.assembly import FEModel
from ..fem.estimate import ContactState, ErrorEstimate, algebraic_error, estimate
from ..fem.factorization import Condensation
from ..fem.flux import FluxEstimate
from ..fem.friction import FrictionPoints
from ..fem.mortar import PairTrace
from ..formulations.fields import ContactFields
from ..scene.description import PerPair, Tresca, compliance_of, evaluate_field
from .certificate import Certificate, normal_displacement, normal_gap, pair_multipliers
from .fields_out import element_stress

CLOSED_PRESSURE = 1e-6
"""A node is closed when its pressure exceeds this fraction of the largest pressure, and of the
data's pressure scale (the applied load's magnitude; E without load), so that round-off
pressures of an unloaded body do not count as contact."""


SLIP = 1e-7
"""A closed node slips when its slip exceeds this fraction of the largest displacement (at least
the data's displacement scale)."""


@dataclass
class ContactNodes:
    """Fields at the contact nodes (user units).

    ``status`` is open / closed without friction, open / stick / slip+ / slip− with
    friction in 2-D (slip± = slipping towards increasing / decreasing coordinate),
    open / stick / slip in 3-D. ``forces`` (m × d) are the nodal contact forces on the
    body; ``friction`` the friction traction along the tangent, ``slip`` the tangential
    slip u_T relative to the obstacle — (m,) in 2-D, (m, 2) in 3-D (components along
    ``tangents`` and ``bitangents``).
    """

    coords: np.ndarray
    coordinate: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    gap: np.ndarray  # initial gap to the obstacle at its final position
    normal_displacement: np.ndarray
    pressure: np.ndarray
    status: np.ndarray
    forces: np.ndarray
    friction: np.ndarray | None = None
    slip: np.ndarray | None = None
    radius: np.ndarray | None = None  # distance from the punch axis (see radius_from_axis)
    bitangents: np.ndarray | None = None
    master_coords: np.ndarray | None = None  # a pair's master nodes and the contact forces on them
    master_forces: np.ndarray | None = None

    @property
    def friction_magnitude(self) -> np.ndarray | None:
        """‖λ_T‖ at each node (|λ_T| in 2-D)."""
        return None if self.friction is None else np.abs(self.friction) if self.friction.ndim == 1 \
            else np.linalg.norm(self.friction, axis=1)


@dataclass
class ContactResult:
    """Displacement, contact tractions, certificate and timings of one solve."""

    fem: FEModel
    solver: str
    status: str
    solver_status: str
    iterations: int
    timings: dict[str, float]
    certificate: Certificate | None
    displacement: np.ndarray | None  # full DOF vector, user units
    contact: ContactNodes | None
    obstacle_advance: float | None = None
    obstacle_shift: float | None = None
    formulation: str = "primal"
    message: str = ""
    extra: dict = field(default_factory=dict)
    not_unique: dict[str, str] = field(default_factory=dict)  # quantity → why the answer does not fix it
    estimate_error: bool = True  # False: no error budget (summary, VTU), saving the estimator's cost
    condensation: Condensation | None = field(default=None, repr=False, compare=False)
    """K condensed onto the contact DOFs as the dual solve built it (None: the solve built none), kept in memory
    for the derivatives of :mod:`convexcontact.drivers.sensitivity`, which then factorize nothing; never saved,
    and dropped when the result is pickled (it holds the sparse solver's factors)."""

    def __getstate__(self) -> dict:
        return {**self.__dict__, "condensation": None}

    @property
    def solved(self) -> bool:
        return self.contact is not None

    @property
    def scene(self):
        return self.fem.scene

    @property
    def ndof(self) -> int:
        return self.fem.n_free

    @property
    def closed(self) -> np.ndarray:
        return self.contact.status != "open"

    @property
    def contact_force(self) -> np.ndarray:
        """Resultant force of the obstacle on the body (per unit thickness), user units."""
        return self.contact.forces.sum(axis=0)

    @property
    def normal_force(self) -> float:
        """Compressive resultant along the mean outward normal of Γ_C (≥ 0)."""
        mean = self.fem.contact.weights @ self.fem.contact.normals
        return float(-self.contact_force @ (mean / np.linalg.norm(mean)))

    @property
    def tangential_force(self) -> float:
        """Friction resultant along the mean tangent of Γ_C."""
        mean = self.fem.contact.weights @ self.fem.contact.tangents
        return float(self.contact_force @ (mean / np.linalg.norm(mean)))

    @property
    def max_pressure(self) -> float:
        return float(self.contact.pressure.max())

    @property
    def contact_half_width(self) -> float:
        """Half the extent of the closed zone along Γ_C (2-D), the largest distance of a closed node
        from the punch axis (3-D: the contact radius); 0 when nothing touches."""
        if self.fem.dim == 3:
            r = self.contact.radius[self.closed]
            return float(r.max()) if r.size else 0.0
        s = self.contact.coordinate[self.closed]
        return float((s.max() - s.min()) / 2) if s.size else 0.0

    @property
    def elastic_energy(self) -> float:
        """½ uᵀKu per unit thickness, user units."""
        scaled = self.displacement / self.fem.scaling.displacement
        return float(0.5 * scaled @ (self.fem.K_full @ scaled) * self.fem.scaling.energy)

    @cached_property
    def error_estimate(self) -> ErrorEstimate | FluxEstimate | None:
        """The estimate of the discretization error, scaled units: the equilibrated-flux bound for 2-D P1 triangles
        (:attr:`equilibrated_bound`), else :attr:`residual_estimate` (calibrated); None where that is. On P1
        tetrahedra the calibrated residual stays the budget's: the bound over-reads by 3–7× on stretched cells
        (docs/estimate.md, "The equilibrated bound on P1 tetrahedra")."""
        if self.fem.dim == 2 and self.equilibrated_bound is not None:
            return self.equilibrated_bound
        return self.residual_estimate

    @cached_property
    def equilibrated_bound(self) -> FluxEstimate | None:
        """The guaranteed equilibrated-flux bound of the discretization error (given Korn's constant), scaled
        units: P1 triangles (:mod:`convexcontact.fem.flux`) or tetrahedra (:mod:`convexcontact.fem.flux3d`), one
        body or a pair; None elsewhere, without an answer or when switched off."""
        if not self.estimated:
            return None
        for bound in (flux, flux3d):
            if bound.supported(self.fem):
                return bound.flux_estimate(self.fem, self.displacement / self.fem.scaling.displacement,
                                           contact_state(self))
        return None

    @property
    def estimated(self) -> bool:
        """Whether the result carries an error estimate: solved and not switched off (``estimate_error``)."""
        return self.solved and self.estimate_error

    @cached_property
    def residual_estimate(self) -> ErrorEstimate | None:
        """The residual estimate of the discretization error (:mod:`convexcontact.fem.estimate`), scaled units;
        None without an answer or when switched off (``estimate_error``)."""
        if not self.estimated:
            return None
        return estimate(self.fem, self.displacement / self.fem.scaling.displacement, contact_state(self))

    @cached_property
    def error_budget(self) -> dict | None:
        """The algebraic and the estimated discretization error side by side, relative to ‖u_h‖_E (docs/estimate.md);
        None where :attr:`error_estimate` is. Relative errors of a zero answer are 0 when the error is, else None
        (no scale to measure them against)."""
        estimated = self.error_estimate
        if estimated is None:
            return None
        norm = np.sqrt(estimated.energy)
        total = sum(estimated.terms.values())
        algebraic = algebraic_error(self.fem, self.displacement / self.fem.scaling.displacement, contact_state(self))
        equilibrated = isinstance(estimated, FluxEstimate)
        calibration = 1.0 if equilibrated else effectivity(self.scene.body.element, self.fem.dim)

        def relative(error: float) -> float | None:
            return float(error / norm) if norm > 0 else 0.0 if error == 0 else None

        return {
            "algebraic": relative(algebraic),
            "discretization": relative(estimated.eta / calibration),
            "eta": float(estimated.eta * np.sqrt(self.fem.scaling.energy)),
            "energy_norm": float(norm * np.sqrt(self.fem.scaling.energy)),
            "estimator": "equilibrated (a bound)" if equilibrated else "residual (calibrated)",
            "calibration": calibration,
            "terms": {name: value / total if total > 0 else 0.0 for name, value in estimated.terms.items()},
        }

    @property
    def warnings(self) -> list[str]:
        """The model's warnings, one naming a remedy when the estimated discretization error is large, and one where
        the estimate is not verified (a Tresca pair: :data:`UNVERIFIED`)."""
        budget, warnings = self.error_budget, list(self.fem.warnings)
        if budget is None:
            return warnings
        if budget["discretization"] is not None and budget["discretization"] > LARGE_ERROR:
            if self.scene.body.element in ("P1", "Q1"):
                remedy = "refine the mesh, or use P2/Q2 elements if ν is near 0.5 (volumetric locking of P1/Q1)"
            else:
                remedy = "refine the mesh (for ν near 0.5 the residual estimate overstates the error: docs/estimate.md)"
            warnings.append(f"estimated discretization error {budget['discretization']:.0%} of the energy norm "
                            f"(over {LARGE_ERROR:.0%}): {remedy}")
        if tied := self.tied_at_coverage_end:
            warnings.append(UNVERIFIED.format(tied))
        return warnings

    @property
    def tied_at_coverage_end(self) -> int:
        """Nodes of a Tresca pair held to the other body (closed, or open with a tangential force over :data:`TIED` of
        the largest contact force: the slip bound ties them across the gap) on a slave facet whose left-out node (one
        the master covers only partly) has a positive slip bound: the tie then ends where the master's coverage does,
        at a facet boundary that moves with the mesh, and the error estimate does not see that (:data:`UNVERIFIED`).
        Closed nodes count too: on a coarse pair the coverage can end inside the contact zone (two P2 spheres)."""
        if not self.solved or not isinstance(self.scene.contact.law, Tresca) or self.contact.master_forces is None:
            return 0  # an unsolved result has no contact nodes
        force = np.linalg.norm(self.contact.forces, axis=1)
        holding = force > TIED * force.max(initial=0.0)
        trace = self.fem.contact
        vertices = self.fem.mesh.facets[:, trace.facets]  # the slave facets' vertices: every row's, and the left-out
        kept = trace.dofs[:, 0] // self.fem.dim
        left_out = np.unique(vertices[~np.isin(vertices, kept)])
        bound = self.scene.contact.law.slip_bound
        if isinstance(bound, (np.ndarray, PerPair)):  # given on the rows only: taken as positive beyond them
            tying = left_out
        else:  # where a finer mesh would cover the slave and the slip bound tie it
            tying = left_out[evaluate_field(bound, "contact.slip_bound", self.fem.mesh.p[:, left_out].T
                                            * self.fem.scaling.length) > 0]
        at_end = np.unique(vertices[:, np.isin(vertices, tying).any(axis=0)])
        return int(np.count_nonzero(holding & np.isin(kept, at_end)))

    def cell_fields(self) -> dict[str, np.ndarray]:
        """The per-cell fields of solution.vtu (user units): element stresses and von Mises."""
        return element_stress(self)

    def summary(self) -> dict:
        """JSON-ready summary (see docs/certificate.md for the certificate, docs/estimate.md for the error budget)."""
        out = {
            "scene": self.scene.name,
            "ndof": self.ndof,
            "n_contact_nodes": self.fem.contact.m,
            "solver": self.solver,
            "status": self.status,
            "solver_status": self.solver_status,
            "law": type(self.scene.contact.law).__name__.lower(),
            "formulation": self.formulation,
            "formulation_reason": self.extra.get("formulation_reason", ""),
            "iterations": self.iterations,
            "timings": self.timings,
            "message": self.message,
            "warnings": self.warnings,
            "not_unique": dict(self.not_unique),
        }
        if not self.solved:
            return out
        c = self.contact
        out.update(
            contact_half_width=self.contact_half_width,
            max_pressure=self.max_pressure,
            normal_force=self.normal_force,
            contact_force=self.contact_force.tolist(),
            elastic_energy=self.elastic_energy,
            certificate=self.certificate.as_dict(),
            n_closed=int(self.closed.sum()),
            error_budget=self.error_budget,
            contact_nodes={
                **{axis: c.coords[:, i].tolist() for i, axis in enumerate("xyz"[: c.coords.shape[1]])},
                "s": c.coordinate.tolist(),
                "weight": (self.fem.contact.weights * self.fem.scaling.length ** (self.fem.dim - 1)).tolist(),
                "gap": c.gap.tolist(),
                "u_N": c.normal_displacement.tolist(),
                "lambda_N": c.pressure.tolist(),
                "status": c.status.tolist(),
            },
        )
        if self.obstacle_advance is not None:
            out["obstacle_advance"] = self.obstacle_advance
        if self.obstacle_shift is not None:
            out["obstacle_shift"] = self.obstacle_shift
        if c.master_forces is not None:
            out["master_force"] = c.master_forces.sum(axis=0).tolist()
            out["master_nodes"] = {**{axis: c.master_coords[:, i].tolist() for i, axis in enumerate("xy")},
                                   **{f"f_{axis}": c.master_forces[:, i].tolist() for i, axis in enumerate("xy")}}
        if c.friction is not None:
            out["tangential_force"] = self.tangential_force
            out["n_stick"] = int((c.status == "stick").sum())
            out["n_slip"] = int(np.char.startswith(c.status.astype(str), "slip").sum())
            out["contact_nodes"].update(lambda_T=c.friction.tolist(), u_T=c.slip.tolist())
            if c.bitangents is not None:
                out["contact_nodes"].update(tangent=c.tangents.tolist(), bitangent=c.bitangents.tolist())
            out["contact_nodes"].update(lambda_T=c.friction.tolist(), u_T=c.slip.tolist())
        out.update({k: v for k, v in self.extra.items() if k not in ("history", "formulation_reason")})
        if "history" in self.extra:
            out["picard_history"] = self.extra["history"]
        return out

    def save(self, directory, formats=("json", "vtk", "png")) -> list:
        """Write summary.json, solution.vtu and plots into ``directory``; return the paths."""
        from .output import save

        return save(self, directory, formats)


EFFECTIVITY = {"P1": 3.8, "Q1": 2.8, "P2": 5.2, "Q2": 4.5}
"""The residual estimator's η / true energy error, per element, below which no measured level of the families it
serves reads (docs/estimate.md, "The calibration, family by family"): where it is the estimator (all but 2-D P1), the
estimated discretization error is η divided by it — a calibration, not a bound. Each constant is the lowest raw
effectivity measured on that element's families (Hertz, the flat punch with Signorini, Tresca and Coulomb, the
two-cylinder pair; uniform and adaptive levels) divided by 1.1, so the calibrated estimate reads 1.1–2 times the
true error on them. The equilibrated bound (2-D P1) is reported as it is; ``P1`` is measured alike on 2-D P1's
residual estimate, which the budget does not use."""

EFFECTIVITY_3D = {"P1": 2.8, "P2": 3.7, "Q1": 2.0, "Q2": 2.8}
"""The same in 3-D (docs/estimate.md, "The calibration, family by family"): P1 tetrahedra from the adaptive 3-D
Hertz levels (raw 3.1–4.5; uniform Hertz boxes 3.8–5.1, the two spheres 3.5–5.4), P2 tetrahedra from the uniform
Hertz box with and without Tresca (raw 4.1–6.6; the graded box 4.6–7.2, the adaptive loop 4.5–5.8: "P2 tetrahedra's
weak multiplier"); Q1 and Q2 hexahedra from uniform levels of the Hertz box with and without Tresca, the 3-D punch
and the graded box (raw Q1 2.2–4.6, Q2 3.1–7.3, the lowest the graded box's last level, its error extrapolated past
its reference's; the graded box's pre-asymptotic first Q1 level excluded: docs/estimate.md, "Hexahedra in 3-D: the
calibration"). The 2-D constants (2.8, 4.5) read those hexahedra down to 0.77 and 0.88."""


def effectivity(element: str, dim: int) -> float:
    """The residual estimate's calibration constant for ``element`` in ``dim`` dimensions."""
    return EFFECTIVITY_3D.get(element, EFFECTIVITY[element]) if dim == 3 else EFFECTIVITY[element]


UNVERIFIED = ("the error estimate is not verified: the Tresca slip bound holds {} nodes (closed, or open and tied "
              "across the gap) to the other body up to the end of the master's coverage, which moves with the mesh "
              "(slave nodes the master covers only partly are left out), so each mesh ties a different part of the "
              "interface and the estimate misses the difference (two cylinders: the P2 and Q2 estimates 0.59-0.98 of "
              "the true error, the P1 bound 1.09-1.23; 1.07-1.62 with the tie inside the coverage; two P2 spheres "
              "0.47-1.00): give the slip bound only where the bodies may touch, or a master that covers the whole "
              "slave face (docs/estimate.md, 'Tresca pairs tied across their gap')")
"""The warning of a Tresca pair tied up to its coverage's end (:attr:`Result.tied_at_coverage_end`)."""
TIED = 1e-6
"""An open node's force, relative to the largest, from which it counts as tied (the solvers' forces at free open
nodes are round-off, ~1e-14 of the largest)."""
LARGE_ERROR = 0.5
"""Estimated relative discretization error (energy norm) above which a result warns and names the remedy: an answer
not resolved at all. Measured (docs/estimate.md, the equilibrated bound that 2-D P1 reports): Hertz P1 ν = 0.3 on the
stability study's nx = 32 mesh 0.21; the locking row (P1, ν = 0.4999, 71 % off Hertz) 28.6, P1 at ν = 0.49 (15 % off)
0.81."""


def contact_state(result: ContactResult) -> ContactState:
    """The discrete contact state of a solved result at the contact nodes, scaled (for the estimator)."""
    scaling, c = result.fem.scaling, result.contact
    slip = None
    if c.slip is not None:
        along = c.slip[:, None] if c.slip.ndim == 1 else c.slip
        frame = [c.tangents] if c.bitangents is None else [c.tangents, c.bitangents]
        slip = sum(along[:, [j]] * t for j, t in enumerate(frame)) / scaling.displacement
    law = result.scene.contact.law
    non_penetration = getattr(law, "non_penetration", "nodal")
    return ContactState(c.forces / scaling.force, c.normal_displacement / scaling.displacement,
                        c.gap / scaling.displacement, slip, constrained=compliance_of(law) is None,
                        gap_at_nodes=non_penetration != "gauss",
                        nodal_friction=non_penetration == "nodal" and getattr(law, "quadrature", "nodal") == "nodal",
                        master_forces=None if c.master_forces is None else c.master_forces / scaling.force)


def contact_nodes(
    fem: FEModel, fields: ContactFields, C, friction: FrictionPoints | None = None
) -> ContactNodes:
    """Contact-node fields in user units; open where the pressure is negligible."""
    contact, scaling = fem.contact, fem.scaling
    pressure = contact.nodal_pressure(C, fields.pressure) * scaling.pressure
    held_normal, held_tangential = held_at_points(contact, fem.scene.contact.law)
    pressure[held_normal] = 0.0
    closed = pressure > CLOSED_PRESSURE * max(pressure.max(initial=0.0), scaling.pressure)
    u_N = contact.N @ fields.u + contact.normal_offset
    gap = u_N - normal_gap(contact, fields)
    forces = -(C.T @ fields.pressure)[:, None] * contact.normals
    status = np.where(closed, "closed", "open")
    traction = slip = None
    if friction is not None:
        shift = 0.0 if contact.tangential_coupling is None else contact.tangential_coupling * fields.obstacle_shift
        slip = friction.components(contact.T @ fields.u + contact.tangent_offset - shift)  # (m, d − 1)
        tangential = friction.components(contact.T @ (friction.R.T @ fields.friction))
        forces = forces + sum(tangential[:, [j]] * t for j, t in enumerate(contact.frame))
        traction = friction.nodal_traction(contact, fields.friction) * scaling.pressure
        traction[held_tangential] = 0.0
        size = np.linalg.norm(slip, axis=1)
        moving = size > SLIP * max(np.abs(fields.u).max(initial=0.0), abs(fields.obstacle_shift), 1.0)
        sliding = np.where(slip[:, 0] > 0, "slip+", "slip-") if friction.dim == 1 else "slip"
        status = np.where(~closed, "open", np.where(~moving, "stick", sliding))
        slip = (slip[:, 0] if friction.dim == 1 else slip) * scaling.displacement
    master = {}
    if isinstance(contact, PairTrace):  # its T reaches the master too: the forces are read off both bodies' DOFs
        both = contact.forces(*pair_multipliers(C, fields, friction))
        forces = both[contact.dofs]
        master = {"master_coords": contact.master_coords * scaling.length,
                  "master_forces": both[contact.master_dofs] * scaling.force}
    return ContactNodes(
        coords=contact.coords * scaling.length,
        coordinate=contact.coordinate * scaling.length,
        normals=contact.normals,
        tangents=contact.tangents,
        gap=gap * scaling.displacement,
        normal_displacement=u_N * scaling.displacement,
        pressure=pressure,
        status=status,
        forces=forces * scaling.force,
        friction=traction,
        slip=slip,
        bitangents=contact.bitangents,
        radius=radius_from_axis(fem) * scaling.length,
        **master,
    )


def not_unique(fem: FEModel, fields: ContactFields, friction: FrictionPoints | None, law) -> dict[str, str]:
    """The reported quantities the discrete problem does not determine, each with the reason.

    u is unique (K is SPD on the free DOFs); a multiplier is unique where its constraint rows are
    independent. They are not at a contact node whose displacement is prescribed (its force goes into
    the support: reported as 0), nor among Gauss friction points that stick on more points than the
    nodal DOFs they act on (the nodal friction force Gᵀωλ_T stays unique and is what is reported).
    """
    from ..scene.description import Coulomb, compliance_of

    contact, reasons = fem.contact, {}
    normal = held(contact.N)
    if normal.any():
        reasons["pressure"] = (f"{normal.sum()} contact nodes have a prescribed normal displacement: their contact "
                               "force is the support's reaction, reported as 0")
    signorini_points = getattr(law, "non_penetration", None) == "gauss" and compliance_of(law) is None
    if contact.points is not None and signorini_points:  # a penalty's point multipliers c e^p are unique
        points = contact.points
        gap = points.gap - points.interpolation @ normal_displacement(contact, fields)
        active = gap <= SLIP * max(np.abs(fields.u).max(initial=0.0), 1.0)
        nodes = np.unique(points.interpolation[active].indices).size
        if active.sum() > nodes:
            reasons["pressure_at_points"] = (f"{active.sum()} Gauss points touch, acting on {nodes} nodes: the point "
                                             "multipliers are one choice among many; the nodal pressure (their "
                                             "nodal force per contact weight) is unique and is what is reported")
    if friction is None:
        return reasons
    gauss = getattr(law, "quadrature", None) == "gauss"
    tangential = held_at_points(contact, law)[1] if gauss else held(friction.R, friction.dim)
    if tangential.any():
        reasons["friction"] = (f"{tangential.sum()} {'contact nodes' if gauss else 'friction points'} have a "
                               "prescribed tangential displacement: their friction force is the support's reaction, "
                               "reported as 0")
    if friction.count > contact.m:  # Gauss points
        slip = np.linalg.norm(friction.components(friction.slip(fields.u)), axis=1) / friction.weights
        sticking = slip <= SLIP * max(np.abs(fields.u).max(initial=0.0), 1.0)
        nodes = np.unique(sp.csr_matrix(friction.interpolation)[sticking].indices).size
        if sticking.sum() > nodes:
            reasons["friction_at_points"] = (f"{sticking.sum()} sticking Gauss points act on {nodes} nodes: the "
                                             "point tractions are one choice among many; the nodal friction "
                                             "traction (their nodal force per contact weight) is unique")
    if isinstance(law, Coulomb):
        reasons["solution"] = ("Coulomb friction: this is one fixed point of the Picard map; the discrete problem is "
                               "unique only for small enough F (Hild), which is not checked here")
    return reasons


def held(rows: sp.spmatrix, components: int = 1) -> np.ndarray:
    """The contact nodes whose displacement along ``rows`` (N, or T's ``components`` blocks) is prescribed: rows
    without a nonzero entry (their stored entries may be zeros, a roller's)."""
    return (np.asarray(abs(rows).sum(axis=1)).ravel() == 0).reshape(components, -1).all(axis=0)


def held_at_points(contact, law) -> tuple[np.ndarray, np.ndarray]:
    """The contact nodes whose normal, and whose tangential, displacement is prescribed where non-penetration,
    and friction, act at Gauss points (none otherwise). The points beside such a node act on it, but its force
    goes into the support: the node's share of the point multipliers is not fixed where they touch or stick (a
    friction traction differed in sign between two solvers). It is reported as 0 and said in :func:`not_unique`,
    as at the nodes, where such a node's row is empty."""
    none = np.zeros(contact.m, bool)
    return (held(contact.N) if contact.points is not None else none,
            held(contact.T, contact.dim - 1) if getattr(law, "quadrature", None) == "gauss" else none)


def radius_from_axis(fem: FEModel) -> np.ndarray:
    """Scaled distance of each contact node from the punch axis (3-D; |coordinate − centre| in 2-D):
    the obstacle's ``center`` when it has one, else the weighted centroid of Γ_C."""
    contact, obstacle = fem.contact, fem.scene.contact.obstacle
    if contact.dim == 2:
        center = obstacle.center / fem.scaling.length if obstacle.shape in ("parabolic", "cylinder", "sphere") \
            else contact.weights @ contact.coordinate / contact.weights.sum()
        return np.abs(contact.coordinate - center)
    if obstacle.shape in ("parabolic", "sphere"):
        center = obstacle.axis(3) / fem.scaling.length
    else:
        center = contact.weights @ contact.coords / contact.weights.sum()
    normal = contact.weights @ contact.normals
    normal /= np.linalg.norm(normal)
    offset = contact.coords - center
    return np.linalg.norm(offset - np.outer(offset @ normal, normal), axis=1)
