"""``convexcontact bench --scenario plastic``: a plastic load step against one linear elastic solve (docs/plasticity.md).

The scene is Prandtl's flat punch of ``examples/plastic_punch.py`` (P2, elastic–perfectly plastic von Mises, a smooth
or, with ``--laws tresca``, rough punch) pushed in :data:`STEPS` steps from 1 to 8 times the depth at which the limit
force is reached elastically (each step 26 % deeper). The last step, at the limit load with its plastic zone grown
from the step before, is timed in one fresh process per size against one linear elastic solve on the same assembly
(K's factorization plus u = K⁻¹f), by three paths from the same state (the steps before solved by the fast path,
not timed):

- ``conic``: the step's conic program (Clarabel) finished by Newton (:class:`~convexcontact.drivers.plastic_history.
  PlasticStepper` with ``fast=False``);
- ``fast``: Newton from the last step, the conic program only as its fallback (the default of ``cc.run_history``);
- ``return mapping``: the classical baseline (:mod:`convexcontact.baselines.return_mapping`: radial return,
  consistent tangent, penalty contact c = :data:`PENALTY`), its step timed by itself; frictionless, so with
  ``--laws tresca`` it is not run (NaN in its columns).

Each path's time includes its formulation and its certificate; the ratios are step ÷ linear solve, and the fast path's
end-to-end ratio puts the assembly, which both pay, on both sides.
"""

from __future__ import annotations

import time

import numpy as np

HALF_WIDTH, YIELD_STRESS = 0.25, 1e-3
LIMIT_DEPTH = 2 * HALF_WIDTH * (2 + np.pi) * YIELD_STRESS / np.sqrt(3)
"""The depth at which the elastic body (E = 1) would carry Prandtl's limit force 2a(2 + π)k (per unit thickness)."""
STEPS = 10
DEPTHS = tuple(np.geomspace(1.0, 8.0, STEPS))
"""The steps' depths, in LIMIT_DEPTH; the last is timed."""
PENALTY = 1e5
"""The baseline's penalty (scaled, × E/L): its force within about 1e-7 of the exact one (docs/plasticity.md)."""
LAWS = ("signorini", "tresca")
COLUMNS = ("dofs", "points", "law", "assembly", "linear", "conic", "fast", "return_mapping", "conic_ratio", "fast_ratio",
           "return_mapping_ratio", "fast_end_to_end", "fast_path", "fast_newton_steps", "fallback", "conic_certificate",
           "fast_certificate", "fast_conic_difference", "return_mapping_newton_steps", "return_mapping_difference")


def cells(dofs: float) -> int:
    """The punch's nx for about ``dofs`` free DOFs (P2 on nx × nx/2 cells: 4 nx² DOFs), a multiple of 8 so that the
    punch's edges are nodes."""
    return max(8, 8 * round(np.sqrt(dofs / 4) / 8))


def punch_scene(dofs: float, law: str = "signorini"):
    """Prandtl's flat punch (examples/plastic_punch.py) at about ``dofs`` DOFs, :data:`STEPS` steps (:data:`DEPTHS`)."""
    import convexcontact as cc

    nx = cells(dofs)
    depths = [m * LIMIT_DEPTH for m in DEPTHS]
    contact_law = cc.Signorini() if law == "signorini" else cc.Tresca(slip_bound=YIELD_STRESS)
    return cc.Scene(
        name="prandtl", body=cc.Body(cc.Rectangle(2.0, 1.0, nx, nx // 2, origin=(-1.0, -1.0)), "P2"),
        materials=cc.Material(1.0, 0.3, yield_stress=YIELD_STRESS),
        dirichlet=(cc.Dirichlet("bottom", ux=0.0, uy=0.0), cc.Dirichlet("left", ux=0.0), cc.Dirichlet("right", ux=0.0)),
        contact=cc.Contact("top", cc.Obstacle("flat_punch", radius=HALF_WIDTH, depth=depths[-1]), contact_law),
        history=cc.History(list(range(1, STEPS + 1)), {"obstacle.depth": depths}))


def last_step(scene, solver: str, fast: bool):
    """The last step's result and seconds, solved by the fast path (``fast``) or the conic program; the steps before
    by the fast path, not timed."""
    from ...drivers.plastic_history import PlasticProcess, PlasticStepper

    process = PlasticProcess(scene, {})
    stepper = PlasticStepper(process, solver, {})
    for k in range(len(scene.history) - 1):
        result = stepper.solve(process.step_model(k, {}), process.key, {})
        if result.status != "solved":
            raise RuntimeError(f"step {k + 1} was not solved ({result.status}: {result.message})")
        process.advance(result)
    stepper.fast = fast
    start = time.perf_counter()
    result = stepper.solve(process.step_model(len(scene.history) - 1, {}), process.key, {})
    return result, time.perf_counter() - start, process.points.count


def measure(law: str, dofs: float, solver: str = "auto") -> dict:
    """One size (call it in a fresh process: :func:`~.bench.run`)."""
    from ...baselines.return_mapping import return_mapping_history
    from ...fem.assembly import assemble
    from ...fem.factorization import factorize

    scene = punch_scene(dofs, law)
    solver = "clarabel" if solver == "auto" else solver
    start = time.perf_counter()
    fem = assemble(scene.history.scene(scene, STEPS - 1))
    assembly = time.perf_counter() - start
    factorize(fem.K[:300, :300], dim=2).solve(fem.f[:300])  # the sparse solver's libraries loaded before timing
    start = time.perf_counter()
    factorize(fem.K, dim=2).solve(fem.f)
    linear = time.perf_counter() - start
    conic, conic_time, points = last_step(scene, solver, fast=False)
    fast, fast_time, _ = last_step(scene, solver, fast=True)
    baseline = return_mapping_history(scene, PENALTY) if law == "signorini" else None  # its penalty is frictionless
    seconds = baseline.seconds[-1] if baseline else float("nan")
    scale = np.abs(conic.displacement).max() if conic.displacement is not None else float("nan")
    return {
        "scenario": "plastic", "dim": 2, "dofs": fem.n_free, "points": points, "law": law, "assembly": assembly, "linear": linear,
        "conic": conic_time, "fast": fast_time, "return_mapping": seconds,
        "conic_ratio": conic_time / linear, "fast_ratio": fast_time / linear,
        "return_mapping_ratio": seconds / linear, "ratio": fast_time / linear,
        "fast_end_to_end": (assembly + fast_time) / (assembly + linear),
        "fast_path": fast.extra.get("path"), "fast_newton_steps": fast.extra.get("newton_steps"),
        "fallback": fast.extra.get("fallback", ""),
        "conic_status": conic.status, "fast_status": fast.status,
        "conic_certificate": conic.certificate.worst if conic.certificate is not None else float("nan"),
        "fast_certificate": fast.certificate.worst if fast.certificate is not None else float("nan"),
        "fast_conic_difference": float(np.abs(fast.displacement - conic.displacement).max() / scale)
        if fast.displacement is not None and conic.displacement is not None else float("nan"),
        "return_mapping_newton_steps": baseline.newton_steps[-1] if baseline else 0,
        "return_mapping_difference": float(np.abs(baseline.displacement[-1] - conic.displacement).max() / scale)
        if baseline and conic.displacement is not None else float("nan"),
    }


def format_row(row: dict) -> str:
    return (f"plastic {row['law']:>9} {row['dofs']:>8d} DOFs {row['points']:>7d} points  linear {row['linear']:6.2f} s  "
            f"conic {row['conic']:7.2f} s ({row['conic_ratio']:5.1f}×, {row['conic_status']}, certificate "
            f"{row['conic_certificate']:.1e})  fast {row['fast']:7.2f} s ({row['fast_ratio']:5.1f}×, {row['fast_path']}, "
            f"{row['fast_newton_steps']} Newton steps, {row['fast_status']}, certificate {row['fast_certificate']:.1e}"
            + (f", fallback: {row['fallback']}" if row["fallback"] else "") + ")  "
            f"return mapping {row['return_mapping']:7.2f} s ({row['return_mapping_ratio']:5.1f}×, "
            f"{row['return_mapping_newton_steps']} Newton steps)  fast end-to-end {row['fast_end_to_end']:.1f}×  |u_fast − u_conic| {row['fast_conic_difference']:.1e}, "
            f"|u_rm − u_conic| {row['return_mapping_difference']:.1e} (× max|u|)")


def check_arguments(args) -> None:
    """What the plastic punch is not built for, named by its option."""
    from ...drivers.plastic_history import CONIC_SOLVERS

    if args.dim != 2:
        raise ValueError("--dim: the plastic bench's punch is 2-D (plane strain); drop --dim 3")
    if set(args.laws) - set(LAWS):
        raise ValueError(f"--laws: {', '.join(sorted(set(args.laws) - set(LAWS)))} is not timed by the plastic bench "
                         "(it times one step by three paths; a Coulomb step is a Picard map of plastic Tresca steps, "
                         "measured in docs/plasticity.md); give --laws signorini tresca")
    if args.formulation not in ("auto", "primal"):
        raise ValueError(f"--formulation: {args.formulation!r}: plastic steps are posed in the primal only; "
                         "give --formulation primal or auto")
    if args.solver.partition(":")[0] not in CONIC_SOLVERS:
        raise ValueError(f"--solver: {args.solver!r} cannot take the plastic points' second-order cones; give "
                         "--solver clarabel (or auto)")
    if args.sweep:
        raise ValueError("--sweep: the friction sweep is Coulomb's; drop --sweep with --scenario plastic")
