"""`vs alpaca` as a user starts it: its own process, the embedded emulator, alpyca on loopback."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import forkserver
import pytest
from typer.testing import CliRunner

from virtualstar.cli.main import app

runner = CliRunner()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_vs_alpaca_with_the_emulator_serves_a_telescope_alpyca_can_drive():
    from alpaca import management
    from alpaca.telescope import Telescope

    port = free_port()
    vs = str(Path(sys.executable).with_name("vs"))
    proc = forkserver.popen([vs, "alpaca", "--emulator",
                             "--listen", f"127.0.0.1:{port}", "--discovery-port", "0"],
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        assert f"127.0.0.1:{port}" in line, line
        address = f"127.0.0.1:{port}"
        assert management.apiversions(address) == [1]
        t = Telescope(address, 0)
        t.Connected = True
        assert -90.0 <= t.Altitude <= 90.0 and 0.0 <= t.Azimuth < 360.0
        assert not t.Slewing
    finally:
        proc.send_signal(signal.SIGTERM)
        rest = proc.communicate(timeout=60)[1]
    assert proc.returncode == 0, rest


@pytest.mark.parametrize(("args", "message"), [
    (["--listen", "nowhere"], "HOST:PORT"),
    (["--listen", "0.0.0.0:11199", "--no-discovery"], "--trust-network"),
    (["--discovery-bind", "0.0.0.0"], "--trust-network"),
    (["--emulator", "--server", "ws://127.0.0.1:1"], "not both"),
    (["--focal-length-m", "-2"], "positive"),
])
def test_vs_alpaca_refuses_bad_arguments_with_exit_2(args, message):
    res = runner.invoke(app, ["alpaca", *args])
    assert res.exit_code == 2, res.output
    assert message in res.output


def test_vs_alpaca_without_a_server_says_what_to_start():
    t0 = time.monotonic()
    res = runner.invoke(app, ["alpaca", "--server", f"ws://127.0.0.1:{free_port()}",
                              "--no-discovery", "--listen", f"127.0.0.1:{free_port()}"])
    assert res.exit_code == 2 and "vs server" in res.output
    assert time.monotonic() - t0 < 120


def test_vs_alpaca_needs_the_operator_password_of_a_server_with_passwords():
    from vss_rig import vs_server_process

    with vs_server_process("--emulator", "--speed", "20", "--start", "2024-05-18T21:00:00Z",
                           "--operator-password", "op-secret",
                           "--observer-password", "obs-secret") as srv:
        base = ["alpaca", "--server", srv.url, "--no-discovery",
                "--listen", f"127.0.0.1:{free_port()}"]
        missing = runner.invoke(app, base)
        observer = runner.invoke(app, ["--password", "obs-secret", *base])
    assert missing.exit_code == 1 and "password" in missing.output
    assert observer.exit_code == 1 and "operator" in observer.output
