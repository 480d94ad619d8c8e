"""Cross-validation of two solutions of the same scene.

Given a reference :class:`ContactResult` (e.g. the exact conic solve) and another
solution on the same mesh — a second result, a penalty baseline, or nodal arrays
imported from another code — report how far apart they are:

- ``energy_error``            ‖u − v‖_K / ‖u‖_K, K the reference's stiffness (Dirichlet DOFs included;
                              a seminorm: a difference by a rigid motion shows only in the L² error)
- ``l2_displacement_error``   ‖u − v‖_L² / ‖u‖_L², mass matrix of the FE basis
- ``pressure_l2_error``       ‖λ_N − μ_N‖ / ‖λ_N‖ in the contact weights w_i (Σ w_i e_i² ≈ ∫_Γc e²)
- ``pressure_max_error``      max |λ_N − μ_N| / max |λ_N|
- ``friction_l2_error``, ``friction_max_error``  the same for λ_T (when both have friction)
- ``contact_zone_difference`` size of the symmetric difference of the closed zones on Γ_C: Σ w_i over
                              the nodes open in one and closed in the other (a length in 2-D, an area
                              in 3-D; user units)
- ``stick_zone_difference``   the same for the stick zones (when both have stick / slip statuses)
- ``certificates``            {"reference": residuals, "other": residuals or None}
- ``not_unique``              {"reference": …, "other": …}: quantities either solution does not determine
                              (``ContactResult.not_unique``), present only when there are some: a
                              Coulomb answer may be one of several, so an error against it may be a
                              different solution rather than a wrong one

Every error is relative to the same norm of the reference field (L² to L², max to
max), so it does not depend on the units; a field that is zero in the reference gives
0 or inf. The zone differences are lengths in the user's units. A
key whose data are missing on either side (no displacement, no friction) is left
out of the report rather than set to a dummy value.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import skfem as fe
from skfem.helpers import dot

from ...results.result import CLOSED_PRESSURE, ContactResult

STATUSES = ("open", "closed", "stick", "slip+", "slip-")


@dataclass
class Fields:
    """A solution's fields in user units, comparable with a reference on the same mesh.

    ``displacement`` is the full DOF vector (None when unknown); ``pressure``,
    ``friction`` (None without friction) and ``status`` are arrays over the contact
    nodes, ordered as the reference's ``contact.coords``. ``residuals`` is the
    solution's certificate, when it has one.
    """

    displacement: np.ndarray | None
    pressure: np.ndarray
    friction: np.ndarray | None = None
    status: np.ndarray | None = None
    residuals: dict[str, float] | None = None
    not_unique: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        """Arrays as floats and strings; without a status the contact zone is read from the pressure.

        Closed where the pressure exceeds ``CLOSED_PRESSURE`` × its maximum, as for our own
        results; the stick zone is then unknown and not compared.
        """
        for name in ("pressure", "displacement", "friction"):
            values = getattr(self, name)
            if values is not None:
                setattr(self, name, numbers(values, name))
        if self.status is None:
            largest = self.pressure.max(initial=0.0)
            self.status = np.where((largest > 0) & (self.pressure > CLOSED_PRESSURE * largest), "closed", "open")
        self.status = np.asarray(self.status, dtype=str)

    @classmethod
    def from_result(cls, result: ContactResult, name: str = "result") -> Fields:
        if not isinstance(result, ContactResult):
            raise TypeError(f"{name}: expected a ContactResult, got {type(result).__name__}")
        if not result.solved:
            raise ValueError(f"{name}: the solve has no answer to compare (status {result.status!r})")
        c = result.contact
        residuals = None if result.certificate is None else dict(result.certificate.residuals)
        return cls(result.displacement, c.pressure, c.friction, c.status, residuals, dict(result.not_unique))

    @classmethod
    def from_arrays(
        cls, reference: ContactResult, *, pressure, displacement=None, friction=None, status=None
    ) -> Fields:
        """Fields imported from another code, checked against ``reference``'s mesh and contact nodes.

        ``displacement`` is the full DOF vector, the other arrays are nodal at the reference's
        contact nodes, all in user units; a length that does not match is a ValueError
        naming the argument.
        """
        fields = cls(displacement, pressure, friction, status)
        check(reference, fields, "")
        return fields

    @property
    def closed(self) -> np.ndarray:
        return self.status != "open"

    @property
    def has_stick_zone(self) -> bool:
        """Friction statuses (stick / slip±) rather than only open / closed."""
        return self.friction is not None and not np.any(self.status == "closed")


def numbers(values, name: str) -> np.ndarray:
    """``values`` as an array of floats, or a ValueError naming the argument."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: expected an array of numbers ({error})") from None


def check(reference: ContactResult, fields: Fields, prefix: str) -> None:
    """Lengths and values of ``fields`` against the reference's DOFs and contact nodes."""
    ndofs, m = reference.fem.basis.N, reference.fem.contact.m
    nodal = "give one value per contact node, ordered as reference.contact.coords"
    full = ("give the full DOF vector in user units "
            "(from free DOFs u: reference.fem.full(u) * reference.fem.scaling.displacement)")
    arrays = {"displacement": (fields.displacement, ndofs, full), "pressure": (fields.pressure, m, nodal),
              "friction": (fields.friction, m, nodal), "status": (fields.status, m, nodal)}
    for name, (values, size, fix) in arrays.items():
        if values is None:
            continue
        if values.shape != (size,):
            raise ValueError(f"{prefix}{name}: {values.size} values, the reference has {size} — {fix}")
        if name != "status" and not np.isfinite(values).all():
            raise ValueError(f"{prefix}{name}: contains NaN or infinity ({np.sum(~np.isfinite(values))} of {size} "
                             "values) — give the finite values of a solve that converged")
    unknown = set(fields.status.tolist()) - set(STATUSES)
    if unknown:
        raise ValueError(f"{prefix}status: unknown values {sorted(unknown)}; use {STATUSES}")


def relative(error: float, scale: float) -> float:
    """error / scale; 0 when both vanish, inf for an error against a zero reference."""
    if scale > 0:
        return float(error / scale)
    return 0.0 if error == 0 else float("inf")


def traction_errors(name: str, reference: np.ndarray, other: np.ndarray, weights: np.ndarray) -> dict[str, float]:
    """Relative L² (with the contact weights) and max errors of a nodal traction."""
    error = other - reference
    return {
        f"{name}_l2_error": relative(np.sqrt(weights @ error**2), np.sqrt(weights @ reference**2)),
        f"{name}_max_error": relative(np.abs(error).max(initial=0.0), np.abs(reference).max(initial=0.0)),
    }


def contact_errors(reference: Fields, other: Fields, weights: np.ndarray) -> dict:
    """Traction errors and zone differences at the contact nodes (``weights`` in user lengths)."""
    report = traction_errors("pressure", reference.pressure, other.pressure, weights)
    if reference.friction is not None and other.friction is not None:
        report.update(traction_errors("friction", reference.friction, other.friction, weights))
    report["contact_zone_difference"] = float(weights[reference.closed != other.closed].sum())
    if reference.has_stick_zone and other.has_stick_zone:
        report["stick_zone_difference"] = float(weights[(reference.status == "stick") != (other.status == "stick")].sum())
    return report


@fe.BilinearForm
def _mass(u, v, w):
    return dot(u, v)


def mass_matrix(fem):
    """The L² mass matrix of the model's vector basis, integrated exactly (scikit-fem's default order 2p: the
    model's own quadrature is chosen for the stiffness and would leave a P1 mass rank-deficient)."""
    return fe.asm(_mass, fe.Basis(fem.mesh, fem.basis.elem))


def compare(reference: ContactResult, other: Fields | ContactResult) -> dict:
    """Errors of ``other`` against ``reference`` on the same mesh (see the module docstring)."""
    ref = Fields.from_result(reference, "reference")
    if not isinstance(other, Fields):
        other = Fields.from_result(other, "other")
    check(reference, other, "other.")
    fem = reference.fem
    report = {}
    if other.displacement is not None:
        u = ref.displacement / fem.scaling.displacement
        error = other.displacement / fem.scaling.displacement - u
        for name, matrix in (("energy_error", fem.K_full), ("l2_displacement_error", mass_matrix(fem))):
            report[name] = relative(np.sqrt(max(error @ (matrix @ error), 0.0)), np.sqrt(max(u @ (matrix @ u), 0.0)))
    report.update(contact_errors(ref, other, fem.contact.weights * fem.scaling.length ** (fem.dim - 1)))
    return finish(report, ref, other)


def finish(report: dict, reference: Fields, other: Fields) -> dict:
    """The report with both certificates and, when either solution leaves some quantity undetermined, what."""
    report["certificates"] = {"reference": reference.residuals, "other": other.residuals}
    if reference.not_unique or other.not_unique:
        report["not_unique"] = {"reference": reference.not_unique, "other": other.not_unique}
    return report


def node_weights(nodes: dict, path: Path) -> np.ndarray:
    """The contact weights w_i (lengths in 2-D, areas in 3-D, user units) a summary stores; for summaries
    written before they were stored, the 2-D trapezoid weights of the node spacing along s. In 3-D s
    repeats along rows of nodes, so spacing weights would be wrong (they weighted 20 of 121 nodes)."""
    if "weight" in nodes:
        return np.asarray(nodes["weight"], float)
    if "z" in nodes or "s" not in nodes:
        raise ValueError(f"{path}: contact_nodes: no weight (the contact weights w_i); write the summary again "
                         "with this version")
    return spacing_weights(np.asarray(nodes["s"], float))


def spacing_weights(s: np.ndarray) -> np.ndarray:
    """Trapezoid weights of nodes at coordinates ``s``: half the distance between each node's neighbours."""
    order = np.argsort(s)
    sorted_s = s[order]
    edges = np.concatenate([[sorted_s[0]], (sorted_s[1:] + sorted_s[:-1]) / 2, [sorted_s[-1]]])
    weights = np.empty_like(s)
    weights[order] = np.diff(edges)
    return weights


SUMMARY_FIX = ("give the summary.json a run writes (convexcontact run SCENE --out DIR); to compare a scene with "
               "another code's output file, give the scene's .toml first")
NODE_NUMBERS = ("x", "y", "z", "s", "lambda_N", "lambda_T", "weight")


def read_summary(path) -> tuple[dict, dict]:
    """A summary.json's data and its ``contact_nodes``, checked: a ValueError starting with the path otherwise."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise ValueError(f"{path}: cannot read it ({error.strerror or error}); check the path") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a summary.json (not UTF-8 text); {SUMMARY_FIX}") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not a summary.json (no JSON: {error.msg} at line {error.lineno}, column "
                         f"{error.colno}); {SUMMARY_FIX}") from None
    if not isinstance(data, dict) or "contact_nodes" not in data:
        problem = (f"no contact_nodes (status {data.get('status')!r}): only a solved result can be compared"
                   if isinstance(data, dict) else f"not a summary.json (a JSON {type(data).__name__}, not an object)")
        raise ValueError(f"{path}: {problem}; {SUMMARY_FIX}")
    return data, check_nodes(data, path)


def check_nodes(data: dict, path: Path) -> dict:
    """``contact_nodes`` as arrays of one length: finite coordinates, pressures, frictions, weights; known statuses;
    a certificate of numbers and a not_unique of reasons, where given."""
    nodes = data["contact_nodes"]
    missing = [name for name in ("x", "y", "lambda_N", "status") if not isinstance(nodes, dict) or name not in nodes]
    if missing:
        raise ValueError(f"{path}: contact_nodes: no {', '.join(missing)}; {SUMMARY_FIX}")
    checked, count = {}, np.size(nodes["x"]) if isinstance(nodes["x"], list) else -1
    for name in (*NODE_NUMBERS, "status"):
        if name not in nodes:
            continue
        values = nodes[name]
        try:
            array = np.asarray(values, dtype=str if name == "status" else float)
        except (TypeError, ValueError):
            array = None
        if not isinstance(values, list) or array is None or array.shape != (count,) or count < 1:
            raise ValueError(f"{path}: contact_nodes.{name}: expected a list of {max(count, 1)} "
                             f"{'statuses' if name == 'status' else 'numbers'} (one per node, as contact_nodes.x), "
                             f"got {str(values)[:60]}; {SUMMARY_FIX}")
        if name != "status" and not np.isfinite(array).all():
            raise ValueError(f"{path}: contact_nodes.{name}: NaN or infinite at {np.sum(~np.isfinite(array))} of "
                             f"{count} nodes; a solved result's fields are finite: write the summary again")
        checked[name] = array
    unknown = sorted(set(checked["status"].tolist()) - set(STATUSES))
    if unknown:
        raise ValueError(f"{path}: contact_nodes.status: unknown values {unknown[:5]}; expected {STATUSES}")
    for name, kind in (("certificate", (int, float)), ("not_unique", str)):
        entries = data.get(name, {})
        if not isinstance(entries, dict) or not all(isinstance(v, kind) for v in entries.values()):
            raise ValueError(f"{path}: {name}: expected an object of {'reasons' if kind is str else 'numbers'}, got "
                             f"{str(entries)[:60]}; {SUMMARY_FIX}")
    return checked


def compare_files(a: Path, b: Path) -> dict:
    """Compare the contact-node fields of two ``summary.json`` files (``a`` is the reference).

    The files hold no displacement field, so the errors are those of the contact-node fields, weighted
    by the contact weights w_i = ∫ψ_i the files store (older 2-D files: the trapezoid weights of the
    node spacing). Both files must have the same contact nodes (x, y and, in 3-D, z).
    """
    (data_a, nodes_a), (data_b, nodes_b) = read_summary(a), read_summary(b)
    xy_a, xy_b = (np.column_stack([n[axis] for axis in "xyz" if axis in n]) for n in (nodes_a, nodes_b))
    extent = np.ptp(xy_a, axis=0).max(initial=0.0)
    if xy_a.shape != xy_b.shape or not np.allclose(xy_a, xy_b, rtol=0, atol=1e-9 * extent):
        dims = f", {xy_b.shape[1]}-D against {xy_a.shape[1]}-D" if xy_a.shape[1] != xy_b.shape[1] else ""
        raise ValueError(
            f"{b}: its {len(xy_b)} contact nodes are not those of {a} ({len(xy_a)} nodes{dims}) — "
            "compare_files needs two solutions on the same mesh and contact boundary"
        )

    def fields(nodes, data):
        residuals = {k: v for k, v in data["certificate"].items() if k != "worst"} if "certificate" in data else None
        return Fields(None, nodes["lambda_N"], nodes.get("lambda_T"), nodes["status"], residuals,
                      data.get("not_unique", {}))

    reference, other = fields(nodes_a, data_a), fields(nodes_b, data_b)
    report = contact_errors(reference, other, node_weights(nodes_a, a))
    return finish(report, reference, other)


def format_report(report: dict) -> str:
    """The report as an aligned text table, then the two certificates side by side."""
    values = {k: v for k, v in report.items() if isinstance(v, (int, float))}
    width = max(map(len, values), default=0) + 2
    lines = [f"{'quantity':<{width}}value"] + [f"{k:<{width}}{v:.3e}" for k, v in values.items()]
    for name in ("fields", "normal_force"):  # a peer's report: which fields were read, both resultants
        if name in report:
            lines.append(f"{name}: " + ", ".join(f"{k} {v:.6g}" if isinstance(v, float) else f"{k} {v!r}"
                                                  for k, v in report[name].items()))
    certificates = report.get("certificates")
    if certificates:
        ref, other = certificates.get("reference") or {}, certificates.get("other") or {}
        names = list(dict.fromkeys([*ref, *other]))
        width = max(map(len, names), default=0) + 2

        def cell(residuals, name):
            return f"{residuals[name]:<12.3e}" if name in residuals else f"{'—':<12}"

        lines += ["", f"{'certificate':<{width}}{'reference':<12}other"]
        lines += [f"{n:<{width}}{cell(ref, n)}{cell(other, n)}".rstrip() for n in names]
    for side, reasons in report.get("not_unique", {}).items():
        lines += [""] + [f"not unique in the {side}: {name} — {why}" for name, why in reasons.items()]
    return "\n".join(lines)
