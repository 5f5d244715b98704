"""`vs demo --json` and `vs server` as a process."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from typer.testing import CliRunner
from vss_rig import vs_server_process

from virtualstar.cli.main import app

runner = CliRunner()


def test_demo_json_reports_slew_sidereal_and_satellite_phases_and_writes_a_plot(tmp_path):
    res = runner.invoke(app, ["demo", "--json", "--sidereal", "5",
                              "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    names = [p["name"] for p in doc["phases"]]
    for word in ("slew", "sidereal", "satellite"):
        assert any(word in n for n in names), names
    for p in doc["phases"]:
        assert p["rms_arcsec"] >= 0 and p["peak_arcsec"] >= p["rms_arcsec"]
    sat = next(p for p in doc["phases"] if "satellite" in p["name"])
    assert sat["duration_s"] > 300  # the whole pass, from 5 deg to 5 deg
    assert sat["rms_arcsec"] <= 2.0
    png = Path(doc["plot"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_vs_server_with_the_embedded_emulator_serves_clients_until_terminated():
    with vs_server_process("--emulator", "--speed", "10", "--start",
                           "2024-05-18T19:40:00Z") as server:
        url = server.url
        for _ in range(100):
            res = runner.invoke(app, ["status", "--server", url, "--json"])
            if res.exit_code == 0 and json.loads(res.stdout)["connected"]:
                break
            time.sleep(0.05)
        st = json.loads(res.stdout)
        assert st["simulated"] and st["speed"] == 10
        assert st["mount_time_utc"].startswith("2024-05-18T19:4")
    assert server.returncode == 0, server.err
    assert "stopped" in server.out


def test_vs_server_speed_max_keeps_idle_time_real_and_runs_ahead_while_a_client_waits():
    """The README's session: typing a command takes wall seconds, and the sky must still be
    where it was. Idle, mount time runs at most at real time (an upper bound, whatever the
    host's load); a client waiting for ten mount minutes is answered in seconds."""
    with vs_server_process("--emulator", "--speed", "max", "--start",
                           "2024-05-18T19:40:00Z") as server:
        url = server.url
        assert "real time otherwise" in server.line
        st = None
        for _ in range(100):
            res = runner.invoke(app, ["status", "--server", url, "--json"])
            if res.exit_code == 0 and json.loads(res.stdout)["connected"]:
                st = json.loads(res.stdout)
                break
            time.sleep(0.05)
        assert st is not None and st["time_mode"] == "lockstep" and st["speed"] == 1.0
        # the wall interval spans both reads (sent after wall0, answered before wall1)
        wall0 = time.monotonic()
        t0 = json.loads(runner.invoke(app, ["status", "--server", url, "--json"]).stdout)
        time.sleep(2.0)
        st = json.loads(runner.invoke(app, ["status", "--server", url, "--json"]).stdout)
        wall1 = time.monotonic()
        idle_s = (st["mount_time_us"] - t0["mount_time_us"]) / 1e6
        assert 0.0 < idle_s <= (wall1 - wall0) * 1.0 + 0.5, (idle_s, wall1 - wall0)
        res = runner.invoke(app, ["track", "--star", "Vega", "--duration", "600", "--wait",
                                  "--server", url, "--json"], )
        assert res.exit_code == 0, res.output
        info = json.loads(res.stdout)["info"]
        assert info["tracking_to_us"] - info["tracking_from_us"] == 600_000_000
    assert server.returncode == 0, server.err


def test_vs_server_whose_port_is_taken_says_so_and_exits_instead_of_hanging():
    """The start fails after the emulator and the VSS's mount link have started: everything
    started must stop. (The link's reconnect loop once swallowed its cancellation, which
    Python 3.11's wait_for loses when the ASTCom handshake completes at that moment, and the
    server waited forever to stop, printing nothing: a panel test's setup hung 300 s.)"""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        url = f"ws://127.0.0.1:{taken.getsockname()[1]}"
        proc = subprocess.run(
            [sys.executable, "-c", "from virtualstar.cli.main import main; main()", "server",
             "--emulator", "--speed", "20", "--start", "2024-05-18T21:00:00Z",
             "--password", "secret", "--listen", url, "--endpoint-port", "0"],
            capture_output=True, text=True, timeout=240,  # a hang guard, not a speed bound
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.returncode == 1, (proc.stdout, proc.stderr)
    assert f"cannot listen on {url}" in proc.stderr and "address already in use" in proc.stderr
    assert "VirtualStar Server on" not in proc.stdout


def test_vs_server_refuses_contradictory_options():
    res = runner.invoke(app, ["server", "--emulator", "--mount", "ws://127.0.0.1:1"])
    assert res.exit_code == 2 and "either --emulator or --mount" in res.stderr
    res = runner.invoke(app, ["server", "--mount", "ws://127.0.0.1:1", "--speed", "max"])
    assert res.exit_code == 2 and "only applies to --emulator" in res.stderr
    res = runner.invoke(app, ["server", "--mount", "ws://127.0.0.1:1", "--start",
                              "2024-05-18T19:40:00Z"])
    assert res.exit_code == 2 and "only applies to --emulator" in res.stderr
    for bad in ("0", "fast", "-3", "1e9"):
        res = runner.invoke(app, ["server", "--emulator", "--speed", bad])
        assert res.exit_code == 2 and "'max' or a number" in res.stderr, bad
    res = runner.invoke(app, ["server", "--emulator", "--start", "yesterday"])
    assert res.exit_code == 2 and "ISO" in res.stderr
