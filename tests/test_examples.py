"""The example scripts run and show what they claim (STYLE.md: examples are documentation)."""

import importlib.util
import itertools
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_signorini_hertz(tmp_path):
    result = example("signorini_hertz").main(nx=40, out=tmp_path)
    assert result.max_pressure == pytest.approx(0.054945, rel=0.03)
    assert (tmp_path / "contact.png").exists() and (tmp_path / "solution.vtu").exists()


def test_tresca_regularization(tmp_path):
    exact, rows = example("tresca_regularization").main(nx=24, out=tmp_path)
    errors = [error for _, error in rows]
    assert all(b < a for a, b in itertools.pairwise(errors))
    assert exact.certificate.passes(1e-8)


def test_coulomb_punch(tmp_path):
    result = example("coulomb_punch").main(h=0.01, out=tmp_path)
    assert result.extra["picard"]["outcome"] == "converged"
    assert (tmp_path / "picard.png").exists()


def test_nonlocal_coulomb(tmp_path):
    results = example("nonlocal_coulomb").main(h=0.01, out=tmp_path)
    assert all(r.status == "solved" for r in results.values())
    assert not np.allclose(results[0.04].contact.friction, results[0.0].contact.friction)


def test_cattaneo_mindlin_stick_zone(tmp_path):
    """Case 5: two-step loading with β = 0 gives c/a = sqrt(1 − Q/(F P)) within 5%."""
    result, stick_ratio = example("cattaneo_mindlin").main(h=0.01, ratio=0.5, out=tmp_path)
    assert result.extra["picard"]["outcome"] == "converged"
    assert result.certificate.passes(1e-6)
    assert result.tangential_force == pytest.approx(0.5 * 0.6 * result.normal_force, rel=1e-6)
    assert stick_ratio == pytest.approx(np.sqrt(0.5), rel=0.05)


def test_hertz_sphere(tmp_path):
    """3-D Hertz, 12³ graded cells: a and p₀ within 5%, the radial plot written, no 2-D mesh picture."""
    _, rows = example("hertz_sphere").main(cells=(12,), out=tmp_path)
    assert all(abs(error) < 0.05 for error in rows[0][2:6])
    assert (tmp_path / "contact.png").exists() and (tmp_path / "solution.vtu").exists()
    assert not (tmp_path / "deformed.png").exists()


def test_cattaneo_mindlin_cycle(tmp_path):
    """Issue 11 / case 5 as a history: the loading stick zone and, after pulling back, the reverse-slip annulus
    of Mindlin–Deresiewicz, each within one node spacing (h / a = 0.1) of the closed form."""
    result, measured, theory = example("cattaneo_mindlin_cycle").main(h=0.01, out=tmp_path)
    assert result.status == "solved"
    for name in theory:
        assert measured[name] == pytest.approx(theory[name], abs=0.1), name
    assert (result.steps[2].contact.status == "slip+").any()  # reverse slip, opposite to the loading slip
    assert (result.steps[1].contact.status == "slip-").any()
    assert (tmp_path / "solution.pvd").exists() and (tmp_path / "history.png").exists()
