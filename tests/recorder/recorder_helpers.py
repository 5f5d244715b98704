"""Helpers of the recorder tests: a simulated-time device behind an in-memory Endpoint,
and a real `influxd` on loopback ports with its data in a temporary directory."""

from __future__ import annotations

import asyncio
import shutil
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest

from astcom_client import Client, Endpoint, EndpointConfig
from astcom_client.example_device import ExampleDevice

START_US = 1_772_398_740_000_000  # 2026-03-01T20:59:00Z: a minute before an hour boundary


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SimDevice:
    """An ExampleDevice whose ticks we compute on demand (simulated time), in memory."""

    def __init__(self, *, loop_rate_hz: float = 1000.0, n_extra: int = 0,
                 start_us: int = START_US, **config) -> None:
        self.device = ExampleDevice(loop_rate_hz=loop_rate_hz, n_extra_signals=n_extra,
                                    start_t_us=start_us)
        self.endpoint = Endpoint(self.device.collection,
                                 EndpointConfig(loop_rate_hz=loop_rate_hz, **config))
        self.transports = []

    async def connect(self) -> Client:
        transport = self.endpoint.connect_in_memory(maxsize=256)
        self.transports.append(transport)  # a test may cut a connection by closing it
        return await Client.open(transport, queue_packets=65_536)

    def advance(self, n_ticks: int) -> None:
        self.device.advance(self.endpoint, n_ticks)


async def settle(rounds: int = 50) -> None:
    """Let the endpoint's writer and the client's reader tasks run."""
    for _ in range(rounds):
        await asyncio.sleep(0)


INFLUX_CONFIG = """\
reporting-disabled = true
bind-address = "127.0.0.1:{rpc_port}"

[meta]
  dir = "{root}/meta"
  logging-enabled = false

[data]
  dir = "{root}/data"
  wal-dir = "{root}/wal"
  query-log-enabled = false
  trace-logging-enabled = false

[http]
  enabled = true
  bind-address = "127.0.0.1:{http_port}"
  log-enabled = false
  auth-enabled = false

[monitor]
  store-enabled = false

[continuous_queries]
  enabled = false

[subscriber]
  enabled = false
"""


class InfluxServer:
    """A real influxd with a temporary config, data, meta and WAL directories."""

    def __init__(self, root: Path) -> None:
        self.root = root
        root.mkdir(parents=True, exist_ok=True)
        self.http_port = free_port()
        self.rpc_port = free_port()
        self.config = root / "influxdb.conf"
        self.config.write_text(INFLUX_CONFIG.format(root=root, rpc_port=self.rpc_port,
                                                    http_port=self.http_port))
        self.proc: subprocess.Popen | None = None
        self.log = root / "influxd.log"

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.http_port}"

    def start(self, timeout_s: float = 20.0) -> None:
        with self.log.open("ab") as log:
            self.proc = subprocess.Popen([shutil.which("influxd") or "influxd", "-config",
                                          str(self.config)], stdout=log, stderr=log)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"influxd exited: {self.log.read_text()[-2000:]}")
            try:
                with urllib.request.urlopen(f"{self.url}/ping", timeout=0.5):
                    return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("influxd did not answer /ping within 20 s")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.proc = None


def require_influxd() -> None:
    if shutil.which("influxd") is None:
        pytest.skip("influxd is not installed (Debian package `influxdb`; `make` installs it via "
                    "setup/20-influxdb.sh)")
