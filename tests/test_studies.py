"""Work-precision study and parameter sweeps (convexcontact.studies.precision.work_precision, .sweeps)."""

import math

import numpy as np
import pytest

from convexcontact.scene.library import hertz_punch, tresca_punch
from convexcontact.studies.crossvalidation import sweeps
from convexcontact.studies.precision import work_precision as wp


@pytest.fixture(scope="module")
def rows():
    lines = []
    found = wp.run(hertz_punch(nx=16), tolerances=(1e-4, 1e-8), progress=lines.append)
    assert len(lines) == len(found) and lines[-1].startswith(f"[{len(found)}/{len(found)}]")
    return found


def test_every_row_has_status_time_and_the_closed_form_reference(rows):
    assert {r["method"] for r in rows} == {"exact", "penalty"}  # frictionless: no ε rows
    for r in rows:
        assert r["status"] and r["reference"] == "closed form"
        if r["status"] == "n/a":
            assert r["message"] and r["time"] is None
        else:
            assert r["time"] > 0
    skipped = [r for r in rows if r["status"] == "n/a"]
    assert skipped and all(r["formulation"] == "dual" and r["method"] == "penalty" for r in skipped)


def test_pareto_front_is_non_dominated(rows):
    front = wp.pareto(rows)
    assert front
    for f in front:
        assert not any(r["time"] < f["time"] and r["error"] < f["error"] for r in wp.measured(rows))
    assert "*" in wp.table(rows)


def test_exact_clarabel_error_does_not_grow_with_tighter_tol(rows):
    exact = {r["tol"]: r["error"] for r in rows
             if (r["method"], r["formulation"], r["solver"]) == ("exact", "primal", "clarabel")}
    loose, tight = exact[1e-4], exact[1e-8]
    assert tight < loose or math.isclose(tight, loose, rel_tol=1e-3)  # or the discretization floor


def test_csv_round_trip(rows, tmp_path):
    back = wp.read_csv(wp.write_csv(rows, tmp_path / "wp.csv"))
    assert len(back) == len(rows)
    for a, b in zip(rows, back):
        for key in wp.FIELDS:
            if isinstance(a[key], float):
                assert b[key] == pytest.approx(a[key], rel=1e-12)
            else:
                assert b[key] == a[key] or (a[key] is None and b[key] is None)


def test_plot_writes_a_png(rows, tmp_path):
    assert wp.plot(rows, tmp_path / "wp.png").stat().st_size > 1000


def test_overkill_reference_and_regularized_rows():
    """A friction scene has no closed form: the reference is an overkill exact solve; OSQP refuses ε (3-D SOC)."""
    found = wp.run(tresca_punch(nx=12), tolerances=(1e-8,), progress=None, formulations=("primal",),
                   solvers=("clarabel", "osqp"))
    assert all(r["reference"].startswith("overkill") for r in found)
    regularized = [r for r in found if r["method"] == "regularized"]
    assert len(regularized) == 2 * len(wp.EPSILON_FACTORS)
    assert all(r["status"] == "n/a" for r in regularized if r["solver"] == "osqp")
    errors = [r["error"] for r in regularized if r["solver"] == "clarabel"]
    assert errors == sorted(errors, reverse=True)  # smaller ε, closer to the exact law
    exact = [r for r in found if r["method"] == "exact" and r["solver"] == "clarabel"]
    assert exact[0]["error"] < 1e-6


def test_penalty_sweep_slope_is_minus_one(tmp_path):
    sweep = sweeps.penalty_sweep(hertz_punch(nx=16), stiffness=np.logspace(3, 6, 4))
    assert all(r["status"] == "solved" for r in sweep.rows)
    assert sweep.slope == pytest.approx(-1.0, rel=0.2)
    assert sweeps.plot_sweep(sweep, tmp_path / "penalty.png").exists()


def test_regularization_sweep_slope_is_plus_one():
    """ε = 1e-5 … 1e-7, small against the largest slip (~1e-4): the asymptotic range."""
    sweep = sweeps.regularization_sweep(tresca_punch(nx=16), epsilon=np.logspace(-5, -7, 3))
    assert sweep.slope == pytest.approx(1.0, rel=0.2)
