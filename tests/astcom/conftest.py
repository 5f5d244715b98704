"""Shared settings of the ASTCom tests: a modest hypothesis profile.

The profile is registered here and applied per test (`@settings.get_profile("astcom")`)
rather than loaded globally, so it does not change other packages' property tests.
Tests parametrised with a C device implementation (`impl` in C_IMPLS) get the device built
in their setup, outside the test's own time budget.
"""

import pytest
from device_impls import C_IMPLS, build_device
from hypothesis import HealthCheck, settings

settings.register_profile(
    "astcom",
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    callspec = getattr(item, "callspec", None)
    if callspec is not None and callspec.params.get("impl") in C_IMPLS:
        build_device("asan")
