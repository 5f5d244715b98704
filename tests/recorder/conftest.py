"""Fixtures of the recorder tests."""

from __future__ import annotations

import socket
import subprocess
import sys
import time

import pytest
from recorder_helpers import InfluxServer, free_port, require_influxd


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


@pytest.fixture(scope="module")
def device_url():
    """Serve the example device (1 kHz, real time) on a loopback TCP port."""
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "astcom_client.example_device",
                             f"tcp://127.0.0.1:{port}", "--duration", "60"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            assert time.monotonic() < deadline and proc.poll() is None, "device did not start"
            time.sleep(0.05)
    yield f"tcp://127.0.0.1:{port}"
    proc.terminate()
    proc.wait(10)
