"""The Telescope tab and the header's STOP in headless chromium against `vs server --emulator`.

The page (panel/test/e2e/telescope.e2e.mjs) connects to the VSS with its password and to the
mount's ASTCom endpoint, tracks Vega from the board, presses the header's STOP and parks.
This test checks each step with its own clients: the VSS's status through
`virtualstar.vss_client`, the mount through `astcom_client` (where the encoders are, whether
the axes move), and Vega's place from its catalogue coordinates (SIMBAD, J2000).
"""

from __future__ import annotations

import asyncio
import json
import re
import subprocess

import pytest
from panel_helpers import ARTIFACTS, CHROMIUM, PANEL_DIR, node, vss_and_panel
from vss_rig import STARS_PROGRAM

from astcom_client import Client
from virtualstar.vss_client import VssClient

MOUNT_PASSWORD, OPERATOR_PASSWORD = "mount-secret", "operator-secret"
START = "2024-05-18T21:00:00Z"  # Poznań (the default site): Vega at about 40° elevation
PACE = "20"  # lockstep, up to 20x real time: a slew takes about a second of wall time
VEGA_RA_DEG, VEGA_DEC_DEG = 279.2347348, 38.7836888  # SIMBAD, ICRS J2000
VEGA_MOVED_DEG = 30 / 3600  # proper motion 2000 -> 2024 (~9″) and the board's rounding, with room
DISPLAY_DEG = 1e-5  # the board shows degrees with 5 decimals
AT_REST_DEG = 1e-4  # tracking at x20 moves the encoders more than this in 0.5 s of wall time


@pytest.fixture(scope="module")
def rig():
    with vss_and_panel("--speed", PACE, "--start", START, "--password", MOUNT_PASSWORD,
                       "--operator-password", OPERATOR_PASSWORD) as urls:
        yield urls


def run_scenario(rig, scenario: str, tmp_path) -> dict:
    result_path = tmp_path / f"{scenario}.json"
    run = subprocess.run(
        [node(), "test/e2e/telescope.e2e.mjs"], cwd=PANEL_DIR, capture_output=True, text=True,
        timeout=180, env={"PATH": "/usr/bin:/bin:/usr/local/bin", "HOME": str(tmp_path),
                          "PANEL_URL": rig["panel"], "ASTCOM_URL": rig["emulator"],
                          "ASTCOM_PASSWORD": MOUNT_PASSWORD, "VSS_URL": rig["vss"],
                          "VSS_PASSWORD": OPERATOR_PASSWORD, "ARTIFACTS": str(ARTIFACTS),
                          "RESULT": str(result_path), "SCENARIO": scenario,
                          "CHROMIUM_PATH": str(CHROMIUM)})
    result = json.loads(result_path.read_text()) if result_path.exists() else {}
    assert result.get("ok"), f"{result.get('error')}\n{run.stdout}\n{run.stderr}"
    assert not result.get("pageErrors"), result["pageErrors"]
    return result


async def _vss_status(url: str) -> dict:
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        return await vss.request("status")


async def _mount_twice(url: str) -> list[dict]:
    """Read the mount's state and encoders, then again half a second (wall) later."""
    names = ["mount.state_name", "axis.az.position_deg", "axis.el.position_deg"]
    async with await Client.connect(url, password=MOUNT_PASSWORD) as c:
        first = await c.read(names)
        await asyncio.sleep(0.5)
        return [first, await c.read(names)]


@pytest.fixture(scope="module")
def track_stop(rig, tmp_path_factory):
    result = run_scenario(rig, "track-stop", tmp_path_factory.mktemp("track-stop"))
    # read right after the page's STOP, before anything else moves the mount
    result["truth_mount"] = asyncio.run(_mount_twice(rig["emulator"]))
    result["truth_vss"] = asyncio.run(_vss_status(rig["vss"]))
    return result


@pytest.fixture(scope="module")
def park(rig, track_stop, tmp_path_factory):
    result = run_scenario(rig, "park", tmp_path_factory.mktemp("park"))
    result["truth_mount"] = asyncio.run(_mount_twice(rig["emulator"]))
    result["truth_vss"] = asyncio.run(_vss_status(rig["vss"]))
    return result


async def _start_program(url: str, tmp_path) -> dict:
    """Plan the stars from two minutes of mount time on, and run the plan (no wait)."""
    from virtualstar.astro import load_site
    from virtualstar.planning import PlanRequest, load_program, plan_program

    (tmp_path / "program.toml").write_text(STARS_PROGRAM)
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        now_us = (await vss.request("status"))["mount_time_us"]
        start_us = (now_us // 60_000_000 + 2) * 60_000_000
        plan = plan_program(PlanRequest(load_program(tmp_path / "program.toml"), start_us,
                                        start_us + 9 * 60_000_000, load_site()))
        assert plan.blocks, plan.left_out
        await vss.request("run_plan", {"plan": plan.as_dict()})
        return plan.as_dict()


async def _program(url: str) -> dict:
    async with await VssClient.connect(url, password=OPERATOR_PASSWORD) as vss:
        return await vss.request("program")


@pytest.fixture(scope="module")
def program(rig, park, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("program")
    plan = asyncio.run(_start_program(rig["vss"], tmp))
    result = run_scenario(rig, "program", tmp)
    result["plan"] = plan
    result["truth_program"] = asyncio.run(_program(rig["vss"]))
    return result


def deg(text: str) -> float:
    return float(text)


def sexagesimal_deg(text: str, *, hours: bool) -> float:
    sign = -1.0 if text.startswith("-") else 1.0
    a, b, c = (float(x) for x in text.lstrip("+-").split(":"))
    return sign * (a + b / 60 + c / 3600) * (15 if hours else 1)


def test_panel_proposes_the_vss_of_vs_panel_and_refuses_a_wrong_password(track_stop, rig):
    assert track_stop["proposedVss"] == rig["vss"]
    assert track_stop["wrongPasswordState"].strip() == "disconnected"
    assert track_stop["role"] == "operator"


def test_board_shows_vega_tracked_where_the_catalogue_puts_it(track_stop):
    board = track_stop["tracking"]
    assert board["target"] == "Vega" and board["phase"] == "tracking"
    assert board["kind"].startswith("track") and board["mode"] == "active"
    assert board["mount-state"] == "tracking" and board["mount-link"] == "connected"
    ra = sexagesimal_deg(board["ra"], hours=True)
    dec = sexagesimal_deg(board["dec"], hours=False)
    assert abs(ra - VEGA_RA_DEG) * 0.78 < VEGA_MOVED_DEG  # cos(dec) on the sky
    assert abs(dec - VEGA_DEC_DEG) < VEGA_MOVED_DEG
    # a perfect mount without a pointing model: observed is the encoder place
    assert board["pointing-model"] == "none"
    assert abs(deg(board["observed-az"]) - deg(board["encoder-az"])) <= DISPLAY_DEG
    assert abs(deg(board["observed-el"]) - deg(board["encoder-el"])) <= DISPLAY_DEG
    assert 30 < deg(board["encoder-el"]) < 60
    assert 0 <= float(board["rms-1s"]) < 1 and 0 <= float(board["on-sky-rms-1s"]) < 1
    assert 0 <= float(board["on-target-rms-1s"]) < 1 and float(board["planned-1s"]) < 0.01
    assert re.fullmatch(r"-?\d+", board["clock-offset"])
    assert re.fullmatch(r"2024-05-18 21:\d\d:\d\d\.\d{3}", board["mount-time"])  # the one time format


def test_the_hand_pad_offsets_the_track_by_a_key_and_a_button_in_steps(track_stop):
    pad = track_stop["handPad"]
    assert pad["labels"] == ["N", "E", "0", "W", "S"]
    assert pad["dec"] == "5.000″" and pad["ra"] == "5.000″"  # ArrowUp north, the E button
    assert pad["mode"] == "replace_from"
    changes = pad["corrections"]["offsets"]["last_changes"]
    assert [c["what"] for c in changes[-2:]] == ["offset dec add", "offset ra add"]
    assert all(c["lead_ms"] >= 20 and c["sent"] == "replace_from" for c in changes[-2:])
    assert "VSS offset" in track_stop["log"]


def test_header_stop_stops_the_mount_and_ends_the_vss_operation(track_stop):
    outcome = track_stop["stopOutcome"]
    assert "mount: mount.stop() done" in outcome and "VSS: stop done" in outcome
    first, second = track_stop["truth_mount"]
    assert first["mount.state_name"] == second["mount.state_name"] == "HOLDING"
    for axis in ("az", "el"):
        name = f"axis.{axis}.position_deg"
        assert abs(second[name] - first[name]) < AT_REST_DEG
    vss = track_stop["truth_vss"]
    tracked = track_stop["trackingOperation"]
    assert vss["operation"]["id"] == tracked["id"] and vss["operation"]["phase"] == "aborted"
    assert track_stop["afterStop"]["phase"] == "stopped"  # aborted by the stop, as asked
    assert "VSS stop sent" in track_stop["log"]


def test_park_from_the_board_leaves_the_mount_off_where_the_board_says(park):
    board = park["parked"]
    assert board["kind"].startswith("park") and board["phase"] == "done"
    assert board["mount-state"] == "off"
    first, second = park["truth_mount"]
    assert first["mount.state_name"] == "OFF"
    for axis in ("az", "el"):
        name = f"axis.{axis}.position_deg"
        assert second[name] == pytest.approx(first[name], abs=AT_REST_DEG)
        assert abs(deg(board[f"encoder-{axis}"]) - second[name]) <= DISPLAY_DEG
    assert park["truth_vss"]["operation"]["kind"] == "park"


def test_a_screenshot_of_the_telescope_board_is_kept(track_stop, park, program):
    for name in ("telescope", "telescope-parked", "telescope-program"):
        png = ARTIFACTS / f"{name}.png"
        assert png.is_file() and png.stat().st_size > 10_000, png


def test_a_running_program_shows_its_block_and_the_header_stop_ends_it(program):
    shown = program["program"]
    assert shown["state"] == "running"
    truth = program["truth_program"]
    assert truth["state"] == "stopped" and "stop" in truth["error"]["message"]
    assert program["programAfterStop"] == "stopped"
    # the block the board showed is one the server ran (and the stop interrupted or followed)
    ran = {r["target"] for r in truth["records"]}
    assert shown["current"].split(" (")[0] in ran
    assert shown["current"].split(" (")[0] in {b["target"] for b in program["plan"]["blocks"]}
