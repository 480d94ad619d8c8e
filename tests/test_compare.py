"""Cross-validation of two solutions: self-comparison, known perturbations, penalty convergence, files."""

import dataclasses

import numpy as np
import pytest

import convexcontact as cc
from convexcontact.baselines import penalty_signorini
from convexcontact.scene.library import hertz_punch
from convexcontact.studies.crossvalidation.compare import Fields, compare, compare_files, format_report, mass_matrix

ERRORS = ("energy_error", "l2_displacement_error", "pressure_l2_error", "pressure_max_error")


@pytest.fixture(scope="module")
def indented():
    """Exact Signorini answer of the Hertz block pressed in by depth 0.02 (displacement control, 5 closed nodes)."""
    scene = dataclasses.replace(
        hertz_punch(nx=24), contact=cc.Contact("top", cc.Obstacle("parabolic", radius=1.0, depth=0.02))
    )
    result = cc.solve(scene)
    assert result.status == "solved"
    return result


@pytest.fixture(scope="module")
def tresca():
    """Hertz block under force control with a Tresca bound: stick and slip nodes, nonzero friction."""
    result = cc.solve(hertz_punch(nx=24, law=cc.Tresca(slip_bound=0.01)))
    assert result.status == "solved"
    assert {"stick", "slip+", "slip-"} <= set(result.contact.status)
    return result


def perturbed(result, factor=1.0, status=None):
    """The result's fields with displacement and tractions multiplied by ``factor``."""
    c = result.contact
    friction = None if c.friction is None else factor * c.friction
    return Fields(factor * result.displacement, factor * c.pressure, friction,
                  c.status if status is None else status)


def test_a_result_against_itself_has_no_error(indented, tresca):
    for result in (indented, tresca):
        report = compare(result, result)
        errors = {k: v for k, v in report.items() if k != "certificates"}
        assert all(value == 0.0 for value in errors.values()), errors
        assert set(ERRORS) <= set(errors) and "contact_zone_difference" in errors
        assert report["certificates"]["reference"] == report["certificates"]["other"] == result.certificate.residuals
    assert {"friction_l2_error", "friction_max_error", "stick_zone_difference"} <= set(compare(tresca, tresca))
    assert "friction_max_error" not in compare(indented, indented)


def test_a_one_percent_scaling_is_a_one_percent_error(tresca):
    """Every relative error of (1.01 u, 1.01 λ_N, 1.01 λ_T) against (u, λ_N, λ_T) is 0.01; the zones agree."""
    report = compare(tresca, perturbed(tresca, 1.01))
    for name in (*ERRORS, "friction_l2_error", "friction_max_error"):
        assert report[name] == pytest.approx(0.01, rel=1e-12), name
    assert report["contact_zone_difference"] == report["stick_zone_difference"] == 0.0
    assert report["certificates"]["other"] is None


def test_zone_differences_are_the_weights_of_the_nodes_that_differ(tresca):
    """Opening one closed node and letting one stick node slip: the zones differ by their w_i (user units)."""
    status = tresca.contact.status.copy()
    stick = np.flatnonzero(status == "stick")
    status[stick[0]] = "open"
    status[stick[1]] = "slip+"
    report = compare(tresca, perturbed(tresca, status=status))
    weights = tresca.fem.contact.weights * tresca.fem.scaling.length
    assert report["contact_zone_difference"] == pytest.approx(weights[stick[0]], rel=1e-14)
    assert report["stick_zone_difference"] == pytest.approx(weights[stick[:2]].sum(), rel=1e-14)


def test_penalty_error_falls_tenfold_per_decade_of_penalty(indented):
    """DESIGN.md case 6: the penalty solution tends to the exact one like 1/c, for every measure."""
    fem = indented.fem
    reports = []
    for penalty in (1e4, 1e5):
        baseline = penalty_signorini(fem.K, fem.f, fem.contact, penalty)
        assert baseline.converged
        imported = Fields.from_arrays(
            indented,
            displacement=fem.full(baseline.u) * fem.scaling.displacement,
            pressure=baseline.pressure * fem.scaling.pressure,
        )
        reports.append(compare(indented, imported))
    coarse, fine = reports
    for name in ERRORS:
        assert 1e-6 < fine[name] < coarse[name] < 1e-2, name
        assert coarse[name] / fine[name] == pytest.approx(10.0, rel=0.05), name
    assert coarse["contact_zone_difference"] == fine["contact_zone_difference"] == 0.0  # same active set here


def test_arrays_of_the_wrong_length_name_the_argument(indented):
    m = indented.fem.contact.m
    with pytest.raises(ValueError, match=rf"^pressure: {m - 1} values, the reference has {m} "):
        Fields.from_arrays(indented, pressure=np.ones(m - 1))
    with pytest.raises(ValueError, match=r"^friction: "):
        Fields.from_arrays(indented, pressure=np.ones(m), friction=np.ones(m + 1))
    with pytest.raises(ValueError, match=r"^displacement: .*full DOF vector"):
        Fields.from_arrays(indented, pressure=np.ones(m), displacement=np.ones(indented.fem.n_free))
    with pytest.raises(ValueError, match=r"^status: unknown values \['touching'\]"):
        Fields.from_arrays(indented, pressure=np.ones(m), status=np.full(m, "touching"))
    other_mesh = cc.solve(hertz_punch(nx=16))
    with pytest.raises(ValueError, match=r"^other\.displacement: "):
        compare(indented, other_mesh)


def test_imported_pressure_alone_gives_the_contact_zone(indented):
    """Without a status, nodes carrying pressure are closed, as in our own results."""
    imported = Fields.from_arrays(indented, pressure=indented.contact.pressure)
    report = compare(indented, imported)
    assert report["pressure_max_error"] == 0.0 and report["contact_zone_difference"] == 0.0
    assert "energy_error" not in report
    assert "pressure_max_error" in format_report(report)


def test_compare_files_matches_the_in_memory_comparison(tmp_path, tresca):
    """Two summary.json files of the same mesh: P1 on a flat Γ_C, so the spacing weights are the exact w_i."""
    other = cc.solve(hertz_punch(nx=24, law=cc.Tresca(slip_bound=0.012)))
    tresca.save(tmp_path / "a", formats=("json",))
    other.save(tmp_path / "b", formats=("json",))
    from_files = compare_files(tmp_path / "a" / "summary.json", tmp_path / "b" / "summary.json")
    in_memory = compare(tresca, other)
    assert from_files.keys() == in_memory.keys() - {"energy_error", "l2_displacement_error"}
    for name, value in from_files.items():
        if name == "certificates":
            assert value == {"reference": tresca.certificate.residuals, "other": other.certificate.residuals}
        else:
            assert value == pytest.approx(in_memory[name], rel=1e-10, abs=1e-15), name
    assert from_files["friction_max_error"] > 0.01
    table = format_report(from_files)
    assert "stick_zone_difference" in table and "friction_law" in table

    cc.solve(hertz_punch(nx=16)).save(tmp_path / "c", formats=("json",))
    with pytest.raises(ValueError, match="not those of"):
        compare_files(tmp_path / "a" / "summary.json", tmp_path / "c" / "summary.json")


def test_a_coulomb_answer_is_reported_as_possibly_one_of_several(tmp_path):
    """Coulomb fixed points are not proven unique: the report (in memory, from files, as a table) says so."""
    coulomb = cc.solve(hertz_punch(nx=16, law=cc.Coulomb(friction=0.2)))
    frictionless = cc.solve(hertz_punch(nx=16))
    report = compare(coulomb, frictionless)
    assert "solution" in report["not_unique"]["reference"] and report["not_unique"]["other"] == {}
    assert "not_unique" not in compare(frictionless, frictionless)
    coulomb.save(tmp_path / "a", formats=("json",))
    frictionless.save(tmp_path / "b", formats=("json",))
    from_files = compare_files(tmp_path / "a" / "summary.json", tmp_path / "b" / "summary.json")
    assert from_files["not_unique"] == report["not_unique"]
    assert "not unique in the reference: solution" in format_report(from_files)


def test_compare_files_weighs_3d_nodes_by_their_areas(tmp_path):
    """3-D summaries: every node weighted by its contact area (the spacing along s, which repeats along rows,
    weighted 20 of 121 nodes and reported 0), zones as areas, and x, y, z all matched."""
    from convexcontact.scene.library import punch_3d

    exact = cc.solve(punch_3d(4))
    shifted = cc.solve(punch_3d(4, depth=0.03))
    exact.save(tmp_path / "a", formats=("json",))
    shifted.save(tmp_path / "b", formats=("json",))
    from_files = compare_files(tmp_path / "a" / "summary.json", tmp_path / "b" / "summary.json")
    in_memory = compare(exact, shifted)
    for name in ("pressure_l2_error", "contact_zone_difference"):
        assert from_files[name] == pytest.approx(in_memory[name], rel=1e-10), name
    assert from_files["pressure_l2_error"] > 0.01 and from_files["contact_zone_difference"] > 0
    fem = exact.fem
    areas = fem.contact.weights * fem.scaling.length**2
    assert from_files["contact_zone_difference"] == pytest.approx(areas[exact.closed != shifted.closed].sum())


def test_the_l2_error_integrates_the_mass_exactly(indented):
    """The displacement error's L² norm uses the exact mass (the model's P1 quadrature has one point, which
    would leave it singular): positive definite, and a unit translation's mass is the body's area."""
    fem = indented.fem
    mass = mass_matrix(fem).toarray()
    assert np.linalg.eigvalsh(mass).min() > 0
    translation = np.zeros(fem.basis.N)
    translation[fem.basis.nodal_dofs[0]] = 1.0
    area = np.ptp(fem.mesh.p[0]) * np.ptp(fem.mesh.p[1])  # the Hertz block is a rectangle
    assert translation @ mass @ translation == pytest.approx(area, rel=1e-12)
