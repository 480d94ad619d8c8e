"""Hypothesis profiles: ``ci`` (the default, a few derandomized examples) and ``long``
(``python -m pytest tests/test_fuzz.py --hypothesis-profile=long``)."""

from hypothesis import HealthCheck, settings

settings.register_profile("ci", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")

