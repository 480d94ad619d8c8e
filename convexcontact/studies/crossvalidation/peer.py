"""Cross-validation of another code's output on that code's own mesh (issue 14).

A penalty code (sfepy, MOOSE, Kratos, Abaqus, Code_Aster…) writes its mesh and point data to a
file meshio reads (VTU, XDMF, Exodus, …). :func:`compare_peer` reads it, interpolates the peer's
nodal fields onto our mesh (scikit-fem's probes: the peer's piecewise-linear field evaluated at our
nodes), and reports against our exact answer, in the same terms as :mod:`.compare`:

- ``energy_error``, ``l2_displacement_error`` — the peer's displacement against ours, in our K and
  mass (relative to our field);
- ``pressure_l2_error``, ``pressure_max_error``, ``contact_zone_difference`` and ``normal_force``
  of both — where the peer writes a contact pressure, interpolated onto our contact nodes;
- ``fields`` — which peer fields were used, under which names.

Pressures differ in meaning between codes (nodal force ÷ ∫ψ_i here, k·d at quadrature points in a
penalty code, 2× at edge nodes elsewhere): the resultant ``normal_force`` of both is reported beside
the pressure errors, and the PNG overlays the two pressure curves. Units are the files': the scene
must be in the peer's units (a point of our mesh outside the peer's is an error saying how many).

:func:`read_peer` checks the file before anything is solved: a mesh meshio reads, of one kind of cell,
finite points; the fields used present, of the right shape (a displacement with the mesh's components,
a pressure with one value per point) and finite. Each refusal starts with the file's path.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import skfem as fe
from scipy.spatial import cKDTree

from ...results.result import CLOSED_PRESSURE, ContactResult
from ...scene.checks import of_type
from .compare import mass_matrix, relative, traction_errors

DISPLACEMENT_NAMES = ("displacement", "displacements", "u", "disp", "DISPLACEMENT", "Displacement", "U")
PRESSURE_NAMES = ("contact_pressure", "CONTACT_PRESSURE", "pressure", "contact pressure", "p_contact")
CELL_DIMENSIONS = {"triangle": 2, "quad": 2, "tetra": 3, "hexahedron": 3}
ELEMENTS = {fe.MeshTri1: fe.ElementTriP1, fe.MeshQuad1: fe.ElementQuad1, fe.MeshTet1: fe.ElementTetP1,
            fe.MeshHex1: fe.ElementHex1}
OPTION = {"displacement": "--displacement", "pressure": "--pressure"}
CHUNK = 64
"""Points probed at a time: scikit-fem's probes try each point against every candidate cell of the batch (and every
cell of the mesh when one is not found nearby), so the memory grows with the batch's size times the mesh's."""


@dataclass
class Peer:
    """A peer's output as read and checked: its mesh (user units) and the fields used, one row per vertex."""

    path: Path
    mesh: fe.Mesh
    names: dict[str, str]  # "displacement" / "pressure" → the file's point-data name, for those found
    displacement: np.ndarray | None  # (vertices, dim)
    pressure: np.ndarray | None  # (vertices,)

    @property
    def box(self) -> np.ndarray:
        """The lowest and highest coordinates of the vertices the cells use (a mesh file may hold others: gmsh's
        geometry points, arc centres)."""
        used = self.mesh.p[:, np.unique(self.mesh.t)]
        return np.array([used.min(axis=1), used.max(axis=1)])


COMMON_FORMATS = (".vtu", ".vtk", ".xdmf", ".exo", ".msh", ".med", ".inp")


def mesh_formats() -> str:
    """The mesh files meshio reads, the common ones by name."""
    import meshio

    others = len(set(meshio.extension_to_filetypes) - set(COMMON_FORMATS))
    return f"{', '.join(COMMON_FORMATS)} or {others} other extensions (meshio.extension_to_filetypes)"


def read_mesh(path: Path):
    """meshio's reading of ``path``; a file it cannot read is a ValueError saying why and which files it reads."""
    import meshio

    if not path.is_file():
        raise ValueError(f"{path}: {'a folder' if path.is_dir() else 'no such file'}; give the peer's output file")
    if path.suffix.lower() == ".json":
        raise ValueError(f"{path}: a JSON file, not a mesh; to compare two summary.json files give both (the first "
                         f"not a .toml), and to compare a scene with a peer give the peer's mesh: {mesh_formats()}")
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            return meshio.read(path)
    except SystemExit:  # meshio 5.3 prints each reader's complaint, then sys.exit(1) when none could read the file
        reason = " ".join(said.getvalue().split()) or "no reader could read it"
    except Exception as error:  # noqa: BLE001 — a reader fed another kind of file fails in its own way (XML, struct…)
        reason = f"{type(error).__name__}: {error}"
    raise ValueError(f"{path}: not a mesh meshio can read ({reason[:160]}); give the peer's output as a mesh file "
                     f"meshio reads: {mesh_formats()}")


def linear_mesh(data, path: Path) -> fe.Mesh:
    """The scikit-fem mesh of the file's cells of the highest dimension, all of one kind, with finite points."""
    from skfem.io.meshio import from_meshio

    solid = [block for block in data.cells if block.type in CELL_DIMENSIONS]
    if not solid:
        raise ValueError(f"{path}: no triangle, quad, tetra or hexahedron cells (found "
                         f"{sorted({b.type for b in data.cells}) or 'none'}); give the peer's mesh with linear cells")
    dim = max(CELL_DIMENSIONS[block.type] for block in solid)
    blocks = [block for block in solid if CELL_DIMENSIONS[block.type] == dim]
    kinds = sorted({block.type for block in blocks})
    if len(kinds) > 1:
        raise ValueError(f"{path}: {dim}-D cells of two kinds ({', '.join(kinds)}); give a mesh of one kind of cell")
    cells = np.concatenate([block.data for block in blocks])
    points = np.asarray(data.points, dtype=float)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}: {bad.sum()} of {len(points)} points have NaN or infinite coordinates (the first: "
                         f"point {np.flatnonzero(bad)[0]}); give a mesh with finite coordinates")
    if cells.size and (cells.min() < 0 or cells.max() >= len(points)):
        raise ValueError(f"{path}: cells refer to point {cells.max() if cells.max() >= len(points) else cells.min()}, "
                         f"the file has points 0 to {len(points) - 1}; the file is damaged")
    if dim == 2 and points.shape[1] == 3 and np.abs(points[:, 2]).max() > 0:
        raise ValueError(f"{path}: 2-D cells with nonzero z coordinates: is this a 3-D mesh? Give a 2-D mesh in the "
                         "plane z = 0, or a 3-D mesh of tetra or hexahedron cells")
    return from_meshio(type(data)(points[:, :dim], [(kinds[0], cells)]))


def point_data(data) -> dict[str, np.ndarray]:
    """The file's numeric point data, by name (other arrays are not fields a comparison can use)."""
    fields = {}
    for name, values in data.point_data.items():
        try:
            fields[name] = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            continue
    return fields


def listing(fields: dict) -> str:
    return ", ".join(f"{name!r} {values.shape}" for name, values in fields.items()) or "none"


def pick(fields: dict, names: tuple[str, ...], wanted: str | None, what: str, path) -> str | None:
    """The point-data name to use for ``what``: ``wanted`` if given, else the first known name present."""
    if wanted is not None:
        of_type(wanted, str, what, f"name one of the file's point data: {listing(fields)}")
        if wanted not in fields:
            raise ValueError(f"{path}: no point data {wanted!r} for the {what} ({OPTION[what]}); its point data: "
                             f"{listing(fields)}")
        return wanted
    return next((name for name in names if name in fields), None)


def field_values(fields: dict, name: str, what: str, mesh: fe.Mesh, path: Path) -> np.ndarray:
    """The point data ``name`` as the ``what`` of each vertex, refused when its shape or values cannot be that:
    a displacement has the mesh's dimension of components (a 2-D file's z component must be zero), a pressure one."""
    values, dim, count = fields[name], mesh.dim(), mesh.p.shape[1]
    components = dim if what == "displacement" else 1
    shape = values.shape
    fits = (len(shape) == 2 and shape[0] == count and (shape[1] == components or (what == "displacement"
            and dim == 2 and shape[1] == 3))) or (what == "pressure" and shape == (count,))
    if not fits:
        expected = f"({count}, {components})" if what == "displacement" else f"({count},)"
        raise ValueError(f"{path}: point data {name!r} has shape {shape}, a {what} of this {dim}-D mesh {expected}; "
                         f"its point data: {listing(fields)} — name the {what} with {OPTION[what]} NAME "
                         f"({what}=NAME in Python)")
    values = values.reshape(count, -1)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        first = np.flatnonzero(bad)[0]
        raise ValueError(f"{path}: point data {name!r} is NaN or infinite at {bad.sum()} of {count} points (the "
                         f"first: point {first} at {np.round(mesh.p[:, first], 6).tolist()}); the peer's answer is not "
                         "finite there: give the output of a run that converged")
    if values.shape[1] > components:  # a 2-D answer written with three components
        scale = np.abs(values[:, :2]).max(initial=0.0)
        if np.abs(values[:, 2]).max() > 1e-9 * scale:
            raise ValueError(f"{path}: point data {name!r} has a z component up to {np.abs(values[:, 2]).max():.3g} "
                             f"on a 2-D mesh (x, y up to {scale:.3g}); give a 2-D answer, or mesh the body in 3-D")
    return values[:, :components] if what == "displacement" else values[:, 0]


def read_peer(path, displacement: str | None = None, pressure: str | None = None) -> Peer:
    """The peer's mesh and the fields to compare, checked (see the module docstring). ``displacement`` /
    ``pressure``: the point data to use (default: the first of :data:`DISPLACEMENT_NAMES` /
    :data:`PRESSURE_NAMES` the file has)."""
    path = Path(of_type(path, (str, Path), "path", "give the peer's output file"))
    data = read_mesh(path)
    mesh = linear_mesh(data, path)
    fields = point_data(data)
    names = {"displacement": pick(fields, DISPLACEMENT_NAMES, displacement, "displacement", path),
             "pressure": pick(fields, PRESSURE_NAMES, pressure, "pressure", path)}
    if names["displacement"] is None and names["pressure"] is None:
        raise ValueError(f"{path}: no displacement or contact pressure among its point data ({listing(fields)}); "
                         "name them with --displacement NAME / --pressure NAME (displacement=… / pressure=… in Python)")
    values = {what: None if name is None else field_values(fields, name, what, mesh, path)
              for what, name in names.items()}
    return Peer(path, mesh, {k: v for k, v in names.items() if v is not None}, values["displacement"],
                values["pressure"])


def interpolation(peer: Peer, points: np.ndarray, box: np.ndarray):
    """The peer's linear field evaluated at ``points`` (d × k): a sparse matrix on the peer's vertices. Points
    outside the peer's mesh are refused, saying how many and how far."""
    mesh = peer.mesh
    basis = fe.Basis(mesh, ELEMENTS[type(mesh)]())
    low, high = peer.box[0][:, None], peer.box[1][:, None]
    outside = np.maximum(low - points, 0.0) + np.maximum(points - high, 0.0)
    if outside.max(initial=0.0) <= 1e-9 * (high - low).max():
        # boundary nodes of two meshes of one body differ by round-off: move them just inside the peer's box
        middle = (low + high) / 2
        points = middle + (1 - 1e-12) * (np.clip(points, low, high) - middle)
    blocks, lost = [], []
    for start in range(0, points.shape[1], CHUNK):
        try:
            blocks.append(basis.probes(points[:, start:start + CHUNK]))
        except ValueError:  # some point of the batch is in no cell: probe its points one by one to find which
            for k in range(start, min(start + CHUNK, points.shape[1])):
                probe = probe_point(basis, points[:, k], 1e-12 * (high - low).max())
                blocks.append(probe) if probe is not None else lost.append(k)
    if lost:
        distance = cKDTree(mesh.p.T).query(points[:, lost].T)[0]
        far = lost[int(np.argmax(distance))]
        raise ValueError(f"{peer.path}: {len(lost)} of {points.shape[1]} of our points "
                         f"({100 * len(lost) / points.shape[1]:.2g} %) lie outside the peer's mesh, the farthest "
                         f"{distance.max():.3g} from the peer's nearest vertex (at {np.round(points[:, far], 6).tolist()}; "
                         f"ours spans {box.tolist()}); the peer's mesh must cover the scene's body: the same body, "
                         "units and placement?")
    return sp.vstack(blocks).tocsr()[:, basis.nodal_dofs[0]]  # columns in the order of the peer's vertices


def probe_point(basis: fe.Basis, point: np.ndarray, step: float):
    """The probe of one point, or of the point moved ``step`` towards the centre of the nearest cell when it lies
    on the peer's boundary up to round-off (a hole's edge, where the box's nudge does not reach); None outside."""
    centres = basis.mesh.p[:, basis.mesh.t].mean(axis=1)
    nearest = centres[:, np.argmin(np.linalg.norm(centres - point[:, None], axis=0))]
    towards = (nearest - point) / max(np.linalg.norm(nearest - point), 1e-300)
    for candidate in (point, point + step * towards):
        try:
            return basis.probes(candidate[:, None])
        except ValueError:
            continue
    return None


def compare_peer(reference: ContactResult, path, displacement: str | None = None,
                 pressure: str | None = None) -> dict:
    """Errors of the peer's output at ``path`` against ``reference`` (see the module docstring)."""
    return peer_errors(reference, read_peer(path, displacement, pressure))


def check_dimension(peer: Peer, dim: int) -> None:
    """Refuse a peer's mesh of another dimension than the scene's."""
    if peer.mesh.dim() != dim:
        raise ValueError(f"{peer.path}: a {peer.mesh.dim()}-D mesh against a {dim}-D scene; compare with a scene of "
                         "the peer's dimension")


def peer_errors(reference: ContactResult, peer: Peer) -> dict:
    """Errors of a peer's output, read by :func:`read_peer`, against ``reference``."""
    of_type(reference, ContactResult, "reference", "give the result of cc.solve(scene)")
    if not reference.solved:
        raise ValueError(f"reference: no answer to compare (status {reference.status!r})")
    path = peer.path
    fem, scaling = reference.fem, reference.fem.scaling
    check_dimension(peer, fem.dim)
    ours = fem.basis.doflocs * scaling.length  # (d, N): a location per DOF
    box = np.array([ours.min(axis=1), ours.max(axis=1)])
    peer_box = peer.box
    if np.abs(peer_box - box).max() > 1e-3 * np.ptp(box, axis=0).max():
        raise ValueError(f"{path}: the peer's mesh spans {peer_box.tolist()}, ours {box.tolist()}: the same body in "
                         "the same units and placement? (the scene must be in the peer file's units)")
    report: dict = {"fields": dict(peer.names)}
    if peer.displacement is not None:
        values = np.empty_like(reference.displacement)
        for component, dofs in enumerate(fem.basis.split_indices()):  # every DOF, mid-side ones included
            values[dofs] = interpolation(peer, ours[:, dofs], box) @ peer.displacement[:, component]
        u, error = reference.displacement / scaling.displacement, (values - reference.displacement) / scaling.displacement
        for name, matrix in (("energy_error", fem.K_full), ("l2_displacement_error", mass_matrix(fem))):
            report[name] = relative(np.sqrt(max(error @ (matrix @ error), 0.0)), np.sqrt(max(u @ (matrix @ u), 0.0)))
    if peer.pressure is not None:
        contact = reference.contact
        peer_pressure = interpolation(peer, contact.coords.T, box) @ peer.pressure
        weights = fem.contact.weights * scaling.length ** (fem.dim - 1)
        report.update(traction_errors("pressure", contact.pressure, peer_pressure, weights))
        closed = peer_pressure > CLOSED_PRESSURE * max(peer_pressure.max(initial=0.0), 1e-300)
        report["contact_zone_difference"] = float(weights[closed != reference.closed].sum())
        report["normal_force"] = {"reference": float(weights @ contact.pressure), "peer": float(weights @ peer_pressure)}
        report["pressure_curves"] = (contact.coordinate, contact.pressure, peer_pressure)
    return report


def plot_pressures(report: dict, path) -> Path:
    """Both pressure curves along Γ_C."""
    import matplotlib.pyplot as plt

    from ...results.plots import save_figure

    s, ours, peer = report["pressure_curves"]
    order = np.argsort(s)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(s[order], ours[order], "o-", ms=3, label="exact (convexcontact)")
    ax.plot(s[order], peer[order], "s--", ms=3, label=f"peer ({report['fields']['pressure']})")
    ax.set_xlabel("position along Γ_C")
    ax.set_ylabel("contact pressure")
    ax.legend()
    return save_figure(fig, path)
