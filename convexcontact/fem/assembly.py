"""Stiffness, loads and Dirichlet elimination in scaled units (scikit-fem)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import skfem as fe
from skfem.helpers import dot, eye, trace
from skfem.models.elasticity import lame_parameters

from ..scene.bodies import Bodies, Pair, Pairs
from ..scene.description import Contact, Dirichlet, Material, Scene, SceneError, check_plane
from ..scene.meshing import build_mesh, check_boundary, mesh_warnings, scaled
from .basis import vector_basis
from .contact import ContactTrace, contact_trace
from .mortar import PairTrace, pair_trace, pairs_trace
from .scaling import Scaling
from .stiffness import stiffness


@dataclass
class FEModel:
    """Everything the formulations need, in scaled units (see :class:`Scaling`).

    ``K`` and ``f`` act on the free DOFs ``free``; ``prescribed`` is the full DOF
    vector holding the Dirichlet values (zero on free DOFs).
    """

    scene: Scene
    scaling: Scaling
    mesh: fe.Mesh  # in scaled coordinates
    basis: fe.Basis
    lame: tuple[np.ndarray, np.ndarray]  # per element (λ, μ) of the law (2-D: plane strain/stress), scaled
    K_full: sp.csr_matrix
    f_full: np.ndarray
    free: np.ndarray
    prescribed: np.ndarray
    contact: ContactTrace
    warnings: tuple[str, ...] = ()

    @cached_property
    def K(self) -> sp.csr_matrix:
        """Stiffness on the free DOFs (sliced once: every solve and certificate uses it)."""
        return self.K_full[self.free][:, self.free]

    @cached_property
    def f(self) -> np.ndarray:
        """Load on the free DOFs, with the Dirichlet data moved to the right-hand side."""
        return (self.f_full - self.K_full @ self.prescribed)[self.free]

    def with_law(self, law) -> FEModel:
        """This model with another contact law: the law enters neither K, f nor the trace, so the
        copy keeps them, including the free-DOF slices already cached."""
        copy = replace(self, scene=self.scene.with_law(law))
        copy.__dict__.update({name: self.__dict__[name] for name in ("K", "f") if name in self.__dict__})
        return copy

    def at(self, scene: Scene) -> FEModel:
        """This model under the loads, supports and obstacle of ``scene`` (a step of a history): the mesh,
        the units and K are kept, f, the Dirichlet values and the contact trace are computed anew."""
        free, prescribed = dirichlet(scene, self.mesh, self.basis, self.scaling.displacement)
        if not np.array_equal(free, self.free):
            raise SceneError("history", "a step prescribes other displacement components than the scene",
                             "keep the same Dirichlet components at every step (only their values change)")
        contact = build_trace(scene.contact, self.mesh, self.basis, self.scaling, free, prescribed)
        copy = replace(self, scene=scene, f_full=load_vector(scene, self.mesh, self.basis, self.scaling),
                       prescribed=prescribed, contact=contact)
        copy.__dict__.update({"K": self.__dict__["K"]} if "K" in self.__dict__ else {})  # K is the same
        return copy

    @property
    def dim(self) -> int:
        return self.mesh.dim()

    @property
    def n_free(self) -> int:
        return self.free.size

    def full(self, u_free: np.ndarray) -> np.ndarray:
        """Full DOF vector from the free DOFs and the Dirichlet data."""
        u = self.prescribed.copy()
        u[self.free] = u_free
        return u


def stress(lam, mu):
    """Stress of the linear elastic law with (possibly per-element) Lamé parameters, any dimension."""

    def sigma(strain):
        return 2.0 * mu * strain + lam * eye(trace(strain), strain.shape[0])

    return sigma


def lame_per_element(scene: Scene, mesh: fe.Mesh, stress_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Scaled Lamé parameters per element (in 2-D of plane strain or plane stress)."""
    nelems = mesh.t.shape[1]
    E = np.full(nelems, np.nan)
    nu = np.full(nelems, np.nan)
    if isinstance(scene.materials, Material):
        E[:], nu[:] = scene.materials.E, scene.materials.nu
    else:
        subdomains = mesh.subdomains or {}
        for name, material in scene.materials.items():
            if name not in subdomains:
                raise SceneError(f"materials.{name}", "no such subdomain", f"the mesh has {sorted(subdomains)}")
            E[subdomains[name]], nu[subdomains[name]] = material.E, material.nu
        if np.isnan(E).any():
            raise SceneError("materials", f"{np.isnan(E).sum()} elements have no material", "cover every subdomain")
    lam, mu = lame_parameters(E / stress_scale, nu)
    if scene.body.plane == "stress" and mesh.dim() == 2:
        lam = 2.0 * lam * mu / (lam + 2.0 * mu)
    return lam, mu


def viscous_stiffness(fem: FEModel) -> sp.csr_matrix | None:
    """K_A of Kelvin–Voigt materials (A = τ B per element, τ = η/E; full DOFs), None if every body is elastic."""
    scene = fem.scene
    materials = {None: scene.materials} if isinstance(scene.materials, Material) else scene.materials
    if not any(m.viscosity for m in materials.values()):
        return None
    tau = np.zeros(fem.mesh.t.shape[1])
    for name, material in materials.items():
        tau[slice(None) if name is None else fem.mesh.subdomains[name]] = material.viscosity / material.E
    return stiffness(fem.basis, (fem.lame[0] * tau, fem.lame[1] * tau))


def check_length(vector, dim: int, field_name: str) -> np.ndarray:
    """A load vector of the body's dimension (an all-zero vector of any length is zero)."""
    vector = np.asarray(vector, dtype=float)
    if vector.size != dim and vector.any():
        raise SceneError(field_name, f"{vector.size} components for a {dim}-D body", f"give {dim} numbers")
    return vector if vector.size == dim else np.zeros(dim)


def load_vector(scene: Scene, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling) -> np.ndarray:
    """Tractions and body force, scaled by the pressure scale."""
    f = np.zeros(basis.N)
    dim = mesh.dim()
    for traction in scene.tractions:
        facets = check_boundary(mesh, traction.boundary, f"traction[{traction.boundary}].boundary")
        facet_basis = fe.FacetBasis(mesh, basis.elem, facets=facets, dofs=basis.dofs, disable_doflocs=True)
        if traction.pressure is not None:
            p = traction.pressure / scaling.pressure
            f += fe.asm(fe.LinearForm(lambda v, w, p=p: -p * dot(w.n, v)), facet_basis)
        else:
            t = check_length(traction.vector, dim, f"traction[{traction.boundary}].vector") / scaling.pressure
            f += fe.asm(fe.LinearForm(lambda v, w, t=t: sum(t[i] * v[i] for i in range(dim))), facet_basis)
    if any(scene.body_force):
        b = check_length(scene.body_force, dim, "body_force") * scaling.length / scaling.pressure
        f += fe.asm(fe.LinearForm(lambda v, w: sum(b[i] * v[i] for i in range(dim))), basis)
    return f


def dirichlet(scene: Scene, mesh: fe.Mesh, basis: fe.Basis, displacement_scale: float):
    """Free DOF indices and the full vector of prescribed values (scaled)."""
    values = np.full(basis.N, np.nan)
    dim = mesh.dim()
    for condition in scene.dirichlet:
        check_boundary(mesh, condition.boundary, f"dirichlet[{condition.boundary}].boundary")
        dofs = basis.get_dofs(condition.boundary)
        for i, name in enumerate(Dirichlet.COMPONENTS):
            value = getattr(condition, name)
            if value is None:
                continue
            if i >= dim:
                raise SceneError(f"dirichlet[{condition.boundary}].{name}", f"a {dim}-D body has no component {i + 1}",
                                 f"prescribe only {', '.join(Dirichlet.COMPONENTS[:dim])}")
            component = f"u^{i + 1}"
            index = dofs.all(component)
            scaled = value / displacement_scale
            clash = ~np.isnan(values[index]) & ~np.isclose(values[index], scaled)
            if clash.any():
                raise SceneError(
                    f"dirichlet[{condition.boundary}]",
                    "prescribes a value that another Dirichlet boundary sets differently at a shared node",
                    "make the values agree at corners",
                )
            values[index] = scaled
    fixed = ~np.isnan(values)
    return np.flatnonzero(~fixed), np.where(fixed, values, 0.0)


LOCKING_NU = 0.45
"""Poisson's ratio above which linear elements (P1, Q1) lock noticeably."""


def locking_warnings(scene: Scene, dim: int = 2) -> tuple[str, ...]:
    """A warning when linear elements meet a near-incompressible material (plane strain or 3-D)."""
    materials = [scene.materials] if isinstance(scene.materials, Material) else list(scene.materials.values())
    nu = max(m.nu for m in materials)
    if scene.body.element in ("P1", "Q1") and nu >= LOCKING_NU and scene.body.plane == "strain":
        where = "plane strain" if dim == 2 else "3-D"
        return ((f"{scene.body.element} elements lock for ν = {nu:g} in {where} (too stiff: smaller contact "
                "zone, higher pressures); use P2 or Q2"),)
    return ()


MIN_STRAIN = 1e-12
"""Smallest strain (pressure / E) that sets the displacement scale: smaller loads are measured against it."""


def characteristic_pressure(scene: Scene, length: float, stress: float, overlap: float, dim: int = 2) -> float:
    """A pressure that sets the displacement scale: the largest applied load or imposed strain.

    ``overlap`` is the largest initial interpenetration of the obstacle at the contact
    nodes (depth, a negative flat gap, or an indentation written in a gap formula).
    """
    candidates = [abs(t.pressure) if t.pressure is not None else float(np.linalg.norm(t.vector))
                  for t in scene.tractions]
    candidates.append(float(np.linalg.norm(scene.body_force)) * length)
    obstacle = scene.contact.obstacle
    for force in (obstacle.force, obstacle.tangential_force):
        if force is not None:
            candidates.append(abs(force) / length ** (dim - 1))
    imposed = [abs(getattr(d, name) or 0.0) for d in scene.dirichlet for name in Dirichlet.COMPONENTS] + [overlap]
    candidates.append(stress * max(imposed) / length)
    return max(candidates)


def build_trace(contact: Contact, mesh: fe.Mesh, basis: fe.Basis, scaling: Scaling, free: np.ndarray,
                prescribed: np.ndarray) -> ContactTrace:
    """The contact trace: of Γ_C against the obstacle, or of pairs of bodies (:mod:`.mortar`)."""
    build = pair_trace if isinstance(contact, Pair) else pairs_trace if isinstance(contact, Pairs) else contact_trace
    return build(contact, mesh, basis, scaling, free, prescribed)


def assemble(scene: Scene) -> FEModel:
    """Assemble the scene's finite element model in scaled units."""
    # several bodies come with their mesh concatenated, each part checked on its own (touching bodies
    # have coincident nodes, which the check of one mesh would take for a crack)
    user_mesh = scene.body.geometry if isinstance(scene.body, Bodies) else build_mesh(scene.body)
    check_plane(scene.body.plane, user_mesh.dim())
    extent = user_mesh.p.max(axis=1) - user_mesh.p.min(axis=1)
    length = float(extent.max())
    E_max = max(m.E for m in ([scene.materials] if isinstance(scene.materials, Material) else scene.materials.values()))
    mesh = scaled(user_mesh, 1.0 / length)
    basis = vector_basis(mesh, scene.body.element)

    # the overlap at the contact nodes sets the displacement scale, so the trace is taken with displacements
    # in user units, then rescaled
    free, prescribed = dirichlet(scene, mesh, basis, 1.0)
    dim = mesh.dim()
    unscaled = build_trace(scene.contact, mesh, basis, Scaling(length, E_max, 1.0, dim), free, prescribed)
    overlap = max(-(unscaled.gap - unscaled.normal_offset).min(initial=0.0), 0.0)
    pressure = characteristic_pressure(scene, length, E_max, overlap, dim)
    # zero load and zero gap: any displacement scale will do, the answer is u = 0. The scale is at least
    # MIN_STRAIN × length: a lone imposed 4e-290 made the scaled obstacle gap 1e287 and W's program overflow
    displacement = length * max(pressure / E_max, MIN_STRAIN) if pressure > 0 else length
    scaling = Scaling(length=length, stress=E_max, displacement=displacement, dim=dim)

    lame = lame_per_element(scene, mesh, scaling.stress)
    K_full = stiffness(basis, lame)
    f_full = load_vector(scene, mesh, basis, scaling)
    prescribed = prescribed / scaling.displacement
    contact = unscaled.in_displacement_units(scaling.displacement)
    pair_warnings = contact.warnings if isinstance(contact, PairTrace) else ()
    return FEModel(scene, scaling, mesh, basis, lame, K_full, f_full, free, prescribed, contact,
                   mesh_warnings(user_mesh) + locking_warnings(scene, mesh.dim()) + pair_warnings)
