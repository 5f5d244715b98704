"""Shared settings of the ASTCom tests: a modest hypothesis profile.

The profile is registered here and applied per test (`@settings.get_profile("astcom")`)
rather than loaded globally, so it does not change other packages' property tests.
"""

from hypothesis import HealthCheck, settings

settings.register_profile(
    "astcom",
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
