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

from .checks import SceneError, finite_vector, of_type, sequence_of
from .description import (
    Body,
    Box,
    Contact,
    Coulomb,
    Dirichlet,
    Material,
    MeshFile,
    Obstacle,
    PerPair,
    Rectangle,
    Scene,
    Traction,
    compliance_of,
    has_friction,
)
from .load_history import History
from .meshing import build_mesh

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
        """The part's mesh in user units, checked, straight-sided (:func:`straight_sided`) and placed where its
        cells stay above round-off (:data:`PLACEMENT`)."""
        if isinstance(self.geometry, fe.Mesh) and not np.isfinite(self.geometry.p).all():
            raise SceneError(f"parts[{self.name}].geometry", "the mesh has NaN or infinite node coordinates",
                             "give every node finite coordinates")
        with self.named():
            mesh = straight_sided(build_mesh(Body(self.geometry, self.element, self.plane)))
        if self.offset is None:
            placed = mesh
        elif len(self.offset) != mesh.dim():
            raise SceneError(f"parts[{self.name}].offset", f"{len(self.offset)} numbers for a {mesh.dim()}-D body",
                             f"give {mesh.dim()} numbers")
        else:
            placed = mesh.translated(self.offset)
        size, reach = np.ptp(mesh.p, axis=1).max(), np.abs(placed.p).max()
        if reach > PLACEMENT * size:
            field_name = f"parts[{self.name}]." + ("geometry" if self.offset is None else "offset")
            raise SceneError(field_name, f"the body lies {reach:.3g} from the origin, {reach / size:.2g} times its size: "
                             "its cells are lost in round-off there (and lengths squared overflow)",
                             "place the bodies near the origin (Rectangle origin, Part offset)")
        return placed


PLACEMENT = 1e8
"""How far from the origin, in the body's sizes, a part may lie: coordinates of that magnitude hold a cell of 10⁻⁴
the body's size only to 2·10⁻⁴ of itself; 10³⁰⁰ made NaN normals and overflows before the pair was refused."""

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
    """Several contacts in one scene — pairs of bodies and rigid obstacles under a body's boundary — each with
    its own law: ``law`` is the one law of the scene's program, :func:`combined_law` of theirs, and
    :meth:`Scene.with_law` gives every contact the law it is given. ``boundary`` is the first slave."""

    pairs: tuple[Contact, ...] = ()

    def __post_init__(self):
        super().__post_init__()
        pairs = sequence_of(self.pairs, Contact, "contact", "give a list of cc.Pair(slave, master=…)")
        if not same(self.law, combined_law(tuple(pair.law for pair in pairs))):  # Scene.with_law: one law for all
            pairs = tuple(replace(pair, law=self.law) for pair in pairs)
        object.__setattr__(self, "pairs", pairs)


def several(pairs: tuple[Contact, ...]) -> Pairs:
    """The contacts of a list, each slave boundary once; a rigid obstacle among them must not need an equation
    of its own (its depth is given, not its force) and holds a node-wise law, as pairs do."""
    slaves = [pair.boundary for pair in pairs]
    for index, pair in enumerate(pairs):
        if slaves.index(pair.boundary) != index:
            raise SceneError(f"contact[{index}].boundary", f"{pair.boundary!r} is the slave of two pairs",
                             "give each slave boundary one master")
        if isinstance(pair, Pair):
            continue
        if pair.obstacle.force is not None or pair.obstacle.tangential_force is not None:
            raise SceneError(f"contact[{index}].obstacle", "an obstacle among several contacts is moved by its depth",
                             "give depth instead of force (a force-controlled obstacle only as the scene's one contact)")
        if getattr(pair.law, "non_penetration", "nodal") != "nodal" or getattr(pair.law, "quadrature", "nodal") != "nodal":
            raise SceneError(f"contact[{index}].non_penetration", "contacts stacked with pairs are node-wise",
                             "use non_penetration = 'nodal' and quadrature = 'nodal'")
    return Pairs(pairs[0].boundary, law=combined_law(tuple(pair.law for pair in pairs)), pairs=pairs)


def combined_law(laws: tuple) -> object:
    """The one law of contacts that each have their own: the friction coefficients (Coulomb) or slip bounds
    (Tresca) as a :class:`PerPair` field, None on frictionless contacts, whose nodes then get no tangential
    unknowns. What one program cannot vary from contact to contact must agree: the normal law, and the
    options of the friction law (one Picard map runs over every Coulomb contact)."""
    first = laws[0]
    if all(same(law, first) for law in laws):
        return first
    for index, law in enumerate(laws):
        if not same(compliance_of(law), compliance_of(first)):
            raise SceneError(f"contact[{index}].law", f"{describe(law)} where contact[0] has {describe(first)}: "
                             "non-penetration and normal compliance (or two compliances) in one scene",
                             "give every contact the same normal law; their friction may differ")
    frictional = [(index, law) for index, law in enumerate(laws) if has_friction(law)]
    kind, reference = type(frictional[0][1]), frictional[0][1]
    options = ("quadrature", "regularization") + (COULOMB_OPTIONS if kind is Coulomb else ())
    for index, law in frictional:
        if type(law) is not kind:
            raise SceneError(f"contact[{index}].law", f"{describe(law)} where contact[{frictional[0][0]}] has "
                             f"{describe(reference)}: Coulomb's slip bounds are the unknowns of a Picard map, Tresca's "
                             "are given", "use Coulomb on every frictional contact (its friction may differ from "
                             "contact to contact), or Tresca on every one")
        for name in options:
            if not same(getattr(law, name), getattr(reference, name)):
                raise SceneError(f"contact[{index}].{name}", f"{getattr(law, name)!r:.40} where contact"
                                 f"[{frictional[0][0]}] has {getattr(reference, name)!r:.40}",
                                 f"give every frictional contact the same {name}: one program runs over all of them")
    field_name = "friction" if kind is Coulomb else "slip_bound"
    values = PerPair(tuple(getattr(law, field_name) if has_friction(law) else None for law in laws))
    return replace(reference, **{field_name: values})


COULOMB_OPTIONS = ("relaxation", "tol", "max_iterations", "initial_pressure", "acceleration", "newton")
"""What one Picard map over several Coulomb contacts needs to be the same on each."""


def describe(law) -> str:
    return f"{law!r:.80}"


def same(a, b) -> bool:
    """Equal laws or fields; arrays compare element-wise."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.array_equal(a, b)
    try:
        return bool(a == b)
    except ValueError:  # numpy arrays in the fields: compare them one by one
        return type(a) is type(b) and all(same(x, y) for x, y in zip(vars(a).values(), vars(b).values()))


def body_of(boundary: str, names: list[str], field_name: str) -> str:
    """The part a ``"<part>.<boundary>"`` name belongs to, or an error naming the parts there are."""
    part = boundary.split(".", 1)[0] if isinstance(boundary, str) else None
    if part not in names or "." not in boundary:
        raise SceneError(field_name, f"{boundary!r} names no body", f"the bodies are {names}; name boundaries as "
                         f"'body.boundary', e.g. '{names[0]}.top'")
    return part


def check_named(mesh: fe.Mesh, boundary: str, names: list[str], field_name: str) -> None:
    """Refuse ``"<part>.<boundary>"`` where the part has no such boundary, listing the ones it has."""
    part = body_of(boundary, names, field_name)
    if boundary not in (mesh.boundaries or {}):
        own = sorted(name for name in mesh.boundaries or {} if name.startswith(f"{part}."))
        raise SceneError(field_name, f"body {part!r} has no boundary {boundary.split('.', 1)[1]!r}",
                         f"use one of {own}" if own else f"body {part!r} has no named boundary: name its facets in "
                         "the mesh file")


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
    is one pair, a rigid obstacle on a body's boundary (cc.Contact), or a list of them, each with its own law.
    ``history`` names the bodies' boundaries as the scene does, e.g. ``dirichlet[punch.top].ux``."""
    parts = sequence_of(parts, Part, "parts", "give a list of cc.Part(name, geometry, material)")
    names = [part.name for part in parts]
    if not parts:
        raise SceneError("parts", "no body", "give a list of cc.Part(name, geometry, material), one per body")
    if len(set(names)) != len(names):
        twice = next(name for name in names if names.count(name) > 1)
        raise SceneError("parts", f"two bodies named {twice!r} (the names are {names})", "give each body its own name")
    for field_name in ("element", "plane"):
        kinds = {getattr(part, field_name) for part in parts}
        if len(kinds) > 1:
            used = ", ".join(f"{part.name}: {getattr(part, field_name)}" for part in parts)
            raise SceneError(f"parts.{field_name}", f"mixed {field_name}s ({used})",
                             f"give every body the same {field_name}, e.g. {field_name} = "
                             f"{getattr(parts[0], field_name)!r} for all")
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
        if not contact:
            pair = f"a pair, e.g. cc.Pair('{names[0]}.bottom', master='{names[1]}.top'), or " if len(names) > 1 else ""
            raise SceneError("contact", "an empty list: the bodies touch nowhere", f"add {pair}a rigid obstacle, "
                             f"e.g. cc.Contact('{names[0]}.bottom', cc.Obstacle('flat'))")
        contact = several(sequence_of(contact, Contact, "contact", "give a list of cc.Pair(slave, master=…, law=…) "
                                      "and cc.Contact(boundary, obstacle, law)"))
    of_type(contact, Contact, "contact", "give cc.Pair(slave, master=…, law=…), a list of them, or "
            "cc.Contact(boundary, obstacle)")
    merged = concatenate(parts, meshes)
    named = [(d.boundary, f"dirichlet[{d.boundary}].boundary") for d in dirichlet]
    named += [(traction.boundary, f"traction[{traction.boundary}].boundary") for traction in tractions]
    several_contacts = isinstance(contact, Pairs)
    for index, pair in enumerate(contact.pairs if several_contacts else (contact,)):
        field_name = f"contact[{index}]" if several_contacts else "contact"
        named.append((pair.boundary, f"{field_name}.boundary"))
        slave = body_of(pair.boundary, names, f"{field_name}.boundary")
        if isinstance(pair, Pair):
            named.append((pair.master, f"{field_name}.master"))
            if body_of(pair.master, names, f"{field_name}.master") == slave:
                raise SceneError(f"{field_name}.master", f"{pair.master!r} and {pair.boundary!r} are boundaries of "
                                 "one body", "pair a boundary of one body with a boundary of another (self-contact is "
                                 "not built)")
    for boundary, field_name in named:
        check_named(merged, boundary, names, field_name)
    supported = {body_of(d.boundary, names, f"dirichlet[{d.boundary}].boundary") for d in dirichlet}
    floating = [name for name in names if name not in supported]
    if floating:
        raise SceneError("dirichlet", f"body {floating[0]!r} has no Dirichlet boundary: it can move rigidly "
                         "(contact alone does not hold a body)",
                         f"fix at least a component on one of its boundaries, e.g. boundary = '{floating[0]}.top', ux = 0")
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
