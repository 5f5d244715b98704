"""Bad commands, parameters and CLI arguments get clear errors; the server keeps serving."""

from __future__ import annotations

import json
import re

import pytest
from typer.testing import CliRunner

from virtualstar.cli.main import app
from virtualstar.vss_client import VssClient

runner = CliRunner()

BAD_FRAMES = [
    ("not json at all", "bad_request", "not JSON"),
    ("[1, 2]", "bad_request", "not an object"),
    ('{"id": 1}', "bad_request", "'cmd'"),
    ('{"id": 2, "cmd": "fly"}', "unknown_command", "valid commands"),
    ('{"id": 3, "cmd": "slew", "params": {"star": "Vega", "speed": 3}}', "bad_request",
     "unknown parameters ['speed']"),
    ('{"id": 4, "cmd": "slew", "params": {"az_deg": "east", "el_deg": 40}}', "bad_request",
     "expected float"),
    ('{"id": 5, "cmd": "slew", "params": {}}', "bad_request", "exactly one target"),
    ('{"id": 6, "cmd": "slew", "params": {"radec": "25h61m +99d"}}', "bad_request", "RA"),
    ('{"id": 7, "cmd": "slew", "params": {"star": "Vegaa"}}', "bad_request", "Vega"),
    ('{"id": 8, "cmd": "slew", "params": {"altaz": "10 95"}}', "bad_request", "elevation 95° is outside -90..90°"),
    ('{"id": 9, "cmd": "track", "params": {"tle": "1 2 3"}}', "bad_request", "line"),
    ('{"id": 10, "cmd": "track", "params": {"star": "Vega", "duration_s": -5}}', "bad_request",
     "positive"),
    ('{"id": 11, "cmd": "set_mode", "params": {"mode": "sleepy"}}', "bad_request", "'active'"),
    ('{"id": 12, "cmd": "load_model", "params": {"path": "/nonexistent/model.json"}}',
     "bad_request", "cannot load pointing model"),
    ('{"id": 13, "cmd": "slew", "params": {"star": "Canopus"}}', "unreachable",
     "below the horizon limit 5.00°"),  # dec -52.7 never rises at latitude 52.4
]


def test_bad_api_requests_are_answered_with_a_code_and_a_message_and_the_server_keeps_running(rig):
    async def scenario():
        async with await VssClient.connect(rig.url) as vs:
            replies = [await vs.send_raw(frame) for frame, _, _ in BAD_FRAMES]
            ok = await vs.request("ping")
        return replies, ok

    replies, ok = rig.run(scenario())
    for (frame, code, words), reply in zip(BAD_FRAMES, replies, strict=True):
        assert reply["ok"] is False, frame
        assert reply["error"]["code"] == code, (frame, reply)
        assert words in reply["error"]["message"], (frame, reply)
    assert ok == {"pong": True}


def test_a_passive_server_refuses_motion_but_still_reports_status(rig):
    async def scenario():
        async with await VssClient.connect(rig.url) as vs:
            await vs.request("set_mode", {"mode": "passive"})
            try:
                return await vs.send_raw(json.dumps({"id": 1, "cmd": "slew",
                                                     "params": {"altaz": "100 40"}})), \
                    await vs.request("status")
            finally:
                await vs.request("set_mode", {"mode": "active"})

    reply, st = rig.run(scenario())
    assert reply["error"]["code"] == "passive"
    assert st["mode"] == "passive" and st["connected"]


@pytest.mark.parametrize(("args", "code", "words"), [
    (["slew"], 2, "exactly one of"),
    (["slew", "--star", "Vega", "--altaz", "10 20"], 2, "exactly one of"),
    (["slew", "--star", "Vegaa"], 1, "did you mean"),
    (["slew", "--altaz", "north 20"], 2, "expected two numbers"),
    (["slew", "--altaz", "400 45"], 2, "azimuth 400° is outside 0..360°"),
    (["slew", "--radec", "25h61m +99d"], 2, "--radec: bad RA"),
    (["track", "--radec", "12h00m +95d"], 2, "--radec"),
    (["track", "--tle", "/nonexistent/file.tle"], 2, "cannot read TLE file"),
    (["track", "--tle", "/dev/zero"], 2, "/dev/zero: a character device, not a regular file"),
    (["track", "--sat", "ISS", "--star", "Vega"], 2, "--tle"),
    (["track", "--star", "Vega", "--duration", "0"], 2, "positive"),
])
def test_bad_cli_arguments_exit_non_zero_with_a_clear_message(rig, args, code, words):
    res = runner.invoke(app, [*args, "--server", rig.url])
    assert res.exit_code == code, res.output
    assert words in res.stderr


def test_a_refused_command_with_json_prints_the_error_object_on_stdout(rig):
    res = runner.invoke(app, ["slew", "--star", "Canopus", "--server", rig.url, "--json"])
    assert res.exit_code == 1
    error = json.loads(res.stdout)["error"]
    assert error["code"] == "unreachable" and "Canopus" in error["message"]
    res = runner.invoke(app, ["status", "--server", "ws://127.0.0.1:9", "--json"])
    assert res.exit_code == 2
    assert json.loads(res.stdout)["error"]["code"] == "server_unavailable"


@pytest.mark.parametrize("args", [["slew", "--radec", "xx"], ["slew", "--altaz", "400"],
                                  ["slew"], ["track", "--sat", "ISS", "--star", "Vega"],
                                  ["track", "--star", "Vega", "--duration", "-1"]])
def test_a_bad_argument_with_json_prints_the_error_object_on_stdout_too(args):
    res = runner.invoke(app, [*args, "--server", "ws://127.0.0.1:9", "--json"])
    assert res.exit_code == 2
    error = json.loads(res.stdout)["error"]
    assert error["code"] == "bad_input" and error["message"] in res.stderr


def test_the_cli_says_how_to_fix_an_unreachable_server():
    res = runner.invoke(app, ["status", "--server", "ws://127.0.0.1:9"])
    assert res.exit_code == 2
    assert "vs server" in res.stderr


def test_a_tle_without_the_named_satellite_lists_what_it_holds(rig, tmp_path):
    from catalogs import sample_tle_path

    res = runner.invoke(app, ["track", "--tle", str(sample_tle_path("stations")), "--sat",
                              "Hubble", "--server", rig.url])
    assert res.exit_code == 1
    assert "ISS" in res.stderr
    res = runner.invoke(app, ["status", "--server", rig.url, "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["connected"]


def test_a_satellite_pass_beyond_the_allowed_wait_is_refused_with_its_start(rig):
    from catalogs import sample_tle_path
    from virtualstar.vss_client import VssRequestError, call_server

    tle = sample_tle_path("stations").read_text(encoding="utf-8")
    # No wait allowed at all: whenever the shared rig's clock stands (it runs at x20, so on a
    # loaded host it may already be near or inside the 19:50 pass), joining any pass needs a
    # slew first, so the refusal does not depend on how far the clock has run.
    with pytest.raises(VssRequestError) as info:
        call_server(rig.url, "track", {"tle": tle, "sat": "ISS", "max_wait_s": 0})
    assert info.value.code == "unreachable"
    assert re.search(r"the next pass of ISS.* begins in \d+ s, more than the 0 s allowed",
                     info.value.message), info.value.message


def test_watch_into_a_pipe_writes_one_line_per_update_as_it_comes(rig):
    res = runner.invoke(app, ["watch", "--count", "3", "--interval", "0.05", "--server", rig.url])
    assert res.exit_code == 0, res.output
    lines = [x for x in res.stdout.splitlines() if x and not x.startswith("event")]
    assert len(lines) == 3  # no table, no redraw codes: one line each
    assert all(" az " in x and " el " in x and "clock" in x for x in lines), lines
    assert "\x1b[" not in res.stdout
