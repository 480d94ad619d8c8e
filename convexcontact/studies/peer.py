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
must be in the peer's units (a point of our mesh outside the peer's is an error naming both boxes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import skfem as fe

from ..results.result import CLOSED_PRESSURE, ContactResult
from .compare import mass_matrix, relative, traction_errors

DISPLACEMENT_NAMES = ("displacement", "displacements", "u", "disp", "DISPLACEMENT", "Displacement", "U")
PRESSURE_NAMES = ("contact_pressure", "CONTACT_PRESSURE", "pressure", "contact pressure", "p_contact")


def read_peer(path) -> tuple[fe.Mesh, dict[str, np.ndarray]]:
    """The peer's mesh (scikit-fem, linear cells) and point data from any file meshio reads."""
    import meshio
    from skfem.io.meshio import from_meshio

    path = Path(path)
    try:
        data = meshio.read(path)
    except (OSError, meshio.ReadError, KeyError, ValueError) as error:
        raise ValueError(f"{path}: meshio cannot read it ({error}); give a VTU, XDMF, Exodus, … file") from None
    kinds = {"triangle", "quad", "tetra", "hexahedron"}
    cells = [block for block in data.cells if block.type in kinds]
    if not cells:
        raise ValueError(f"{path}: no triangle, quad, tetra or hexahedron cells (found "
                         f"{sorted({b.type for b in data.cells})})")
    dim = 3 if cells[0].type in ("tetra", "hexahedron") else 2
    points = data.points[:, :dim]
    if dim == 2 and data.points.shape[1] == 3 and np.abs(data.points[:, 2]).max() > 0:
        raise ValueError(f"{path}: 2-D cells with nonzero z coordinates: is this a 3-D mesh?")
    mesh = from_meshio(meshio.Mesh(points, [(cells[0].type, cells[0].data)]))
    return mesh, {name: np.asarray(values, float) for name, values in data.point_data.items()}


def pick(fields: dict, names: tuple[str, ...], wanted: str | None, what: str, path) -> str | None:
    """The point-data name to use for ``what``: ``wanted`` if given, else the first known name present."""
    if wanted is not None:
        if wanted not in fields:
            raise ValueError(f"{path}: no point data {wanted!r} for the {what}; it has {sorted(fields)}")
        return wanted
    return next((name for name in names if name in fields), None)


def interpolation(mesh: fe.Mesh, points: np.ndarray, path, box: np.ndarray):
    """The peer's linear field evaluated at ``points`` (d × k): a sparse matrix on the peer's vertices."""
    element = {fe.MeshTri1: fe.ElementTriP1, fe.MeshQuad1: fe.ElementQuad1, fe.MeshTet1: fe.ElementTetP1,
               fe.MeshHex1: fe.ElementHex1}[type(mesh)]()
    basis = fe.Basis(mesh, element)
    low, high = mesh.p.min(axis=1, keepdims=True), mesh.p.max(axis=1, keepdims=True)
    outside = np.maximum(low - points, 0.0) + np.maximum(points - high, 0.0)
    if outside.max(initial=0.0) <= 1e-9 * (high - low).max():
        # boundary nodes of two meshes of one body differ by round-off: move them just inside the peer's box
        middle = (low + high) / 2
        points = middle + (1 - 1e-12) * (np.clip(points, low, high) - middle)
    try:
        probes = basis.probes(points)
    except ValueError:
        raise ValueError(f"{path}: our mesh reaches outside the peer's (ours spans {box.tolist()}, the peer's "
                         f"{[mesh.p.min(axis=1).tolist(), mesh.p.max(axis=1).tolist()]}): the same units and "
                         "placement?") from None
    return probes.tocsr()[:, basis.nodal_dofs[0]]  # columns in the order of the peer's vertices


def compare_peer(reference: ContactResult, path, displacement: str | None = None,
                 pressure: str | None = None) -> dict:
    """Errors of the peer's output at ``path`` against ``reference`` (see the module docstring)."""
    if not reference.solved:
        raise ValueError(f"reference: no answer to compare (status {reference.status!r})")
    mesh, fields = read_peer(path)
    fem, scaling = reference.fem, reference.fem.scaling
    if mesh.dim() != fem.dim:
        raise ValueError(f"{path}: a {mesh.dim()}-D mesh against a {fem.dim}-D scene")
    names = {"displacement": pick(fields, DISPLACEMENT_NAMES, displacement, "displacement", path),
             "pressure": pick(fields, PRESSURE_NAMES, pressure, "contact pressure", path)}
    if names["displacement"] is None and names["pressure"] is None:
        raise ValueError(f"{path}: no displacement or contact pressure among its point data {sorted(fields)}; "
                         "name them with displacement=… / pressure=… (--displacement, --pressure)")
    ours = fem.basis.doflocs * scaling.length  # (d, N): a location per DOF
    box = np.array([ours.min(axis=1), ours.max(axis=1)])
    peer_box = np.array([mesh.p.min(axis=1), mesh.p.max(axis=1)])
    if np.abs(peer_box - box).max() > 1e-3 * np.ptp(box, axis=0).max():
        raise ValueError(f"{path}: the peer's mesh spans {peer_box.tolist()}, ours {box.tolist()}: the same body in "
                         "the same units and placement? (the scene must be in the peer file's units)")
    report: dict = {"fields": {k: v for k, v in names.items() if v is not None}}
    if names["displacement"] is not None:
        values = fields[names["displacement"]][:, : fem.dim]
        peer = np.empty_like(reference.displacement)
        for component, dofs in enumerate(fem.basis.split_indices()):  # every DOF, mid-side ones included
            peer[dofs] = interpolation(mesh, ours[:, dofs], path, box) @ values[:, component]
        u, error = reference.displacement / scaling.displacement, (peer - reference.displacement) / scaling.displacement
        for name, matrix in (("energy_error", fem.K_full), ("l2_displacement_error", mass_matrix(fem))):
            report[name] = relative(np.sqrt(max(error @ (matrix @ error), 0.0)), np.sqrt(max(u @ (matrix @ u), 0.0)))
    if names["pressure"] is not None:
        contact = reference.contact
        values = fields[names["pressure"]]
        peer_pressure = interpolation(mesh, contact.coords.T, path, box) @ values
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

    from ..results.plots import save_figure

    s, ours, peer = report["pressure_curves"]
    order = np.argsort(s)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(s[order], ours[order], "o-", ms=3, label="exact (convexcontact)")
    ax.plot(s[order], peer[order], "s--", ms=3, label=f"peer ({report['fields']['pressure']})")
    ax.set_xlabel("position along Γ_C")
    ax.set_ylabel("contact pressure")
    ax.legend()
    return save_figure(fig, path)
