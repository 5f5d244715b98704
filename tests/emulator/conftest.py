"""Fixtures of the mount emulator tests."""

from __future__ import annotations

import pytest
from emulator_helpers import START_US

from mount_emulator.model import MountModel


@pytest.fixture
def mount() -> MountModel:
    """Return a mount at rest, drives off, az 0°, el 20°."""
    return MountModel(start_us=START_US)
