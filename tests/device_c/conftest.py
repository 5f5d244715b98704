"""The C device's own tests (astcom_device/): its processes and builds come from
tests/astcom/device_impls.py; each build is made in a fixture, outside any test's budget."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "astcom"))

from device_impls import build_device  # noqa: E402


@pytest.fixture(scope="session")
def asan_device() -> None:
    """The sanitizer build (ASan + UBSan) of the example controller."""
    build_device("asan")


@pytest.fixture(scope="session")
def host_device() -> None:
    """The optimised build of the example controller (-O2), for real-time work."""
    build_device("host")
