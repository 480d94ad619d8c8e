"""The traces as they were before symmetry planes were found, for the checks of the solvers' mechanisms made on them."""

import numpy as np


def without_symmetry_planes(monkeypatch) -> None:
    """:func:`~convexcontact.fem.contact.symmetry_planes` finding none: a quarter model's nodes on its planes keep
    their one-sided normals and the friction rows along the planes' normals that act on almost nothing — the near-null
    rows newton-cg's damping, inert sets, HELD and STEP_SPREAD were made on, and which a roller that is no symmetry
    plane still makes."""
    from convexcontact.fem import contact, mortar

    def none(mesh, basis, dofs, *rest):
        return np.zeros(dofs.shape, bool)

    for module in (contact, mortar):
        monkeypatch.setattr(module, "symmetry_planes", none)
