"""Shared settings of the ASTCom tests: a fast hypothesis profile."""

from hypothesis import HealthCheck, settings

settings.register_profile(
    "astcom",
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile("astcom")
