"""Hypothesis profiles: ``ci`` (the default, a few derandomized examples) and ``long``
(``python -m pytest tests/test_fuzz.py --hypothesis-profile=long``); the fixture ``no_symmetry_planes``."""

import pytest
from former_trace import without_symmetry_planes
from hypothesis import HealthCheck, settings

settings.register_profile("ci", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")


@pytest.fixture
def no_symmetry_planes(monkeypatch):
    """:func:`former_trace.without_symmetry_planes` for the whole test."""
    without_symmetry_planes(monkeypatch)
