"""Several elastic bodies in one scene: the parts, their placement, and contact pairs between them.

:func:`bodies_scene` concatenates the parts' meshes into one scikit-fem mesh with disjoint node sets
(no node is shared, even where two bodies touch), boundaries and subdomains named ``<part>.<name>``
and one material per part, and returns an ordinary :class:`Scene`: K is block diagonal by
construction and every formulation, solver and driver applies unchanged. A :class:`Pair` is the
contact between a slave boundary (the non-mortar side, which carries the multipliers) and a master
boundary of another part (docs/bodies.md).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import skfem as fe

from ..fem.mesh import build_mesh
from .checks import SceneError, finite_vector, of_type, sequence_of
from .history import History
from .model import ELEMENTS, Body, Box, Contact, Dirichlet, Material, MeshFile, Obstacle, Rectangle, Scene, Traction

METHODS = ("mortar", "node_to_segment")


@dataclass(frozen=True)
class Part:
    """One elastic body: geometry (moved by ``offset``), element, 2-D hypothesis and material.

    Its boundaries are named ``"<name>.<boundary>"`` in the scene, e.g. ``"punch.bottom"``.
    """

    name: str
    geometry: Rectangle | Box | MeshFile | fe.Mesh
    material: Material
    element: str = "P1"
    plane: str = "strain"
    offset: tuple[float, ...] | None = None

    def __post_init__(self):
        of_type(self.name, str, "parts.name", "name each body, e.g. 'punch'")
        if not self.name or "." in self.name:
            raise SceneError("parts.name", f"{self.name!r} is empty or holds a '.'",
                             "use a plain word: boundaries are named 'body.boundary'")
        of_type(self.material, Material, f"parts[{self.name}].material", "give cc.Material(E, nu)")
        if self.offset is not None:
            object.__setattr__(self, "offset", finite_vector(self.offset, f"parts[{self.name}].offset", (2, 3)))
        with self.named():
            Body(self.geometry, self.element, self.plane)  # checks the geometry, element and hypothesis

    @contextmanager
    def named(self):
        """The body's errors ("body.element: …") named as this part's ("parts[punch].element: …")."""
        try:
            yield
        except SceneError as error:
            field_name = f"parts[{self.name}]." + error.field.removeprefix("body.")
            raise SceneError(field_name, str(error)[len(error.field) + 2:]) from None

    def mesh(self) -> fe.Mesh:
        """The part's mesh in user units, checked, straight-sided (:func:`straight_sided`) and placed."""
        with self.named():
            mesh = straight_sided(build_mesh(Body(self.geometry, self.element, self.plane)))
        if self.offset is None:
            return mesh
        if len(self.offset) != mesh.dim():
            raise SceneError(f"parts[{self.name}].offset", f"{len(self.offset)} numbers for a {mesh.dim()}-D body",
                             f"give {mesh.dim()} numbers")
        return mesh.translated(self.offset)


LINEAR = {fe.MeshTri2: (fe.MeshTri1, fe.ElementTriP2), fe.MeshQuad2: (fe.MeshQuad1, fe.ElementQuad2),
          fe.MeshTet2: (fe.MeshTet1, fe.ElementTetP2), fe.MeshHex2: (fe.MeshHex1, fe.ElementHex2)}
"""Each quadratic mesh's linear mesh, and the element whose nodes are the quadratic mesh's."""

STRAIGHT = 1e-9
"""How far (relative to the mesh's extent) a quadratic mesh's edge node may lie from where a straight-sided cell
puts it."""


def straight_sided(mesh: fe.Mesh) -> fe.Mesh:
    """A quadratic mesh whose edge (face, cell) nodes lie where straight-sided cells put them, as its linear mesh —
    P2/Q2 elements add those nodes back; a linear mesh as it is. Bodies are joined as linear meshes, and a pair's
    quadratic facets must be straight (their projection and mortar integrals are built for straight facets), so a
    curved quadratic mesh is refused (``body.geometry``, named as the part's by :meth:`Part.named`)."""
    if type(mesh) not in LINEAR:
        return mesh
    kind, element = LINEAR[type(mesh)]
    vertices = mesh.t.max() + 1  # a quadratic mesh numbers its vertices first
    linear = kind(mesh.p[:, :vertices], mesh.t, _boundaries=mesh.boundaries, _subdomains=mesh.subdomains)
    offset = np.abs(fe.CellBasis(linear, element(), intorder=1).doflocs - mesh.doflocs).max() / np.ptp(mesh.p, axis=1).max()
    if offset > STRAIGHT:
        raise SceneError("body.geometry", f"a {type(mesh).__name__} with curved edges (a node "
                         f"{offset:.2g} of the body's size off where a straight-sided cell puts it): bodies are "
                         "joined as straight-sided meshes, and a contact pair's quadratic facets must be straight",
                         "give a mesh with straight edges (gmsh: element order 1; element = 'P2' or 'Q2' adds the "
                         "middle nodes), finer where the boundary curves")
    return linear


@dataclass(frozen=True)
class Bodies(Body):
    """The parts as one Body: ``geometry`` is their concatenated mesh (built by :func:`bodies_scene`)."""

    parts: tuple[Part, ...] = ()

    def body_ids(self, mesh: fe.Mesh) -> np.ndarray:
        """The index in ``parts`` of each cell's body."""
        ids = np.empty(mesh.t.shape[1], dtype=int)
        for index, part in enumerate(self.parts):
            ids[mesh.subdomains[part.name]] = index
        return ids


@dataclass(frozen=True)
class Pair(Contact):
    """Contact between the slave boundary ``boundary`` and the ``master`` boundary of another part.

    ``method``: ``"mortar"`` (segment-to-segment, dual multipliers: passes the contact patch test) or
    ``"node_to_segment"`` (each slave node projected on the master: fails it, kept to compare).
    The gap comes from the geometry; there is no obstacle.
    """

    master: str = ""
    method: str = "mortar"

    def __post_init__(self):
        super().__post_init__()
        of_type(self.master, str, "contact.master", "name the master boundary, e.g. 'foundation.top'")
        if not self.master:
            raise SceneError("contact.master", "missing", "name the master boundary, e.g. 'foundation.top'")
        if self.method not in METHODS:
            raise SceneError("contact.method", f"unknown method {self.method!r}", f"use one of {METHODS}")
        if self.obstacle != Obstacle():
            raise SceneError("contact.obstacle", "a pair of bodies has no rigid obstacle",
                             "drop the obstacle (the gap comes from the two boundaries), or use cc.Contact")
        law = self.law
        if law.non_penetration != "nodal" or getattr(law, "quadrature", "nodal") != "nodal":
            raise SceneError("contact.non_penetration", "a pair is posed with dual (biorthogonal) mortar "
                             "multipliers: its node-wise law is already the weak, integral non-penetration",
                             "use non_penetration = 'nodal' and quadrature = 'nodal'")
        if getattr(law, "smoothing_radius", 0.0):
            raise SceneError("contact.smoothing_radius", "nonlocal Coulomb is not built for pairs",
                             "drop smoothing_radius (the local law)")


@dataclass(frozen=True)
class Pairs(Contact):
    """Several pairs of one law (the scene's program has one): ``boundary`` is the first slave, and each pair
    takes ``law``, so that :meth:`Scene.with_law` changes them all."""

    pairs: tuple[Pair, ...] = ()

    def __post_init__(self):
        super().__post_init__()
        pairs = sequence_of(self.pairs, Pair, "contact", "give a list of cc.Pair(slave, master=…)")
        object.__setattr__(self, "pairs", tuple(replace(pair, law=self.law) for pair in pairs))


def one_law(pairs: tuple[Pair, ...]) -> Pairs:
    """Pairs sharing the first pair's law; another law, or a slave boundary twice, is refused."""
    slaves = [pair.boundary for pair in pairs]
    for index, pair in enumerate(pairs):
        if not same(pair.law, pairs[0].law):
            raise SceneError(f"contact[{index}].law", f"{type(pair.law).__name__} where contact[0] has "
                             f"{pairs[0].law!r:.80}", "give every pair the same law: one scene is one program")
        if slaves.index(pair.boundary) != index:
            raise SceneError(f"contact[{index}].boundary", f"{pair.boundary!r} is the slave of two pairs",
                             "give each slave boundary one master")
    return Pairs(pairs[0].boundary, law=pairs[0].law, pairs=pairs)


def same(a, b) -> bool:
    """Equal laws; fields holding arrays compare element-wise."""
    try:
        return bool(a == b)
    except ValueError:  # numpy arrays in the fields: compare them one by one
        return type(a) is type(b) and all(np.array_equal(x, y) for x, y in zip(vars(a).values(), vars(b).values()))


def body_of(boundary: str, names: list[str], field_name: str) -> str:
    """The part a ``"<part>.<boundary>"`` name belongs to, or an error naming the parts there are."""
    part = boundary.split(".", 1)[0] if isinstance(boundary, str) else None
    if part not in names or "." not in boundary:
        raise SceneError(field_name, f"{boundary!r} names no body", f"the bodies are {names}; name boundaries as "
                         f"'body.boundary', e.g. '{names[0]}.top'")
    return part


def concatenate(parts: tuple[Part, ...], meshes: list[fe.Mesh]) -> fe.Mesh:
    """One mesh of all parts, node sets disjoint, boundaries and subdomains prefixed by the part's name."""
    shifts = np.cumsum([0] + [m.p.shape[1] for m in meshes[:-1]])
    cells = np.cumsum([0] + [m.t.shape[1] for m in meshes])
    merged = type(meshes[0])(np.hstack([m.p for m in meshes]), np.hstack([m.t + s for m, s in zip(meshes, shifts)]))
    boundaries, subdomains = {}, {}
    for part, mesh, shift, first in zip(parts, meshes, shifts, cells):
        for name, facets in (mesh.boundaries or {}).items():
            boundaries[f"{part.name}.{name}"] = facet_index(merged, np.sort(mesh.facets[:, facets], axis=0) + shift)
        subdomains[part.name] = first + np.arange(mesh.t.shape[1])
        subdomains.update({f"{part.name}.{name}": first + np.asarray(c) for name, c in (mesh.subdomains or {}).items()})
    return merged.with_boundaries(boundaries).with_subdomains(subdomains)


def facet_index(mesh: fe.Mesh, vertices: np.ndarray) -> np.ndarray:
    """Indices in ``mesh.facets`` of the facets given by their sorted vertices (one column each)."""
    def keys(columns):
        rows = np.ascontiguousarray(columns.T.astype(np.int64))
        return rows.view([("", np.int64)] * rows.shape[1]).ravel()

    table = keys(np.sort(mesh.facets, axis=0))
    order = np.argsort(table)
    return order[np.searchsorted(table[order], keys(vertices))]


def bodies_scene(
    parts,
    contact: Contact | list[Pair],
    dirichlet,
    tractions=(),
    name: str = "bodies",
    body_force=(0.0, 0.0),
    history: History | None = None,
) -> Scene:
    """A scene of several bodies (see the module's docstring); every body needs a support of its own. ``contact``
    is one pair, a list of pairs of one law, or a rigid obstacle on a body's boundary.
    ``history`` names the bodies' boundaries as the scene does, e.g. ``dirichlet[punch.top].ux``."""
    parts = sequence_of(parts, Part, "parts", "give a list of cc.Part(name, geometry, material)")
    names = [part.name for part in parts]
    if not parts or len(set(names)) != len(names):
        raise SceneError("parts", f"expected distinct names, got {names}", "give each body its own name")
    for field_name in ("element", "plane"):
        kinds = {getattr(part, field_name) for part in parts}
        if len(kinds) > 1:
            used = ", ".join(f"{part.name}: {getattr(part, field_name)}" for part in parts)
            raise SceneError(f"parts.{field_name}", f"mixed {field_name}s ({used})",
                             f"give every body the same {field_name}, e.g. {ELEMENTS[0]} with {ELEMENTS[0]}")
    meshes = [part.mesh() for part in parts]
    if len({m.dim() for m in meshes}) > 1:
        raise SceneError("parts.geometry", "2-D and 3-D bodies mixed", "give every body the same dimension")
    for part, mesh in zip(parts, meshes):
        if type(mesh) is not type(meshes[0]):
            raise SceneError(f"parts[{part.name}].geometry", f"a {type(mesh).__name__} among "
                             f"{type(meshes[0]).__name__} bodies: only meshes of one kind are joined",
                             "give every body a mesh of one cell type (P2/Q2 elements run on linear meshes too)")
    dirichlet = sequence_of(dirichlet, Dirichlet, "dirichlet", "give a list of cc.Dirichlet(boundary, ux=…, uy=…)")
    tractions = sequence_of(tractions, Traction, "tractions", "give a list of cc.Traction(boundary, pressure=…)")
    if isinstance(contact, (list, tuple)):
        contact = one_law(sequence_of(contact, Pair, "contact", "give a list of cc.Pair(slave, master=…, law=…)"))
    of_type(contact, Contact, "contact", "give cc.Pair(slave, master=…, law=…), a list of them, or "
            "cc.Contact(boundary, obstacle)")
    supported = {body_of(d.boundary, names, f"dirichlet[{d.boundary}].boundary") for d in dirichlet}
    for traction in tractions:
        body_of(traction.boundary, names, f"traction[{traction.boundary}].boundary")
    for pair in contact.pairs if isinstance(contact, Pairs) else (contact,):
        slave = body_of(pair.boundary, names, "contact.boundary")
        if isinstance(pair, Pair) and body_of(pair.master, names, "contact.master") == slave:
            raise SceneError("contact.master", f"{pair.master!r} and {pair.boundary!r} are boundaries of one body",
                             "pair a boundary of one body with a boundary of another (self-contact is not built)")
    floating = [name for name in names if name not in supported]
    if floating:
        raise SceneError("dirichlet", f"body {floating[0]!r} has no Dirichlet boundary: it can move rigidly "
                         "(contact alone does not hold a body)",
                         f"fix at least a component on one of its boundaries, e.g. boundary = '{floating[0]}.top', ux = 0")
    merged = concatenate(parts, meshes)
    return Scene(
        body=Bodies(merged, parts[0].element, parts[0].plane, parts=parts),
        materials={part.name: part.material for part in parts},
        dirichlet=dirichlet,
        tractions=tractions,
        contact=contact,
        name=name,
        body_force=body_force,
        history=history,
    )
