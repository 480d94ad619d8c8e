"""A law's coefficients against the scales of the assembled problem: refused where the solve cannot resolve them.

The dataclasses check what a number means alone (finite, signs, ranges); what it means beside the body's size,
stiffness and load is known once the scene is assembled, and checked here, before any program is built.
"""

from __future__ import annotations

import numpy as np

from ..fem.assembly import MIN_STRAIN
from ..fem.contact import gap_field
from ..scene.description import SceneError, compliance_of

TRACTION_RANGE = 1e6
"""Largest slip bound (or initial pressure), in units of the data's pressure scale, and largest friction coefficient:
tractions are of the load's order, so a bound or coefficient far beyond it holds every touching point (a bonded
contact) and only takes the solvers past their precision — measured on the 3 × 3 patch: F = 10⁶ solved (certificate
5e-11), 10⁹ inaccurate (2e-7), 10¹² failed; a slip bound of 10¹³ × the pressure was reported unbounded."""

COMPLIANCE_RANGE = (1e-8, 1e16)
"""Normal compliance c_N in units of the body's stiffness (c_N u^p / p of the scales, the penalty over E/L): below,
the contact's deflection swamps the body's and the solve loses it (10⁻⁹ left a certificate of 6e-6, 10⁻¹² of 0.3);
above, the body's stiffness is below round-off beside the penalty (10³⁰⁰ gave a certificate of 10²⁶⁹)."""

GAP_RANGE = 1e13
"""Largest gap at a contact node, in units of the displacement the loads make: the programs carry the gap beside the
displacements and lose them beyond (a parabolic punch of radius 1e-10 on the 4 × 2 Hertz block, gaps up to 2e12 of
the displacement scale: solved; radius 1e-12, 2e14: inaccurate with certificate 0.9 on the dual, failed on the
primal). A node that far never touches."""


def check_force(fem) -> None:
    """Refuse an obstacle force too small for the solve to resolve beside the body's stiffness (P = 1e-13 on the
    Hertz block, E = 1, was reported infeasible): below the smallest strain the assembly's scales resolve."""
    force, scaling = fem.scene.contact.obstacle.force, fem.scaling
    stiffness = scaling.stress * scaling.length ** (scaling.dim - 1)  # E L^(d−1): a force of unit strain
    if force is not None and 0 < force < MIN_STRAIN * stiffness:
        raise SceneError("obstacle.force", f"{force:.3g} is {force / stiffness:.1e} of E·L^(d−1) = "
                         f"{stiffness:.3g}, below the strain {MIN_STRAIN:g} a solve resolves",
                         f"give 0 (the obstacle just touching) or at least {MIN_STRAIN * stiffness:.3g}")


def check_gap_scale(fem) -> None:
    """Refuse an obstacle whose gap at some node is beyond :data:`GAP_RANGE` of the displacement scale."""
    gap, displacement = np.abs(fem.contact.gap), fem.scaling.displacement
    if gap.max(initial=0.0) > GAP_RANGE:
        node = int(np.argmax(gap))
        at = np.round(fem.contact.coords[node] * fem.scaling.length, 12).tolist()
        raise SceneError(gap_field(fem.scene.contact.obstacle), f"the gap at {at} on Γ_C is "
                         f"{gap[node] * displacement:.3g}, {gap[node]:.1e} times the displacements the loads make "
                         f"({displacement:.3g}): the solvers lose it", "give a radius, centre, gap or depth on the "
                         "scale of the body and its loads (a node that far never touches: cut Γ_C, or use flat_punch)")


def check_law_scales(fem, law, fields: dict[str, np.ndarray], compliance: tuple[float, float] | None) -> None:
    """Refuse a coefficient of ``law`` the assembled problem ``fem`` cannot resolve, naming it, its scale and the
    range. ``fields``: the law's fields at the friction points by name (``slip_bound`` and ``initial_pressure``
    scaled by the pressure, ``friction`` as it is); ``compliance``: (c_N, p) scaled."""
    scaling = fem.scaling
    if compliance is not None:
        check_compliance(law, compliance, scaling)
    for name, values in fields.items():
        # a traction bound against E, not against the load: a scene whose loads are tiny (a Dirichlet value of
        # 1e-118, a punch that barely touches) with a bound of the body's stress scale is a bonded contact the
        # solvers answer (the fuzz suite's long profile), while 10⁶ E is beyond any stress of linear elasticity
        unit = 1.0 if name == "friction" else scaling.stress / scaling.pressure
        largest, pressure = values.max(initial=0.0) / unit, unit * (1.0 if name == "friction" else scaling.pressure)
        if largest > TRACTION_RANGE:
            times = "" if name == "friction" else f", {largest:.1e} times E"
            raise SceneError(f"contact.{name}", f"up to {largest * pressure:.3g}{times}",
                             f"beyond {TRACTION_RANGE:g}{times and ' times that'} every touching point already "
                             f"sticks and the solvers lose the scale: give at most {TRACTION_RANGE * pressure:.3g} "
                             "(a bonded contact)")
    length = f"the body's size L = {scaling.length:.3g}"
    regularization = getattr(law, "regularization", None)
    if regularization is not None and regularization > scaling.length:
        raise SceneError("contact.regularization", f"ε = {regularization:.3g} exceeds {length}: it smooths away "
                         "the friction it regularizes", "give ε well below the slips you expect (e.g. 1e-6 L)")
    if getattr(law, "smoothing_radius", 0.0) > scaling.length:
        raise SceneError("contact.smoothing_radius", f"ρ = {law.smoothing_radius:.3g} exceeds {length}: a "
                         "roughness length averages the pressure near a point, not over the whole body",
                         "give ρ ≤ L, e.g. a few element sizes")


def check_compliance(law, compliance: tuple[float, float], scaling) -> None:
    """The scaled compliance (c_N u^p / p of the scales) a float, and within :data:`COMPLIANCE_RANGE`."""
    scaled, exponent = compliance
    if not 0 < scaled < np.inf:
        raise SceneError("contact.exponent", f"p = {exponent:g} takes u^p of the load's displacement scale u = "
                         f"{scaling.displacement:.3g} beyond the floats",
                         "give a contact law's exponent, 1 ≤ p ≤ 4 or so")
    if not COMPLIANCE_RANGE[0] <= scaled <= COMPLIANCE_RANGE[1]:
        c_N = compliance_of(law).stiffness
        low, high = (bound * c_N / scaled for bound in COMPLIANCE_RANGE)
        raise SceneError("contact.stiffness", f"c_N = {c_N:.3g} is {scaled:.1e} times the body's stiffness (E/L at "
                         f"these loads), outside the {COMPLIANCE_RANGE[0]:g} to {COMPLIANCE_RANGE[1]:g} a solve "
                         f"resolves", f"give c_N between {low:.3g} and {high:.3g}, or Signorini() for a contact "
                         "stiffer than that")
