"""`vs offset`, `vs track --closed-loop` and `vs server --camera-sim` as a user runs them."""

from __future__ import annotations

import json
import time

import pytest
from typer.testing import CliRunner
from vss_rig import vs_server_process

from virtualstar.cli.main import app

runner = CliRunner()
CAMERA_FILE = """\
[truth]
star = "Vega"

[camera]
noise_arcsec = 0.3
seed = 4
"""


def _vs(url: str, *args: str):
    return runner.invoke(app, [*args, "--server", url])


def test_vs_offset_and_a_closed_loop_track_through_a_server_with_a_simulated_camera(tmp_path):
    camera = tmp_path / "vega.toml"
    camera.write_text(CAMERA_FILE)
    with vs_server_process("--emulator", "--speed", "20", "--start", "2024-05-18T22:00:00Z",
                           "--seed", "11", "--camera-sim", str(camera)) as srv:
        assert "simulated guide camera on ws://" in srv.proc.stdout.readline()
        res = _vs(srv.url, "track", "--star", "Vega", "--closed-loop", "--json")
        assert res.exit_code == 0, res.output
        assert json.loads(res.output)["kind"] == "track"
        res = _vs(srv.url, "offset", "dec", "-5", "--json")  # a negative value is a value
        assert res.exit_code == 0, res.output
        answer = json.loads(res.output)
        assert answer["offsets"]["axes"]["dec"]["goal_arcsec"] == pytest.approx(-5.0, abs=1.0)
        res = _vs(srv.url, "offset", "path", "0.5", "--seconds")
        assert res.exit_code == 0 and "path" in res.output and "ms after acceptance" in res.output
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            st = json.loads(_vs(srv.url, "status", "--json").output)
            loop = st["operation"]["info"].get("closed_loop", {})
            if loop.get("accepted", 0) > 20:
                break
            time.sleep(0.5)
        assert loop["state"] in ("locked", "refusing") and loop["kind"] == "sky"
        assert st["corrections"]["mode"] == "replace_from"
        res = _vs(srv.url, "offset", "all", "--op", "reset", "--json")
        assert res.exit_code == 0, res.output
        assert _vs(srv.url, "stop").exit_code == 0


def test_vs_offset_refuses_bad_arguments_before_sending_and_a_track_without_one(tmp_path):
    url = "ws://127.0.0.1:9"  # nothing listens: every refusal below comes from the CLI itself
    for args, text in ((["offset", "x", "1"], "expected one of"),
                       (["offset", "ra", "1", "--op", "spin"], "--op"),
                       (["offset", "ra", "--op", "add"], "needs a finite VALUE"),
                       (["offset", "ra", "1", "--seconds"], "--seconds is for the path"),
                       (["offset", "all", "1"], "goes with --op reset")):
        res = _vs(url, *args)
        assert res.exit_code == 2 and text in res.output, (args, res.output)
