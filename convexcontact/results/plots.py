"""Plots of a result: deformed mesh (2-D), and tractions along Γ_C or against the radius (3-D), with Hertz."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PolyCollection

from ..analytic import hertz_plane_strain, hertz_pressure, hertz_sphere
from ..scene.description import Coulomb, Material, Tresca, field_at_nodes, has_friction
from .fields_out import vertex_displacement


def deformed_mesh(result, path, magnification: float | None = None):
    """Deformed mesh coloured by von Mises stress; contact nodes marked by status."""
    fem = result.fem
    points = fem.mesh.p.T * fem.scaling.length
    u = vertex_displacement(result)
    size = np.ptp(points, axis=0).max()
    if magnification is None:
        largest = np.abs(u).max()
        magnification = 0.05 * size / largest if largest > 0 else 1.0
    moved = points + magnification * u
    corners = fem.mesh.t[: 4 if fem.mesh.t.shape[0] >= 4 else 3]
    fig, ax = plt.subplots(figsize=(8, 5))
    polys = PolyCollection(moved[corners.T], array=result.cell_fields()["von_mises"], cmap="viridis",
                           edgecolors="k", linewidths=0.1)
    ax.add_collection(polys)
    fig.colorbar(polys, ax=ax, label="von Mises stress")
    contact = result.contact
    tip = contact.coords + magnification * result.displacement[fem.contact.dofs]
    for status, color in (("open", "tab:gray"), ("closed", "tab:red"), ("stick", "tab:blue"), ("slip", "tab:orange")):
        mask = contact.status == status
        if mask.any():
            ax.plot(*tip[mask].T, ".", color=color, ms=3, label=status)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"{result.scene.name}: deformed mesh (displacement ×{magnification:.3g})")
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)


def hertz_reference(result):
    """(a, p0) of Hertz (plane strain in 2-D, the sphere in 3-D) for a punch scene with one material,
    else None. A 3-D model of a quarter (half) of the contact carries a quarter (half) of the force."""
    scene = result.scene
    obstacle = scene.contact.obstacle
    if obstacle.shape not in ("parabolic", "cylinder", "sphere") or not isinstance(scene.materials, Material):
        return None
    E, nu = scene.materials.E, scene.materials.nu
    if result.fem.dim == 3:
        return hertz_sphere(result.normal_force * symmetry_factor(result), obstacle.radius, E, nu)
    if scene.body.plane == "stress":  # plane stress: E* = E
        nu = 0.0
    return hertz_plane_strain(result.normal_force, obstacle.radius, E, nu)


def symmetry_factor(result) -> int:
    """2 per tangent direction in which Γ_C lies on one side only of the punch axis (a symmetry plane)."""
    contact = result.fem.contact
    offset = contact.coords * result.fem.scaling.length - result.scene.contact.obstacle.axis(3)
    sides = [offset @ t.mean(axis=0) for t in contact.frame]
    return 2 ** sum(int(side.min() >= -1e-12 or side.max() <= 1e-12) for side in sides)


def friction_bound(result) -> tuple[np.ndarray, str] | None:
    """The nodal slip bound to draw against λ_T: s for Tresca, F λ_N for Coulomb."""
    law, contact, pieces = result.scene.contact.law, result.contact, getattr(result.fem.contact, "pieces", ())
    if isinstance(law, Tresca):
        return field_at_nodes(law.slip_bound, "contact.slip_bound", contact.coords, pieces), "±s (slip bound)"
    if isinstance(law, Coulomb):
        return field_at_nodes(law.friction, "contact.friction", contact.coords, pieces) * contact.pressure, "±F λ_N"
    return None


def contact_tractions(result, path):
    """Contact pressure and friction traction along Γ_C (2-D) or against the distance from the punch
    axis (3-D, friction as ‖λ_T‖): Hertz curve for punches, slip bounds and stick (blue) / slip
    (orange) zones with friction; one panel per contact of a scene that has several."""
    contacts, pieces = getattr(result.scene.contact, "pairs", ()), getattr(result.fem.contact, "pieces", ())
    panels = [(slice(None), f"{result.scene.name}: contact tractions", True)]
    if len(pieces) > 1:
        panels = [(rows, f"{c.boundary} on {getattr(c, 'master', '') or 'the rigid obstacle'}: {type(c.law).__name__}",
                   has_friction(c.law)) for (rows, *_), c in zip(pieces, contacts)]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 4 * len(panels)), squeeze=False, layout="constrained")
    for ax, (rows, title, friction) in zip(axes[:, 0], panels):
        draw_tractions(ax, result, rows, hertz=len(panels) == 1, friction=friction)
        ax.set_title(title)
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)


def draw_tractions(ax, result, rows, hertz: bool, friction: bool):
    """The tractions of the contact nodes ``rows`` on ``ax`` (see :func:`contact_tractions`)."""
    contact = result.contact
    radial = result.fem.dim == 3
    coordinate = (contact.radius if radial else contact.coordinate)[rows]
    order = np.argsort(coordinate)
    s = coordinate[order]
    style = "o" if radial else "o-"  # 3-D nodes at one radius are not a curve
    ax.plot(s, contact.pressure[rows][order], style, ms=3, label="λ_N (pressure)")
    bound = friction_bound(result) if friction else None
    if bound is not None:
        values, label = bound[0][rows], bound[1]
        friction = (contact.friction_magnitude if radial else contact.friction)[rows]
        ax.plot(s, friction[order], "s" if radial else "s-", ms=3, label="‖λ_T‖" if radial else "λ_T (friction traction)")
        ax.plot(s, values[order], "k.", ms=2) if radial else ax.plot(s, values[order], "k:", lw=1, label=label)
        if not radial:
            ax.plot(s, -values[order], "k:", lw=1)
            status = contact.status[rows][order]
            for name, color in (("stick", "tab:blue"), ("slip", "tab:orange")):
                inside = np.char.startswith(status.astype(str), name)
                ax.fill_between(s, 0, 1, where=inside, color=color, alpha=0.12, transform=ax.get_xaxis_transform(),
                                label=f"{name} zone")
    reference = hertz_reference(result) if hertz else None
    if reference is not None:
        a, p0 = reference
        center = 0.0 if radial else result.scene.contact.obstacle.center
        x = np.linspace(0.0 if radial else center - 1.5 * a, center + 1.5 * a, 400)
        ax.plot(x, hertz_pressure(x - center, a, p0), "k--", lw=1, label=f"Hertz (a = {a:.4g}, p₀ = {p0:.4g})")
    closed = s[contact.status[rows][order] != "open"]
    if closed.size:
        span = 1.5 * max(closed.max() - closed.min(), 1e-12) / 2 + 0.2 * np.ptp(closed)
        ax.set_xlim(0.0 if radial else closed.mean() - span, (1.5 * closed.max()) if radial else closed.mean() + span)
    ax.set_xlabel("distance from the punch axis" if radial else "coordinate along Γ_C")
    ax.set_ylabel("traction")
    ax.axhline(0, color="0.7", lw=0.5)
    ax.legend(fontsize=8)


def picard_convergence(result, path):
    """Relative change of the slip bounds and Coulomb residual per Picard iteration, and the natural residual of
    each Newton step where Newton's method on the Coulomb problem answered."""
    history = result.extra["history"]
    k = [h["iteration"] for h in history]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogy(k, [h["relative_change"] for h in history], "o-", label="relative change of s")
    ax.semilogy(k, [h["coulomb_residual"] for h in history], "s-", label="Coulomb residual (certificate)")
    newton = next((h["newton_residuals"] for h in history if h.get("newton_residuals")), None)
    if newton is not None:
        ax.semilogy(range(len(newton)), newton, "^-", label="Newton on the Coulomb problem: natural residual")
    ax.axhline(result.scene.contact.law.tol, color="k", ls=":", label="tol")
    ax.set_xlabel("Picard iteration" + (" / Newton step" if newton is not None else ""))
    ax.legend()
    method = "Newton's method" if newton is not None else "Picard map"
    ax.set_title(f"{result.scene.name}: {method} — {result.extra['picard']['outcome']}")
    fig.savefig(path, dpi=150, bbox_inches="tight")
    plt.close(fig)


def save_figure(fig, path) -> Path:
    """Write ``fig`` to ``path`` (creating its folder) and close it."""
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
