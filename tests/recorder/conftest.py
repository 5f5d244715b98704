"""Fixtures of the recorder tests."""

from __future__ import annotations

import pytest
from recorder_helpers import InfluxServer, require_influxd


@pytest.fixture
def influx(tmp_path):
    """Start a real influxd on loopback ports for one test; stop it afterwards."""
    require_influxd()
    server = InfluxServer(tmp_path / "influx")
    server.start()
    try:
        yield server
    finally:
        server.stop()
