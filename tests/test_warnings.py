"""The test run's warning policy (pyproject.toml, filterwarnings): a warning of the project's own code, or a
deprecation it meets in a library, fails the test that caused it; the third-party warnings filtered are named."""

import warnings

import numpy as np
import pytest


@pytest.mark.parametrize("category", [UserWarning, RuntimeWarning, DeprecationWarning])
def test_a_warning_of_the_project_fails_the_run(category):
    with pytest.raises(category):
        warnings.warn_explicit("a warning", category, "convexcontact/fem/assembly.py", 1,
                               module="convexcontact.fem.assembly")


def test_a_deprecation_met_in_a_library_fails_the_run():
    """Attributed to the library's line (no stacklevel), as scikit-fem's, OSQP's and cvxpy's are."""
    with pytest.raises(PendingDeprecationWarning):
        warnings.warn_explicit("The default value of raise_error will change to True in the future.",
                               PendingDeprecationWarning, "osqp/interface.py", 405, module="osqp.interface")


def test_a_numpy_overflow_in_the_projects_code_fails_the_run():
    """numpy attributes its floating-point RuntimeWarnings to the line that computed: here, a module of ours."""
    code = compile("np.float64(1e200) * np.float64(1e200)", "convexcontact/fem/assembly.py", "eval")
    with pytest.raises(RuntimeWarning, match="overflow"):
        eval(code, {"np": np, "__name__": "convexcontact.fem.assembly"})


def test_osqp_solves_without_a_warning():
    """OSQP is told raise_error=False (a failure is read from its status), so it does not warn that the default will
    change. (cvxpy's "Solution may be inaccurate" is silenced where the status is read; test_3d's Coulomb stick zone
    meets it under this run's filters.)"""
    import convexcontact as cc

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cc.solve(cc.library.pressure_patch(nx=3), "osqp").solved
